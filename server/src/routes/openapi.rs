//! The OpenAPI 3 document, generated from the handlers and wire types.

use super::auth::Role;
use crate::config::Config;
use crate::state::AppState;
use axum::extract::State;
use axum::Json;
use serde_json::{json, Value};
use std::sync::LazyLock;
use utoipa::OpenApi;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "tslg coordinator",
        description = "Testing scenario library generation: \
        libraries, importance-sampling campaigns and the leases workers take."
    ),
    paths(
        super::health::healthz,
        super::cases::list,
        super::cases::create,
        super::libraries::create,
        super::libraries::list,
        super::libraries::get_one,
        super::libraries::file,
        super::campaigns::create,
        super::campaigns::list,
        super::campaigns::get_one,
        super::campaigns::history,
        super::campaigns::stages,
        super::campaigns::timeline,
        super::events::list,
        super::events::openscenario,
        super::campaigns::plan,
        super::campaigns::cancel,
        super::campaigns::delete,
        super::libraries::delete,
        super::leases::claim,
        super::leases::heartbeat,
        super::leases::release,
        super::leases::results,
        super::leases::library,
        super::workers::register,
        super::workers::leave,
        super::workers::list,
        super::workers::revoke,
        super::workers::unflag,
        super::enrolments::issue,
        super::enrolments::revoke,
        super::queue::get,
        super::figures::estimate,
        super::figures::relative_half_width,
        super::figures::stages,
        super::figures::support,
        super::figures::library_picture,
    )
)]
pub struct ApiDoc;

/// `GET /api/v1/openapi.json`: the contract of this coordinator, with the
/// tokens it is configured with.
pub async fn document(State(state): State<AppState>) -> Json<Value> {
    static GENERATED: LazyLock<Value> = LazyLock::new(|| {
        serde_json::to_value(ApiDoc::openapi()).expect("the OpenAPI document serialises")
    });
    Json(contract(GENERATED.clone(), &state.config))
}

/// Who may call an operation: the router's groups (`routes/mod.rs`);
/// `None` for the open ones. `tests/it/service_access.rs` checks the router
/// and `scripts/fuzz-api` checks this against it (schemathesis's
/// `ignored_auth`).
fn role_of(path: &str, method: &str) -> Option<Role> {
    match (method, path) {
        (_, "/healthz" | "/api/v1/openapi.json") => None,
        (
            "post",
            "/api/v1/cases"
            | "/api/v1/libraries"
            | "/api/v1/campaigns"
            | "/api/v1/campaigns/{id}/cancel",
        )
        | ("delete", _) => Some(Role::Admin),
        (_, p) if p.starts_with("/api/v1/leases") => Some(Role::Worker),
        ("post", "/api/v1/workers") => Some(Role::Worker),
        ("get", "/api/v1/campaigns/{id}/plan" | "/api/v1/libraries/{id}/file") => {
            Some(Role::Worker)
        }
        _ => Some(Role::Read),
    }
}

/// The generated document, completed with what utoipa cannot see: errors
/// are `application/problem+json` (utoipa writes `application/json`), every
/// error status an operation can answer is listed (400 for a malformed
/// body, path or query; 401 when its token is configured; 403 and 409 on
/// leases; 404 for an unknown id; 413 over the body limit; 414 for a
/// target over `MAX_URI_BYTES`; 422 for an
/// invalid body), and operations whose token is configured require the
/// bearer scheme.
fn contract(mut doc: Value, config: &Config) -> Value {
    let problem = json!({"schema": {"$ref": "#/components/schemas/Problem"}});
    let configured = |role: Role| match role {
        Role::Admin => config.admin_token.is_some(),
        Role::Worker => config.worker_token.is_some(),
        Role::Read => config.read_token.is_some(),
    };
    let paths = doc["paths"].as_object_mut().expect("paths");
    for (path, item) in paths.iter_mut() {
        let lease_report = path.starts_with("/api/v1/leases/{id}/");
        for (method, op) in item.as_object_mut().expect("a path item") {
            let has_body = op.get("requestBody").is_some();
            let has_query = op["parameters"]
                .as_array()
                .is_some_and(|ps| ps.iter().any(|p| p["in"] == "query"));
            let role = role_of(path, method);
            let guarded = role.is_some_and(configured);
            let mut codes = vec![
                ("413", "The body exceeds the configured limit"),
                ("414", "The request target exceeds 8,192 bytes"),
            ];
            if guarded {
                codes.push(("401", "The token this operation needs is missing or wrong"));
            }
            if path.contains('{') || has_body || has_query {
                codes.push(("400", "A malformed body, path or query parameter"));
            }
            if path.contains('{') {
                codes.push(("404", "No such resource"));
            }
            if has_body {
                codes.push(("422", "A well-formed body with invalid values"));
            }
            if lease_report {
                codes.push((
                    "403",
                    "Not the named worker's secret, or not the key of this lease's attempt",
                ));
                codes.push((
                    "409",
                    "Not the lease's current holder, or a conflicting result",
                ));
            }
            let responses = op["responses"].as_object_mut().expect("responses");
            for response in responses.values_mut() {
                let Some(content) = response.get_mut("content").and_then(Value::as_object_mut)
                else {
                    continue;
                };
                if content.get("application/json") == Some(&problem) {
                    content.remove("application/json");
                    content.insert("application/problem+json".into(), problem.clone());
                }
            }
            for (code, description) in codes {
                responses.entry(code).or_insert_with(|| {
                    json!({"description": description,
                           "content": {"application/problem+json": problem.clone()}})
                });
            }
            if guarded {
                op["security"] = json!([{"bearer": []}]);
            }
        }
    }
    doc["components"]["securitySchemes"] = json!({
        "bearer": {"type": "http", "scheme": "bearer",
                   "description": "The admin, worker or read token, as the operation needs"}
    });
    doc
}
