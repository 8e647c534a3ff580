//! What a worker's request must be before anything is taken: its name,
//! threads, wait and budget, and the programs it offers or reports
//! unhealthy (422 otherwise, or 400 for a name in a path).

use crate::error::ServiceError;
use crate::leasing::claim as claiming;
use tslg_api::{LeaseRequest, MAX_CLAIM_WAIT_SECONDS};
use tslg_method::external::{check_program_name, ExternalMode};

/// Most programs' offers and unhealthy reports one request may carry.
const MAX_OFFERS: usize = 256;
const MAX_UNHEALTHY: usize = 16;
const MAX_UNHEALTHY_REASON: usize = 4000;

/// A worker's name: 1 to 128 bytes, no control characters; the problem
/// otherwise (a body's name answers 422, a path's 400).
pub(crate) fn worker_name_problem(worker: &str) -> Option<String> {
    (worker.is_empty() || worker.len() > 128 || worker.chars().any(char::is_control))
        .then(|| "worker must be 1 to 128 printable characters".to_string())
}

pub fn check_worker(worker: &str) -> Result<(), ServiceError> {
    worker_name_problem(worker).map_or(Ok(()), |m| Err(ServiceError::Unprocessable(m)))
}

/// What a lease request must be before anything is taken (422 otherwise).
pub fn check_lease_request(req: &LeaseRequest) -> Result<(), ServiceError> {
    check_worker(&req.worker)?;
    if !(1..=claiming::MAX_THREADS).contains(&req.threads) {
        return Err(ServiceError::Unprocessable(format!(
            "threads = {} must be in 1..={}",
            req.threads,
            claiming::MAX_THREADS
        )));
    }
    if let Some(wait) = req.wait_seconds {
        if !(0.0..=MAX_CLAIM_WAIT_SECONDS).contains(&wait) {
            // A huge number in exponent form, not in hundreds of digits.
            let shown = if wait.abs() < 1e6 {
                format!("{wait}")
            } else {
                format!("{wait:e}")
            };
            return Err(ServiceError::Unprocessable(format!(
                "wait_seconds = {shown} must be in [0, {MAX_CLAIM_WAIT_SECONDS}]"
            )));
        }
    }
    if req.max_tests == Some(0) {
        return Err(ServiceError::Unprocessable(
            "max_tests = 0: a lease holds at least one test".into(),
        ));
    }
    check_programs(req)
}

/// Checks the external programs a lease request offers (`NAME:case:mode`)
/// and reports unhealthy.
fn check_programs(req: &LeaseRequest) -> Result<(), ServiceError> {
    let bad = |m: String| Err(ServiceError::Unprocessable(m));
    if req.offers.len() > MAX_OFFERS {
        return bad(format!(
            "offers lists {} entries; at most {MAX_OFFERS}",
            req.offers.len()
        ));
    }
    for offer in &req.offers {
        let parts: Vec<&str> = offer.split(':').collect();
        let [name, case, mode] = parts[..] else {
            return bad(format!("offer `{offer}` must be NAME:case:mode"));
        };
        check_program_name(name).map_err(ServiceError::Unprocessable)?;
        if case.is_empty() || case.len() > 64 {
            return bad(format!(
                "offer `{offer}`: the case must be 1 to 64 characters"
            ));
        }
        if serde_json::from_value::<ExternalMode>(mode.into()).is_err() {
            return bad(format!("offer `{offer}`: the mode must be step or episode"));
        }
    }
    if req.noisy.len() > req.offers.len() {
        return bad(format!(
            "noisy lists {} entries, more than offers ({})",
            req.noisy.len(),
            req.offers.len()
        ));
    }
    if let Some(stray) = req.noisy.iter().find(|n| !req.offers.contains(n)) {
        return bad(format!(
            "noisy lists `{stray}`, which offers does not: list the offers whose program said \
             \"deterministic\": false"
        ));
    }
    if req.unhealthy.len() > MAX_UNHEALTHY {
        return bad(format!(
            "unhealthy lists {} programs; at most {MAX_UNHEALTHY}",
            req.unhealthy.len()
        ));
    }
    for u in &req.unhealthy {
        check_program_name(&u.name).map_err(ServiceError::Unprocessable)?;
        if u.reason.len() > MAX_UNHEALTHY_REASON {
            return bad(format!(
                "the reason program `{}` is unhealthy exceeds {MAX_UNHEALTHY_REASON} bytes",
                u.name
            ));
        }
    }
    Ok(())
}
