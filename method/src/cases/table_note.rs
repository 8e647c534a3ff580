//! The note a case attaches to an exposure table a user gave it.

/// What a user should know about an exposure table once read: how far it
/// lies from the case's built-in model (total variation distance
/// `½ Σ |P − P_builtin|` on the grid; `None` when the built-in model puts
/// no mass on the table's grid, which lies beyond what it was fitted on) and
/// whether its sum was renormalised.
pub(crate) fn table_note(name: &str, sum: f64, distance: Option<f64>) -> String {
    let mut note = match distance {
        Some(distance) => format!(
            "exposure table {name}: total variation distance {distance:.3} from the built-in \
             model"
        ),
        None => format!(
            "exposure table {name}: the built-in model puts no mass on its grid (beyond the \
             ranges it was fitted on), so no distance from it"
        ),
    };
    if (sum - 1.0).abs() > 1e-12 {
        note.push_str(&format!("; it sums to {sum:.7} and was renormalised to 1"));
    }
    note
}
