//! The car-following case as a service runs it: a preset (world, grid and
//! exposure), the case's vehicle defaults, library learning and campaign
//! samplers.

use super::exposure::FollowExposure;
use super::exposure_model::FollowExposureModel;
use super::library::{
    dynamic_programming, temporal_difference, PolicyLibrary, Transitions, Zone, DP_MAX_SWEEPS,
    TD_MAX_UPDATES,
};
use super::sampling::FollowSampler;
use super::states::StateGrid;
use super::world::FollowWorld;
use crate::progress::Progress;
use crate::vehicle::VehicleModel;

use std::str::FromStr;

/// The world and exposure in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FollowPreset {
    /// The paper's world and grid with the built-in exposure
    /// (`docs/models.md`): `P(A)` of the order of 10⁻⁶.
    #[default]
    Paper,
    /// The same world and grid on a road with short headways (median 0.8 s)
    /// and harsher braking (`λ_brake` 1.5 m/s²): `P(A)` of the order of
    /// 10⁻³, so NDD baselines finish in seconds (tests and quick demos).
    Risky,
}

impl FollowPreset {
    /// The preset's name on the wire (`paper`, `risky`).
    pub fn name(self) -> &'static str {
        match self {
            FollowPreset::Paper => "paper",
            FollowPreset::Risky => "risky",
        }
    }

    /// The preset's built-in exposure model.
    pub fn exposure(self) -> FollowExposureModel {
        match self {
            FollowPreset::Paper => FollowExposureModel::default(),
            FollowPreset::Risky => FollowExposureModel {
                brake_scale: 1.5,
                headway_median: 0.8,
                ..FollowExposureModel::default()
            },
        }
    }
}

impl FromStr for FollowPreset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "paper" => Ok(FollowPreset::Paper),
            "risky" => Ok(FollowPreset::Risky),
            other => Err(format!(
                "unknown car-following preset `{other}`; presets are paper (the built-in \
                 exposure), risky (short headways, harsh braking)"
            )),
        }
    }
}

pub use crate::library::PolicySolver;

/// The smallest TD learning rate accepted: TD needs about 3 × 10⁶/α
/// updates on the paper's grid (2.8 × 10⁷ at α = 0.1).
pub const MIN_ALPHA: f64 = 1e-3;

/// Tolerances of the two solvers: tight enough that DP and TD agree to
/// about 10⁻¹⁰ (far below any weight's precision) in under a second each.
pub const DP_TOLERANCE: f64 = 1e-13;
/// Tolerance of TD(0): every `|δ|` of a sweep below it.
pub const TD_TOLERANCE: f64 = 1e-10;

impl PolicySolver {
    /// The library, or why the solver stopped short of its tolerance.
    pub fn solve(&self, transitions: &Transitions) -> Result<PolicyLibrary, String> {
        let (library, cap) = match *self {
            PolicySolver::DynamicProgramming => (
                dynamic_programming(transitions, DP_TOLERANCE),
                DP_MAX_SWEEPS,
            ),
            PolicySolver::TemporalDifference { alpha, seed } => (
                temporal_difference(transitions, alpha, TD_TOLERANCE, seed),
                TD_MAX_UPDATES,
            ),
        };
        if library.iterations >= cap {
            return Err(format!(
                "the solver stopped after {cap} iterations without reaching its tolerance"
            ));
        }
        Ok(library)
    }
}

/// A learned library with what its build cost.
#[derive(Debug, Clone)]
pub struct LearnedPolicy {
    /// The Q-values and `P(S|s)` learned.
    pub library: PolicyLibrary,
    /// `μ_S = Σ_s P(s) P(S|s)`: the surrogate's accident rate on the grid chain.
    pub mu_s: f64,
    /// `P(Φ) = Σ_{s : P(S|s) > 0} P(s)`: the exposure of the library's states.
    pub library_exposure: f64,
    /// States with `P(S|s) > 0`.
    pub library_states: usize,
    /// One-decision surrogate simulations: a 30-decision zone run per
    /// state plus one per dangerous state and action.
    pub sm_evaluations: usize,
}

/// The car-following case with one preset.
#[derive(Debug, Clone)]
pub struct CarFollowing {
    /// The preset in force.
    pub preset: FollowPreset,
    /// Time step, decisions, action set and bounds.
    pub world: FollowWorld,
    /// The grid of initial states `(v, R, Ṙ)`.
    pub grid: StateGrid,
    /// `P(s)` on the grid and `P(u|v)` per grid speed: the preset's model,
    /// or the user's tables.
    pub exposure: FollowExposure,
    /// `P(s)` on the grid (the exposure's, kept at hand).
    pub initial: Vec<f64>,
    /// The exposure's name: `builtin` or the tables'.
    pub exposure_name: String,
}

impl CarFollowing {
    /// The case with `preset`'s world, grid and exposure, `P(s)` evaluated on the grid.
    pub fn new(preset: FollowPreset) -> Self {
        let world = FollowWorld::paper();
        let grid = StateGrid::paper();
        let exposure = FollowExposure::from_model(&preset.exposure(), &world, &grid);
        Self {
            preset,
            world,
            grid,
            initial: exposure.initial.clone(),
            exposure,
            exposure_name: "builtin".into(),
        }
    }

    /// The case with the exposure of tables `text` ([`FollowExposure::from_tables`])
    /// named `name`, and the sum of its `P(s)` as read.
    pub fn from_tables(
        preset: FollowPreset,
        text: &str,
        name: String,
    ) -> Result<(Self, f64), crate::ndd_table::TableError> {
        let builtin = Self::new(preset);
        let (exposure, sum) = FollowExposure::from_tables(text, &builtin.world, &builtin.grid)?;
        Ok((
            Self {
                initial: exposure.initial.clone(),
                exposure,
                exposure_name: name,
                ..builtin
            },
            sum,
        ))
    }

    /// A fingerprint of `P(s)` and `P(u|v)` (FNV-1a over their bits): a
    /// library and a campaign must use the same exposure.
    pub fn fingerprint(&self) -> String {
        const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        let mut hash = OFFSET;
        for x in self.initial.iter().chain(&self.exposure.actions) {
            for byte in x.to_bits().to_le_bytes() {
                hash ^= u64::from(byte);
                hash = hash.wrapping_mul(PRIME);
            }
        }
        format!("{hash:016x}")
    }

    /// A vehicle from its specification, with this case's defaults for what
    /// it leaves out: the cut-in models are tuned for 20 m/s, so here the
    /// IDM desires 36 m/s and measures the bumper gap (`length` 0), and the
    /// ACC+AEB is set to 36 m/s.
    pub fn vehicle(spec: &serde_json::Value) -> Result<VehicleModel, String> {
        let defaults = match spec.get("model").and_then(|m| m.as_str()) {
            Some("idm") => serde_json::json!({"v0": 36.0, "length": 0.0}),
            Some("acc-aeb") => serde_json::json!({"set_speed": 36.0}),
            _ => serde_json::json!({}),
        };
        let mut merged = defaults;
        if let (Some(m), Some(given)) = (merged.as_object_mut(), spec.as_object()) {
            for (k, v) in given {
                m.insert(k.clone(), v.clone());
            }
        } else {
            return Err("a vehicle is a JSON object such as {\"model\": \"idm\"}".into());
        }
        serde_json::from_value(merged).map_err(|e| e.to_string())
    }

    /// Learns the library of `surrogate` with `solver`; fails when the
    /// solver does not converge or the surrogate has no accident at all.
    pub fn learn(
        &self,
        surrogate: &VehicleModel,
        solver: PolicySolver,
    ) -> Result<LearnedPolicy, String> {
        self.learn_observed(surrogate, solver, &Progress::default())
    }

    /// [`CarFollowing::learn`], counting the surrogate's transitions in
    /// `progress` (the solver that follows takes a small share of the time).
    pub fn learn_observed(
        &self,
        surrogate: &VehicleModel,
        solver: PolicySolver,
        progress: &Progress,
    ) -> Result<LearnedPolicy, String> {
        let transitions = Transitions::compute_observed(
            &self.world,
            self.grid,
            &self.exposure,
            surrogate,
            progress,
        );
        let library = solver.solve(&transitions)?;
        let dangerous = transitions
            .zones
            .iter()
            .filter(|&&z| z == Zone::Dangerous)
            .count();
        let (mut mu_s, mut library_exposure, mut library_states) = (0.0, 0.0, 0);
        for (p, c) in self.initial.iter().zip(&library.challenge) {
            if *c > 0.0 {
                mu_s += p * c;
                library_exposure += p;
                library_states += 1;
            }
        }
        if mu_s <= 0.0 {
            return Err(
                "the surrogate has no accident from any state with positive exposure: the \
                 library would be empty"
                    .into(),
            );
        }
        Ok(LearnedPolicy {
            library,
            mu_s,
            library_exposure,
            library_states,
            sm_evaluations: self.grid.len() + dangerous * self.world.actions,
        })
    }

    /// The NDD baseline's sampler.
    pub fn ndd_sampler(&self) -> FollowSampler {
        FollowSampler::ndd(self.world, self.grid, &self.exposure)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn vehicles_take_the_cases_defaults_and_keep_what_is_given() {
        let idm = CarFollowing::vehicle(&json!({"model": "idm"})).unwrap();
        let spec = serde_json::to_value(idm).unwrap();
        assert_eq!(
            (spec["v0"].clone(), spec["length"].clone()),
            (json!(36.0), json!(0.0))
        );
        let slow = CarFollowing::vehicle(&json!({"model": "idm", "v0": 30})).unwrap();
        assert_eq!(serde_json::to_value(slow).unwrap()["v0"], json!(30.0));
        let acc =
            serde_json::to_value(CarFollowing::vehicle(&json!({"model": "acc-aeb"})).unwrap())
                .unwrap();
        assert_eq!(
            (acc["set_speed"].clone(), acc["actuator_lag"].clone()),
            (json!(36.0), json!(0.0))
        );
        let lagged =
            CarFollowing::vehicle(&json!({"model": "acc-aeb", "actuator_lag": 0.3})).unwrap();
        assert_eq!(
            serde_json::to_value(lagged).unwrap()["set_speed"],
            json!(36.0)
        );
        let err = CarFollowing::vehicle(&json!({"model": "idm", "alpha": -1})).unwrap_err();
        assert!(err.contains("parameter `alpha`"), "{err}");
        assert!(CarFollowing::vehicle(&json!("idm")).is_err());
    }

    #[test]
    fn presets_parse_and_differ_in_exposure() {
        assert_eq!("risky".parse::<FollowPreset>(), Ok(FollowPreset::Risky));
        let err = "fast".parse::<FollowPreset>().unwrap_err();
        assert!(err.contains("presets are paper"), "{err}");
        let (paper, risky) = (
            CarFollowing::new(FollowPreset::Paper),
            CarFollowing::new(FollowPreset::Risky),
        );
        assert_ne!(paper.fingerprint(), risky.fingerprint());
        assert_eq!(
            paper.fingerprint(),
            CarFollowing::new(FollowPreset::Paper).fingerprint()
        );
        assert!(PolicySolver::TemporalDifference {
            alpha: 0.0,
            seed: 0
        }
        .validate()
        .is_err());
    }
}
