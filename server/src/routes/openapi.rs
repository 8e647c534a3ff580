//! The OpenAPI 3 document, generated from the handlers and wire types.

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
        super::libraries::create,
        super::libraries::list,
        super::libraries::get_one,
        super::libraries::file,
        super::campaigns::create,
        super::campaigns::list,
        super::campaigns::get_one,
        super::campaigns::history,
        super::campaigns::plan,
        super::campaigns::cancel,
        super::leases::claim,
        super::leases::heartbeat,
        super::leases::release,
        super::leases::results,
        super::leases::workers,
        super::figures::estimate,
        super::figures::relative_half_width,
        super::figures::library_picture,
    )
)]
pub struct ApiDoc;

/// `GET /api/v1/openapi.json`.
pub async fn document() -> Json<Value> {
    static DOCUMENT: LazyLock<Value> = LazyLock::new(|| contract(ApiDoc::openapi()));
    Json(DOCUMENT.clone())
}

/// The generated document, completed with what holds for every operation:
/// errors are `application/problem+json` (utoipa writes `application/json`
/// for the documented ones), any operation may answer with another error
/// status (a `default` response: 400 for a malformed body or path, 401
/// without the token, 404, 405, 413 over the body limit, 422), and the
/// bearer-token security scheme.
fn contract(doc: utoipa::openapi::OpenApi) -> Value {
    let mut doc = serde_json::to_value(doc).expect("the OpenAPI document serialises");
    let problem = json!({"schema": {"$ref": "#/components/schemas/Problem"}});
    if let Some(paths) = doc["paths"].as_object_mut() {
        for operation in paths.values_mut().filter_map(Value::as_object_mut) {
            for op in operation.values_mut() {
                let Some(responses) = op["responses"].as_object_mut() else {
                    continue;
                };
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
                responses.insert(
                    "default".into(),
                    json!({
                        "description": "An error, as RFC 9457 problem details",
                        "content": {"application/problem+json": problem.clone()},
                    }),
                );
                op["security"] = json!([{"bearer": []}, {}]);
            }
        }
    }
    doc["components"]["securitySchemes"] = json!({
        "bearer": {"type": "http", "scheme": "bearer",
                   "description": "The admin, worker or read token, as configured"}
    });
    doc
}
