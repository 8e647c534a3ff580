//! Tokens. Three roles: admin (create and cancel), worker (leases, plans,
//! library files) and read (the dashboard, metrics and the API's reads).
//! Each role's token is optional; an unset token leaves its role open. The
//! admin token also passes as worker and reader. Tokens are compared in
//! constant time and never logged: the request log records method, path
//! and status, not headers, and a refusal names the role, not the token.

use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::{Request, State};
use axum::http::header::{AUTHORIZATION, WWW_AUTHENTICATE};
use axum::http::{HeaderMap, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use base64::Engine;
use subtle::ConstantTimeEq;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Workers: leases, plans, library files.
    Worker,
    /// Creating libraries, starting and cancelling campaigns.
    Admin,
    /// The dashboard, `/metrics` and the API's reads.
    Read,
}

fn matches(given: Option<&str>, expected: &str) -> bool {
    given.is_some_and(|g| bool::from(g.as_bytes().ct_eq(expected.as_bytes())))
}

/// Whether `token` grants `role` under the configured tokens.
pub fn allowed(state: &AppState, role: Role, token: Option<&str>) -> bool {
    let config = &state.config;
    let admin = config.admin_token.as_deref();
    let own = match role {
        Role::Admin => return admin.is_none_or(|a| matches(token, a)),
        Role::Worker => config.worker_token.as_deref(),
        Role::Read => config.read_token.as_deref(),
    };
    match own {
        None => true,
        Some(t) => matches(token, t) || admin.is_some_and(|a| matches(token, a)),
    }
}

/// The presented token: `Authorization: Bearer TOKEN`, or for reads the
/// password of `Authorization: Basic base64(user:TOKEN)` (any user name),
/// which is what a browser sends after asking. Basic is refused for the
/// admin and worker roles: a browser attaches cached Basic credentials to
/// any request to the origin, a form posted from another site included,
/// and `POST …/cancel` needs no body.
fn presented(headers: &HeaderMap, role: Role) -> Option<String> {
    let value = headers.get(AUTHORIZATION)?.to_str().ok()?;
    if let Some(token) = value.strip_prefix("Bearer ") {
        return Some(token.to_owned());
    }
    if role != Role::Read {
        return None;
    }
    let encoded = value.strip_prefix("Basic ")?;
    let decoded = base64::engine::general_purpose::STANDARD
        .decode(encoded.trim())
        .ok()?;
    let text = String::from_utf8(decoded).ok()?;
    text.split_once(':')
        .map(|(_, password)| password.to_owned())
}

/// Middleware: admits requests with the admin token (when one is set).
pub async fn require_admin(state: State<AppState>, request: Request, next: Next) -> Response {
    check(state, request, next, Role::Admin).await
}

/// Middleware: admits requests with the worker or admin token (when set).
pub async fn require_worker(state: State<AppState>, request: Request, next: Next) -> Response {
    check(state, request, next, Role::Worker).await
}

/// Middleware: admits requests with the read or admin token (when set).
pub async fn require_read(state: State<AppState>, request: Request, next: Next) -> Response {
    check(state, request, next, Role::Read).await
}

async fn check(
    State(state): State<AppState>,
    request: Request,
    next: Next,
    role: Role,
) -> Response {
    let token = presented(request.headers(), role);
    if allowed(&state, role, token.as_deref()) {
        return next.run(request).await;
    }
    let which = match role {
        Role::Admin => "the admin token",
        Role::Worker => "the worker token",
        Role::Read => "the read token",
    };
    let mut response = ServiceError::Unauthorized(format!(
        "this endpoint needs {which} as `Authorization: Bearer <token>`"
    ))
    .into_response();
    if role == Role::Read {
        // Lets a browser ask for the token (as the password) on the dashboard.
        response.headers_mut().insert(
            WWW_AUTHENTICATE,
            HeaderValue::from_static("Basic realm=\"tslg\", charset=\"UTF-8\""),
        );
    }
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(AUTHORIZATION, HeaderValue::from_str(value).unwrap());
        h
    }

    #[test]
    fn bearer_tokens_and_for_reads_basic_passwords_are_the_presented_token() {
        let read = Role::Read;
        assert_eq!(
            presented(&headers("Bearer s3cret"), read).as_deref(),
            Some("s3cret")
        );
        // base64("viewer:s3:cret"): the password may hold colons.
        let basic = format!(
            "Basic {}",
            base64::engine::general_purpose::STANDARD.encode("viewer:s3:cret")
        );
        assert_eq!(
            presented(&headers(&basic), read).as_deref(),
            Some("s3:cret")
        );
        for role in [Role::Admin, Role::Worker] {
            assert_eq!(presented(&headers(&basic), role), None, "{role:?}");
            assert_eq!(
                presented(&headers("Bearer s3cret"), role).as_deref(),
                Some("s3cret")
            );
        }
        assert_eq!(presented(&headers("Basic !!!"), read), None);
        assert_eq!(presented(&headers("Token s3cret"), read), None);
        assert_eq!(presented(&HeaderMap::new(), read), None);
    }
}
