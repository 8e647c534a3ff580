//! A vehicle specification named for people: its model or program and the
//! parameters it sets that differ from the model's defaults (`idm (v0
//! 25)`), with the noise on its commands. Specifications are stored
//! normalised, every parameter filled in, so naming what is set would name
//! every parameter: the defaults are each case's models' own.

use crate::cases::highway::ExitVehicle;
use crate::vehicle::VehicleModel;
use serde_json::Value;

/// Keys of a specification that are not parameters: what it is, how a
/// program runs, and the noise (named on its own).
const NOT_PARAMETERS: [&str; 4] = ["model", "external", "mode", "noise"];

/// `spec`'s name on case `case` with the parameters that differ from its
/// model's defaults there and its noise: `idm`, `idm (v0 25)`,
/// `mobil (politeness 0.5)`, `acc-aeb (actuator_lag 0.3, noise 0.5)`. The
/// car-following case has defaults of its own (the IDM desires 36 m/s);
/// a program's specification (`{"external": …}`) is named with the
/// numbers it sets.
pub fn vehicle_label(spec: &Value, case: &str) -> String {
    if let Ok(model) = serde_json::from_value::<VehicleModel>(spec.clone()) {
        let bare = serde_json::json!({ "model": model.name() });
        let defaults = match case {
            "car-following" => crate::cases::carfollow::CarFollowing::vehicle(&bare).ok(),
            _ => VehicleModel::builtin(model.name()).ok(),
        };
        if let Some(defaults) = defaults {
            return model.label(&defaults);
        }
    }
    // Another case's model (highway exit's), or a program.
    let defaults = spec
        .get("model")
        .and_then(|name| {
            serde_json::from_value::<ExitVehicle>(serde_json::json!({ "model": name })).ok()
        })
        .and_then(|v| serde_json::to_value(v).ok());
    let mut parts: Vec<String> = spec
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(key, _)| !NOT_PARAMETERS.contains(&key.as_str()))
        .filter(|(key, value)| defaults.as_ref().and_then(|d| d.get(*key)) != Some(*value))
        .filter_map(|(key, value)| Some(format!("{key} {}", value.as_f64()?)))
        .collect();
    if let Some(noise) = spec
        .get("noise")
        .filter(|_| crate::noise::spec_is_noisy(spec))
    {
        parts.push(format!("noise {noise}"));
    }
    let name = spec
        .get("model")
        .or_else(|| spec.get("external"))
        .and_then(Value::as_str)
        .unwrap_or("?");
    if parts.is_empty() {
        name.to_owned()
    } else {
        format!("{name} ({})", parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_label_names_what_differs_from_the_models_defaults() {
        let cut_in = |spec: Value| vehicle_label(&spec, "cut-in");
        assert_eq!(cut_in(json!({"model": "idm", "v0": 25})), "idm (v0 25)");
        // Car-following's IDM desires 36 m/s and measures the bumper gap:
        // as stored, it is the plain IDM there, and 18 m/s is a change.
        let stored = |spec: Value| {
            serde_json::to_value(crate::cases::carfollow::CarFollowing::vehicle(&spec).unwrap())
                .unwrap()
        };
        let following = |spec: Value| vehicle_label(&stored(spec), "car-following");
        assert_eq!(following(json!({"model": "idm"})), "idm");
        assert_eq!(following(json!({"model": "idm", "v0": 18})), "idm (v0 18)");
        assert_eq!(following(json!({"model": "acc-aeb"})), "acc-aeb");
        // Stored specifications are normalised: every default is written.
        let mobil = serde_json::to_value(
            serde_json::from_value::<ExitVehicle>(json!({"model": "mobil", "politeness": 0.5}))
                .unwrap(),
        )
        .unwrap();
        assert!(mobil.as_object().unwrap().len() > 5, "{mobil}");
        assert_eq!(
            vehicle_label(&mobil, "highway-exit"),
            "mobil (politeness 0.5)"
        );
        assert_eq!(
            vehicle_label(&json!({"model": "mobil"}), "highway-exit"),
            "mobil"
        );
        assert_eq!(
            cut_in(json!({"external": "py", "mode": "episode", "noise": 0.5})),
            "py (noise 0.5)"
        );
    }
}
