//! Bearer tokens. Compared in constant time, never logged.

use crate::error::ApiError;
use crate::state::AppState;
use axum::extract::{Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Workers: leases, plans, library files. The admin token also passes.
    Worker,
    /// Creating libraries, starting and cancelling campaigns.
    Admin,
}

fn matches(given: Option<&str>, expected: &str) -> bool {
    given.is_some_and(|g| bool::from(g.as_bytes().ct_eq(expected.as_bytes())))
}

/// Whether `token` grants `role` under the configured tokens.
pub fn allowed(state: &AppState, role: Role, token: Option<&str>) -> bool {
    let admin = state.config.admin_token.as_deref();
    let worker = state.config.worker_token.as_deref();
    match role {
        Role::Admin => admin.is_none_or(|a| matches(token, a)),
        Role::Worker => match worker {
            None => true,
            Some(w) => matches(token, w) || admin.is_some_and(|a| matches(token, a)),
        },
    }
}

/// Middleware: admits requests with the admin token (when one is set).
pub async fn require_admin(state: State<AppState>, request: Request, next: Next) -> Response {
    check(state, request, next, Role::Admin).await
}

/// Middleware: admits requests with the worker or admin token (when set).
pub async fn require_worker(state: State<AppState>, request: Request, next: Next) -> Response {
    check(state, request, next, Role::Worker).await
}

async fn check(
    State(state): State<AppState>,
    request: Request,
    next: Next,
    role: Role,
) -> Response {
    let token = request
        .headers()
        .get(AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    if allowed(&state, role, token) {
        next.run(request).await
    } else {
        let which = match role {
            Role::Admin => "the admin token",
            Role::Worker => "the worker token",
        };
        ApiError::Unauthorized(format!(
            "this endpoint needs {which} as `Authorization: Bearer <token>`"
        ))
        .into_response()
    }
}
