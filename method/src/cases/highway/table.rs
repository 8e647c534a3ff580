//! Highway-exit exposure tables: the paper's `P(x) = P(p₁) P(v₁, R, v₂)`
//! with `P(v₁, R, v₂)` given by the user (the paper takes it from the
//! car-following events of naturalistic data) and `p₁` uniform over a range
//! of the road, by default the whole grid.
//!
//! The file is a long table ([`crate::long_table`]):
//!
//! ```text
//! # P(v1, R, v2): speeds on the grid's speeds, R = p1 − p2 (m) a multiple of
//! # its position step
//! v1,range,v2,probability
//! 29,40,29,0.0012
//! …
//!
//! # optional: the range of the leading vehicle's position p1
//! p1_min,p1_max
//! -50,150
//! ```
//!
//! On a grid cell `(p₁, v₁, p₂, v₂)` the exposure is the table's
//! `P(v₁, p₁ − p₂, v₂)` where `p₁` lies in its range (0 elsewhere), then
//! normalised over the grid, as the built-in model is
//! ([`super::ExitExposureModel::mass_on`]).

use crate::grid::Grid;
use crate::long_table::{block_with, check_sum, only_blocks, parse_blocks, KeyAxis};
use crate::mass::GridMass;
use crate::ndd_table::TableError;
use crate::number::Num;

/// The columns of the `P(v₁, R, v₂)` block.
pub const JOINT_COLUMNS: [&str; 4] = ["v1", "range", "v2", "probability"];
/// The columns of the optional block giving the range of `p₁`.
pub const P1_COLUMNS: [&str; 2] = ["p1_min", "p1_max"];

/// The key axes of the `P(v₁, R, v₂)` block on `grid` (`p₁, v₁, p₂, v₂`):
/// the speeds of the grid, and the ranges `R = p₁ − p₂ > 0` it can hold.
fn axes(grid: &Grid) -> [KeyAxis<'static>; 3] {
    let positions = &grid.axes()[0];
    let speeds = &grid.axes()[1];
    let (dp, dv) = (
        positions.value(1) - positions.value(0),
        speeds.value(1) - speeds.value(0),
    );
    let speed = |column| KeyAxis {
        column,
        start: speeds.value(0),
        step: dv,
        count: speeds.len(),
    };
    [
        speed("v1"),
        KeyAxis {
            column: "range",
            start: dp,
            step: dp,
            count: positions.len() - 1,
        },
        speed("v2"),
    ]
}

/// The exposure the table `text` gives on `grid`, and the sum of its
/// `P(v₁, R, v₂)` as read (renormalised to 1 when off by less than the
/// tolerance; the caller reports it).
pub fn exposure_from_table(text: &str, grid: Grid) -> Result<(GridMass, f64), TableError> {
    let blocks = parse_blocks(text)?;
    only_blocks(&blocks, &[&JOINT_COLUMNS, &P1_COLUMNS])?;
    let joint = block_with(&blocks, &JOINT_COLUMNS, "P(v1, R, v2)")?;
    let [v1, range, v2] = axes(&grid);
    let (table, sum) = joint.dense(&[v1, range, v2])?;
    check_sum(sum)?;
    let positions = &grid.axes()[0];
    let (first, last) = (positions.value(0), positions.value(positions.len() - 1));
    let (low, high) = match blocks.iter().find(|b| b.has_columns(&P1_COLUMNS)) {
        None => (first, last),
        Some(block) => {
            let [(line, row)] = block.rows.as_slice() else {
                return Err(TableError::Unusable(format!(
                    "line {}: the p1_min,p1_max block holds one row, not {}",
                    block.line,
                    block.rows.len()
                )));
            };
            let at = |name: &str| row[block.columns.iter().position(|c| c == name).unwrap()];
            let (low, high) = (at("p1_min"), at("p1_max"));
            if !(first <= low && low <= high && high <= last) {
                return Err(TableError::Unusable(format!(
                    "line {line}: the range of p1, [{}, {}] m, must be an interval inside the \
                     road section [{}, {}] m",
                    Num(low),
                    Num(high),
                    Num(first),
                    Num(last)
                )));
            }
            (low, high)
        }
    };
    let step = range.step;
    let speeds = v1.count;
    let weights: Vec<f64> = (0..grid.len())
        .map(|cell| {
            let x = grid.values(cell);
            let r = x[0] - x[2];
            if r <= 0.0 || x[0] < low - 1e-9 || x[0] > high + 1e-9 {
                return 0.0;
            }
            let (i1, ir, i2) = (
                grid.axes()[1].nearest_index(x[1]),
                (r / step).round() as usize - 1,
                grid.axes()[3].nearest_index(x[3]),
            );
            table[(i1 * range.count + ir) * speeds + i2]
        })
        .collect();
    let mass = GridMass::from_weights(grid, weights).map_err(|_| {
        TableError::Unusable(format!(
            "the table puts no probability on a scenario of this grid: no (v1, R, v2) with \
             mass has a p1 in [{}, {}] m with p1 − R on the road",
            Num(low),
            Num(high)
        ))
    })?;
    Ok((mass, sum))
}

/// The built-in model's `P(v₁, R, v₂)` on `grid`'s speeds and ranges, as a
/// table [`exposure_from_table`] reads back to the built-in exposure.
pub fn builtin_table(model: &super::ExitExposureModel, grid: &Grid) -> String {
    use crate::number::Label;
    let [v1, range, v2] = axes(grid);
    let value = |a: &KeyAxis<'_>, k: usize| a.start + k as f64 * a.step;
    let mut points = Vec::new();
    for i in 0..v1.count {
        for r in 0..range.count {
            for j in 0..v2.count {
                let (a, b, c) = (value(&v1, i), value(&range, r), value(&v2, j));
                points.push((a, b, c, model.density(a, b, c)));
            }
        }
    }
    let total: f64 = points.iter().map(|p| p.3).sum();
    let mut text = String::from(
        "# P(v1, R, v2) of the built-in model (docs/models.md), R = p1 - p2\nv1,range,v2,probability\n",
    );
    for (a, b, c, d) in points {
        if d > 0.0 {
            let (a, b, c) = (Label(a), Label(b), Label(c));
            text.push_str(&format!("{a},{b},{c},{:e}\n", d / total));
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::highway::{exit_grid, ExitExposureModel};

    #[test]
    fn the_builtin_model_written_as_a_table_reads_back_to_itself() {
        let grid = exit_grid(20.0, 4.0);
        let model = ExitExposureModel::default();
        let (mass, sum) = exposure_from_table(&builtin_table(&model, &grid), grid.clone()).unwrap();
        assert!((sum - 1.0).abs() < 1e-9, "{sum}");
        let builtin = model.mass_on(grid);
        assert!(mass.total_variation(&builtin) < 1e-12);
    }

    #[test]
    fn a_p1_range_restricts_the_leader_and_bad_tables_say_why() {
        let grid = exit_grid(20.0, 4.0);
        let one = "v1,range,v2,probability\n28,40,28,1\n";
        let (all, _) = exposure_from_table(one, grid.clone()).unwrap();
        let (some, _) =
            exposure_from_table(&format!("{one}\np1_min,p1_max\n0,100\n"), grid.clone()).unwrap();
        let cells = |m: &GridMass| {
            (0..grid.len())
                .filter(|&c| m.p(c) > 0.0)
                .map(|c| grid.value(c, 0))
                .collect::<Vec<_>>()
        };
        // p1 from −60 (p2 = −100) to 200 without a range; 0 … 100 with it.
        assert_eq!(cells(&all).len(), 14);
        assert!(cells(&some).iter().all(|&p1| (0.0..=100.0).contains(&p1)));
        assert_eq!(cells(&some).len(), 6);
        let err = |text: &str| {
            exposure_from_table(text, grid.clone())
                .unwrap_err()
                .to_string()
        };
        assert!(err("v1,range,v2,probability\n28,30,28,1\n")
            .contains("range = 30 is not on the grid (20 to 300 in steps of 20)"));
        assert!(err("v1,range,v2,probability\n28,40,28,0.5\n").contains("sum to 0.5"));
        assert!(err(&format!("{one}\np1_min,p1_max\n150,120\n")).contains("must be an interval"));
        assert!(err("v1,range,probability\n28,40,1\n").contains("not one this case reads"));
        assert!(err("p1_min,p1_max\n0,100\n").contains("P(v1, R, v2) is missing"));
        // Mass only at a range no leader position in the range can hold.
        assert!(
            err("v1,range,v2,probability\n28,300,28,1\n\np1_min,p1_max\n0,100\n")
                .contains("no probability on a scenario of this grid")
        );
    }
}
