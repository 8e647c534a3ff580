//! A vehicle specification named for people: its model or program and the
//! parameters it sets. The CLI narrows these to the ones that differ from
//! the model's defaults where it knows them; figures and other readers of
//! a campaign's JSON show what the specification sets.

use serde_json::Value;

/// Keys of a specification that are not parameters: what it is, how a
/// program runs, and the noise (shown on its own).
const NOT_PARAMETERS: [&str; 4] = ["model", "external", "mode", "noise"];

/// The model's or program's name: `idm`, `external cutin-idm`.
pub fn vehicle_base_name(spec: &Value) -> String {
    match (spec.get("model"), spec.get("external")) {
        (Some(Value::String(model)), _) => model.clone(),
        (_, Some(Value::String(program))) => format!("external {program}"),
        _ => "?".to_owned(),
    }
}

/// The numeric parameters a specification sets, in its key order.
pub fn given_parameters(spec: &Value) -> Vec<(String, f64)> {
    spec.as_object()
        .into_iter()
        .flatten()
        .filter(|(key, _)| !NOT_PARAMETERS.contains(&key.as_str()))
        .filter_map(|(key, value)| Some((key.clone(), value.as_f64()?)))
        .collect()
}

/// `name (k v, …)` of the parameters given, with the noise when positive.
pub fn vehicle_label(spec: &Value) -> String {
    let mut parts: Vec<String> = given_parameters(spec)
        .into_iter()
        .map(|(key, value)| format!("{key} {value}"))
        .collect();
    if let Some(noise) = spec
        .get("noise")
        .and_then(Value::as_f64)
        .filter(|n| *n > 0.0)
    {
        parts.push(format!("noise {noise}"));
    }
    let name = vehicle_base_name(spec);
    if parts.is_empty() {
        name
    } else {
        format!("{name} ({})", parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_label_names_the_model_and_what_the_specification_sets() {
        assert_eq!(vehicle_label(&json!({"model": "idm"})), "idm");
        assert_eq!(
            vehicle_label(&json!({"model": "idm", "v0": 25})),
            "idm (v0 25)"
        );
        assert_eq!(
            vehicle_label(&json!({"external": "py", "mode": "episode", "noise": 0.5})),
            "external py (noise 0.5)"
        );
        assert_eq!(vehicle_label(&json!({"model": "idm", "noise": 0})), "idm");
    }
}
