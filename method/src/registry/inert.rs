//! Whether a vehicle's parameters change any accident of the case's
//! preset: a user who sets `{"model": "idm", "v0": 25}` on cut-in's
//! paper-code preset gets exactly the plain IDM's answer (no accident
//! there depends on the free-road term), and should be told once.

use super::ExactAnswers;

/// Whether `vut`'s parameters that differ from its model's defaults on
/// `case` leave its exact `P(A)` (`exact`, already enumerated) unchanged to
/// the bit; `None` when it sets none (or is a program), or the defaults'
/// `P(A)` cannot be enumerated.
pub fn parameters_inert(
    case: &dyn ExactAnswers,
    vut: &serde_json::Value,
    exact: f64,
) -> Option<bool> {
    let name = vut.get("model")?.as_str()?;
    let case_name = case.descriptor().name;
    let plain = case
        .normalise_vehicle(&serde_json::json!({ "model": name }))
        .ok()?;
    let label = |spec| crate::cases::vehicle_label(spec, case_name);
    if label(vut) == label(&plain) {
        return None;
    }
    let defaults = case.exact_event_probability(&plain).ok()?;
    Some(defaults.to_bits() == exact.to_bits())
}
