//! User-defined grid cases: dimensions, an exposure table and a simulation
//! program, named in a case file ([`file`]), so a new scenario type needs
//! no Rust and no redeployment (docs/bring-your-own.md).
//!
//! The simulation is an external program in episode mode: it receives the
//! scenario's values by dimension name and returns the outcome and a
//! criticality in `[0, 1]` (0 for the event). Vehicles are programs only.
//! Workers run them as they run any program (`--vut-exec NAME=COMMAND`);
//! the command line runs them itself through a [`ProgramHost`], which is
//! how a program becomes a surrogate (library search), a vehicle of an
//! in-process campaign or the subject of an exact answer by enumeration.
//!
//! Library search takes `P(S|x)` as the event (the programs are
//! deterministic) and, for multistart, the objective
//! `J(x) = criticality(x) + w d(x, Ω)` with `Ω` the box of the central 80%
//! of the exposure's marginal along each dimension, distances normalised
//! by each dimension's span (the paper's form, with `Ω` from the data).

pub mod descriptor;
pub mod file;
pub mod registry;

use crate::case::{Case, SurrogateEvaluation};
use crate::external::{DriverError, ExternalMode, ExternalVehicle, ProgramHost, TestStart};
use crate::grid::{Axis, Grid};
use crate::long_table::{block_with, check_sum, only_blocks, parse_blocks, KeyAxis};
use crate::mass::GridMass;
use crate::ndd_table::TableError;
use file::CaseFile;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex, OnceLock};

/// A user-defined grid case, opened.
pub struct UserCase {
    file: CaseFile,
    name: &'static str,
    exposure: GridMass,
    exposure_name: String,
    /// The box `Ω` of the multistart objective: per dimension `[low, high]`
    /// and the span that normalises distances.
    omega: Vec<(f64, f64, f64)>,
    /// The block a program is told at each reset.
    world: serde_json::Value,
    /// Programs run in this process, when the caller has some.
    host: Option<Arc<dyn ProgramHost>>,
    /// Why a program run here failed, first failure only: everything after
    /// it is void ([`Case::failure`]).
    failure: Arc<Mutex<Option<String>>>,
}

/// A program as a vehicle this process runs: each scenario once,
/// remembered (the program is deterministic).
pub struct UserVehicle {
    program: String,
    host: Arc<dyn ProgramHost>,
    runs: Vec<OnceLock<(bool, f64)>>,
}

impl std::fmt::Debug for UserVehicle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "UserVehicle({})", self.program)
    }
}

/// Written as the program it is; never read back (a user case has no
/// built-in vehicles: a specification names a program).
impl Serialize for UserVehicle {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        serde_json::json!({"external": self.program, "mode": "episode"}).serialize(s)
    }
}

impl<'de> Deserialize<'de> for UserVehicle {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let _ = serde_json::Value::deserialize(d)?;
        Err(serde::de::Error::custom(
            "a user-defined case has no built-in vehicles: name a program, {\"external\": NAME}",
        ))
    }
}

/// The texts [`intern`] leaked.
static INTERNED: Mutex<Vec<&'static str>> = Mutex::new(Vec::new());

/// Whether `text` was interned (a test's probe for leaks).
#[cfg(test)]
pub(crate) fn interned(text: &str) -> bool {
    let names = INTERNED.lock().unwrap_or_else(|p| p.into_inner());
    names.contains(&text)
}

/// Interns a case name: descriptors and errors hold `&'static str`, and a
/// process opens few distinct user cases.
fn intern(name: &str) -> &'static str {
    let mut names = INTERNED.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(&found) = names.iter().find(|&&n| n == name) {
        return found;
    }
    let leaked: &'static str = Box::leak(name.to_owned().into_boxed_str());
    names.push(leaked);
    leaked
}

impl UserCase {
    /// The case of `file` on the exposure table `table` (named `table_name`:
    /// the case file's own, or one given in its place), with `host` to run
    /// programs here, if any.
    pub fn open(
        file: CaseFile,
        table_name: String,
        table: &str,
        host: Option<Arc<dyn ProgramHost>>,
    ) -> Result<Self, TableError> {
        let grid = Grid::new(
            file.dimensions
                .iter()
                .map(|d| Axis::uniform(&d.name, d.lower, d.step, d.count()))
                .collect::<Result<Vec<_>, _>>()
                .map_err(TableError::Labels)?,
        )
        .map_err(TableError::Labels)?;
        let exposure = exposure(&file, grid, table)?;
        let omega = central_box(&exposure, &file);
        let world = serde_json::json!({
            "case": file.name,
            "event": file.event,
            "dimensions": file.dimensions.iter().map(|d| serde_json::json!({
                "name": d.name, "unit": d.unit, "lower": d.lower, "upper": d.upper, "step": d.step,
            })).collect::<Vec<_>>(),
        });
        Ok(Self {
            name: intern(&file.name),
            file,
            exposure,
            exposure_name: table_name,
            omega,
            world,
            host,
            failure: Arc::new(Mutex::new(None)),
        })
    }

    /// The case file.
    pub fn file(&self) -> &CaseFile {
        &self.file
    }

    /// `d(x, Ω)`: `√((1/m) Σ (distance to Ω along i / span_i)²)`.
    fn distance(&self, cell: usize) -> f64 {
        let grid = self.grid();
        let sum: f64 = self
            .omega
            .iter()
            .enumerate()
            .map(|(i, &(low, high, span))| {
                let x = grid.value(cell, i);
                ((low - x).max(x - high).max(0.0) / span).powi(2)
            })
            .sum();
        (sum / self.omega.len() as f64).sqrt()
    }

    /// Event and criticality of program `vehicle` in `cell`, run once.
    fn outcome(&self, vehicle: &UserVehicle, cell: usize) -> (bool, f64) {
        *vehicle.runs[cell].get_or_init(|| {
            if self.failure().is_some() {
                return (false, 1.0);
            }
            let start = TestStart {
                case: self.name,
                mode: ExternalMode::Episode,
                index: cell as u64,
                // Run once per cell, remembered: a fixed seed per cell.
                noise_seed: crate::noise::noise_seed(0, cell as u64),
                world: &self.world,
            };
            let run = vehicle.host.converse(&vehicle.program, &|vut| {
                vut.reset(&start)?;
                self.external_event_and_criticality(vut, ExternalMode::Episode, cell)
            });
            match run {
                Ok((true, _)) => (true, 0.0),
                Ok((false, criticality)) => (false, criticality.unwrap_or(1.0)),
                Err(reason) => {
                    let mut failure = self.failure.lock().unwrap_or_else(|p| p.into_inner());
                    failure.get_or_insert_with(|| {
                        format!(
                            "program `{}` on scenario {}: {reason}",
                            vehicle.program,
                            self.external_scenario(cell)
                        )
                    });
                    (false, 1.0)
                }
            }
        })
    }
}

/// The exposure of `table` (long form: one column per dimension, then
/// `probability`) on `grid`.
fn exposure(file: &CaseFile, grid: Grid, table: &str) -> Result<GridMass, TableError> {
    let mut columns: Vec<&str> = file.dimensions.iter().map(|d| d.name.as_str()).collect();
    columns.push("probability");
    let blocks = parse_blocks(table)?;
    only_blocks(&blocks, &[&columns])?;
    let block = block_with(&blocks, &columns, "the exposure P(x)")?;
    let axes: Vec<KeyAxis<'_>> = file
        .dimensions
        .iter()
        .map(|d| KeyAxis {
            column: &d.name,
            start: d.lower,
            step: d.step,
            count: d.count(),
        })
        .collect();
    let (mass, sum) = block.dense(&axes)?;
    check_sum(sum)?;
    GridMass::from_weights(grid, mass).map_err(|e| TableError::Unusable(e.to_string()))
}

/// Per dimension the central 80% of the exposure's marginal and the span.
fn central_box(exposure: &GridMass, file: &CaseFile) -> Vec<(f64, f64, f64)> {
    let grid = exposure.grid();
    file.dimensions
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let mut marginal = vec![0.0; d.count()];
            for cell in 0..grid.len() {
                let k = grid.axes()[i].nearest_index(grid.value(cell, i));
                marginal[k] += exposure.p(cell);
            }
            let quantile = |q: f64| {
                let mut acc = 0.0;
                for (k, m) in marginal.iter().enumerate() {
                    acc += m;
                    if acc >= q {
                        return d.lower + k as f64 * d.step;
                    }
                }
                d.upper
            };
            let span = (d.upper - d.lower).max(d.step);
            (quantile(0.1), quantile(0.9), span)
        })
        .collect()
}

impl Case for UserCase {
    type Vehicle = UserVehicle;

    fn name(&self) -> &'static str {
        self.name
    }

    fn exposure(&self) -> &GridMass {
        &self.exposure
    }

    fn exposure_name(&self) -> &str {
        &self.exposure_name
    }

    fn picture_axes(&self) -> (usize, usize) {
        (0, if self.file.dimensions.len() > 1 { 1 } else { 0 })
    }

    fn is_event(&self, vehicle: &UserVehicle, cell: usize) -> bool {
        self.outcome(vehicle, cell).0
    }

    fn criticality(&self, vehicle: &UserVehicle, cell: usize) -> f64 {
        self.outcome(vehicle, cell).1
    }

    fn event_and_criticality(&self, vehicle: &UserVehicle, cell: usize) -> (bool, f64) {
        self.outcome(vehicle, cell)
    }

    fn external_world(&self) -> serde_json::Value {
        self.world.clone()
    }

    fn external_step_event_and_criticality(
        &self,
        _: &mut dyn ExternalVehicle,
        _: usize,
    ) -> Result<(bool, Option<f64>), DriverError> {
        Err(DriverError(format!(
            "case {} runs its programs in episode mode: its simulation is the program",
            self.name
        )))
    }

    fn evaluate_surrogate(&self, surrogate: &UserVehicle, cell: usize) -> SurrogateEvaluation {
        let (event, criticality) = self.outcome(surrogate, cell);
        SurrogateEvaluation {
            challenge: if event { 1.0 } else { 0.0 },
            objective: criticality + self.file.objective_weight * self.distance(cell),
        }
    }

    fn surrogate_challenge(&self, surrogate: &UserVehicle, cell: usize) -> f64 {
        if self.outcome(surrogate, cell).0 {
            1.0
        } else {
            0.0
        }
    }

    /// The simulation is the program: it runs whole scenarios.
    fn external_modes(&self) -> &'static [ExternalMode] {
        &[ExternalMode::Episode]
    }

    /// A program this process can run, named as a campaign names it.
    fn resolve_vehicle(&self, spec: &serde_json::Value) -> Option<UserVehicle> {
        let host = self.host.as_ref()?;
        let program = spec.get("external")?.as_str()?;
        host.has(program).then(|| UserVehicle {
            program: program.to_owned(),
            host: Arc::clone(host),
            runs: (0..self.grid().len()).map(|_| OnceLock::new()).collect(),
        })
    }

    fn failure(&self) -> Option<String> {
        self.failure
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
}
