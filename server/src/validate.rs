//! Checks shared by the request handlers.

use crate::error::ServiceError;

/// A name a request gives (a case, a worker, a table): 1 to `max` bytes,
/// no control characters (it ends up in logs, problem details and the
/// dashboard).
pub fn check_name(field: &str, value: &str, max: usize) -> Result<(), ServiceError> {
    if value.is_empty() || value.len() > max || value.chars().any(char::is_control) {
        return Err(ServiceError::Unprocessable(format!(
            "{field} must be 1 to {max} bytes without control characters"
        )));
    }
    Ok(())
}
