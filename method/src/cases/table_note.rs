//! The note a case attaches to an exposure table a user gave it.

/// What a user should know about an exposure table once read: how far it
/// lies from the case's built-in model (total variation distance
/// `½ Σ |P − P_builtin|` on the grid) and whether its sum was renormalised.
pub(crate) fn table_note(name: &str, sum: f64, distance: f64) -> String {
    let mut note = format!(
        "exposure table {name}: total variation distance {distance:.3} from the built-in model"
    );
    if (sum - 1.0).abs() > 1e-12 {
        note.push_str(&format!("; it sums to {sum:.7} and was renormalised to 1"));
    }
    note
}
