//! What car-following tests are drawn from: `P(s)` over the initial states
//! `s = (v, R, Ṙ)` of the grid, and `P(u|v)`, the background vehicle's
//! action law at each grid speed; from the built-in model
//! ([`super::FollowExposureModel`]) or from the user's tables.
//!
//! Tables are one file of two long blocks ([`crate::long_table`]):
//!
//! ```text
//! # P(s): the initial states of car-following on the state grid
//! speed,range,range_rate,probability
//! 30,40,0,0.00071
//! …
//!
//! # P(u | v): the BV's acceleration per one-second decision at each speed
//! speed,acceleration,probability
//! 30,-4,0.00002
//! …
//! ```
//!
//! `P(s)` sums to 1 and puts no mass where the range is at the accident
//! range or below (an accident has happened); `P(u | v)` gives, for every
//! grid speed, a law over the 31 accelerations that sums to 1.

use super::exposure_model::FollowExposureModel;
use super::states::StateGrid;
use super::world::FollowWorld;
use crate::long_table::{block_with, check_sum, only_blocks, parse_blocks, KeyAxis};
use crate::ndd_table::TableError;
use crate::number::Num;

/// The columns of the `P(s)` block.
pub const STATE_COLUMNS: [&str; 4] = ["speed", "range", "range_rate", "probability"];
/// The columns of the `P(u|v)` block.
pub const ACTION_COLUMNS: [&str; 3] = ["speed", "acceleration", "probability"];

/// `P(s)` on the state grid and `P(u|v)` per grid speed.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowExposure {
    /// `P(s)` per grid state, summing to 1.
    pub initial: Vec<f64>,
    /// `P(u|v)` as `speeds × actions` (row `i` for the grid speed
    /// `v_min + i · step`), each row summing to 1.
    pub actions: Vec<f64>,
}

impl FollowExposure {
    /// The built-in `model` on `grid`.
    pub fn from_model(model: &FollowExposureModel, world: &FollowWorld, grid: &StateGrid) -> Self {
        Self {
            initial: model.initial_states(world, grid),
            actions: model.actions_by_speed(world, grid),
        }
    }

    /// The exposure of tables `text`, and the sum of its `P(s)` as read
    /// (renormalised to 1 when off by less than the tolerance).
    pub fn from_tables(
        text: &str,
        world: &FollowWorld,
        grid: &StateGrid,
    ) -> Result<(Self, f64), TableError> {
        let blocks = parse_blocks(text)?;
        only_blocks(&blocks, &[&STATE_COLUMNS, &ACTION_COLUMNS])?;
        let axis = |column, (start, count): (f64, usize)| KeyAxis {
            column,
            start,
            step: grid.step,
            count,
        };
        let speed = axis("speed", grid.speed);
        let states = block_with(&blocks, &STATE_COLUMNS, "P(s)")?;
        let (mut initial, sum) = states.dense(&[
            speed,
            axis("range", grid.range),
            axis("range_rate", grid.range_rate),
        ])?;
        check_sum(sum)?;
        if let Some(s) = (0..grid.len())
            .find(|&s| initial[s] > 0.0 && grid.state(s).range <= world.accident_range)
        {
            let x = grid.state(s);
            return Err(TableError::Unusable(format!(
                "P(s) puts mass on the state speed {}, range {}, range_rate {}: a range of at \
                 most {} m is an accident that has happened, not an initial state",
                Num(x.bv_speed),
                Num(x.range),
                Num(x.range_rate),
                Num(world.accident_range)
            )));
        }
        initial.iter_mut().for_each(|p| *p /= sum);
        let acceleration = KeyAxis {
            column: "acceleration",
            start: world.u_min,
            step: world.u_step,
            count: world.actions,
        };
        let laws = block_with(&blocks, &ACTION_COLUMNS, "P(u | v)")?;
        let (mut actions, _) = laws.dense(&[speed, acceleration])?;
        for (i, row) in actions.chunks_mut(world.actions).enumerate() {
            let v = grid.speed.0 + i as f64 * grid.step;
            let total: f64 = row.iter().sum();
            if total == 0.0 {
                return Err(TableError::Unusable(format!(
                    "P(u | v) has no law at speed {}: every grid speed ({} to {} m/s) needs one",
                    Num(v),
                    Num(grid.speed.0),
                    Num(grid.speed.0 + (grid.speed.1 - 1) as f64 * grid.step)
                )));
            }
            check_sum(total).map_err(|_| {
                TableError::Unusable(format!(
                    "P(u | v) at speed {} sums to {total}, which differs from 1 by more than {}",
                    Num(v),
                    crate::tolerance::MASS_SUM_TOLERANCE
                ))
            })?;
            row.iter_mut().for_each(|p| *p /= total);
        }
        Ok((Self { initial, actions }, sum))
    }

    /// The total variation distance to `other` of `P(s)`, and the largest
    /// over the grid speeds of `P(u|v)`'s.
    pub fn distance(&self, other: &FollowExposure, actions: usize) -> (f64, f64) {
        let tv =
            |a: &[f64], b: &[f64]| 0.5 * a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>();
        let laws = self
            .actions
            .chunks(actions)
            .zip(other.actions.chunks(actions))
            .map(|(a, b)| tv(a, b))
            .fold(0.0, f64::max);
        (tv(&self.initial, &other.initial), laws)
    }

    /// The exposure written as tables that [`FollowExposure::from_tables`]
    /// reads back to it.
    pub fn to_tables(&self, world: &FollowWorld, grid: &StateGrid) -> String {
        use crate::number::Label;
        let mut text = String::from(
            "# P(s): initial states (BV speed m/s, bumper range m, range rate m/s)\n\
             speed,range,range_rate,probability\n",
        );
        for (s, &p) in self.initial.iter().enumerate() {
            if p > 0.0 {
                let x = grid.state(s);
                text.push_str(&format!(
                    "{},{},{},{p:e}\n",
                    Label(x.bv_speed),
                    Label(x.range),
                    Label(x.range_rate)
                ));
            }
        }
        text.push_str(
            "\n# P(u | v): the BV's acceleration (m/s²) per decision at each speed\n\
             speed,acceleration,probability\n",
        );
        for (i, row) in self.actions.chunks(world.actions).enumerate() {
            let v = grid.speed.0 + i as f64 * grid.step;
            for (k, &p) in row.iter().enumerate() {
                if p > 0.0 {
                    text.push_str(&format!("{},{},{p:e}\n", Label(v), Label(world.action(k))));
                }
            }
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setting() -> (FollowWorld, StateGrid, FollowExposure) {
        let (world, grid) = (FollowWorld::paper(), StateGrid::paper());
        let builtin = FollowExposure::from_model(&FollowExposureModel::default(), &world, &grid);
        (world, grid, builtin)
    }

    #[test]
    fn the_builtin_model_written_as_tables_reads_back_to_itself() {
        let (world, grid, builtin) = setting();
        let (read, sum) =
            FollowExposure::from_tables(&builtin.to_tables(&world, &grid), &world, &grid).unwrap();
        assert!((sum - 1.0).abs() < 1e-9);
        let (states, laws) = read.distance(&builtin, world.actions);
        assert!(states < 1e-12 && laws < 1e-12, "{states} {laws}");
    }

    #[test]
    fn bad_tables_say_why() {
        let (world, grid, builtin) = setting();
        let tables = builtin.to_tables(&world, &grid);
        let (states, laws) = tables.split_once("\n\n").unwrap();
        let err = |text: &str| {
            FollowExposure::from_tables(text, &world, &grid)
                .unwrap_err()
                .to_string()
        };
        assert!(err(states).contains("P(u | v) is missing"));
        assert!(err(laws).contains("P(s) is missing"));
        // A law missing at one speed.
        let without_40: String = laws
            .lines()
            .filter(|l| !l.starts_with("40,"))
            .map(|l| format!("{l}\n"))
            .collect();
        assert!(err(&format!("{states}\n\n{without_40}")).contains("no law at speed 40"));
        // Mass at the accident range.
        let at_one = "speed,range,range_rate,probability\n30,1,0,1\n";
        assert!(err(&format!("{at_one}\n{laws}")).contains("an accident that has happened"));
        // Off the grid, and a law that does not sum to 1.
        let off = "speed,range,range_rate,probability\n30.5,20,0,1\n";
        assert!(err(&format!("{off}\n{laws}")).contains("speed = 30.5 is not on the grid"));
        let one_state = "speed,range,range_rate,probability\n30,20,0,1\n";
        let bad_law = format!(
            "{one_state}\nspeed,acceleration,probability\n{}",
            (0..21)
                .map(|i| format!("{},0,{}\n", 20 + i, if i == 3 { 0.5 } else { 1.0 }))
                .collect::<String>()
        );
        assert!(err(&bad_law).contains("P(u | v) at speed 23 sums to 0.5"));
    }
}
