//! Longitudinal vehicle models: the surrogate model (SM) that builds a library
//! and the built-in vehicles under test (VUT).
//!
//! A model is described by a [`VehicleSpec`] (serde: `{"model": "idm", ...}`,
//! every parameter optional with the documented default) and validated into a
//! [`VehicleModel`]. A simulation asks a fresh [`Controller`] per test for an
//! acceleration at each step; the controller keeps whatever memory the model
//! has (the switching ACC remembers its last error and output).

mod acc_aeb;
pub mod batch;
mod fvdm;
mod idm;
mod observation;
mod parameters;
pub mod power;
mod switching_acc;
pub mod tanh;

pub use acc_aeb::AccAebParams;
pub use fvdm::FvdmParams;
pub use idm::IdmParams;
pub use observation::FollowerObservation;
pub(crate) use parameters::check;
pub use parameters::{ParamError, MAX_PARAMETER_MAGNITUDE, MIN_PARAMETER_MAGNITUDE};
pub use switching_acc::{SwitchingAccParams, SwitchingAccState};

use crate::noise::{Noise, NoiseRng, RunNoise};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// One control step of a follower, as its driver sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowStep {
    /// Steps since the test started, and `time = step · dt` (s).
    pub step: usize,
    /// Seconds since the test started.
    pub time: f64,
    /// Own front bumper from where the test started (m).
    pub position: f64,
    /// What the follower sees: own speed, the leader's speed and the gap.
    pub obs: FollowerObservation,
    /// The world's acceleration bounds `(a_min, a_max)`.
    pub clip: (f64, f64),
    /// The simulation's time step (s).
    pub dt: f64,
}

/// Whatever drives a follower: a built-in [`Controller`] (which cannot
/// fail, `Error = Infallible`, so the built-in path costs nothing extra) or
/// an external program ([`crate::external::ExternalFollower`]).
pub trait FollowDriver {
    /// Why a decision failed (`Infallible` for built-in drivers).
    type Error;
    /// The commanded acceleration for the next step.
    fn decide(&mut self, step: &FollowStep) -> Result<f64, Self::Error>;
}

impl FollowDriver for Controller {
    type Error = std::convert::Infallible;
    fn decide(&mut self, step: &FollowStep) -> Result<f64, Self::Error> {
        Ok(self.acceleration(&step.obs, step.clip, step.dt))
    }
}

/// A vehicle model as written in a request or a file, before validation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VehicleSpec {
    /// The Intelligent Driver Model.
    Idm(IdmParams),
    /// The full velocity difference model.
    Fvdm(FvdmParams),
    /// The switching ACC (incremental PI on the time-to-collision error).
    SwitchingAcc(SwitchingAccParams),
    /// A constant-time-gap ACC with an autonomous emergency brake.
    AccAeb(AccAebParams),
}

/// A vehicle model as written, with the noise on its runs
/// (`{"model": "idm", "noise": 0.5}`, `{"model": "idm", "noise": {"kind":
/// "reaction", "sigma": 1.5}}`), before validation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WrittenVehicle {
    #[serde(flatten)]
    spec: VehicleSpec,
    /// The noise on its runs ([`Noise`]): a number is σ (m/s²) of Gaussian
    /// noise added to every commanded acceleration, before the world's
    /// bounds; an object names another kind. A noisy vehicle is not
    /// bit-reproducible ([`crate::noise`]); absent or 0 for none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    noise: Option<Noise>,
}

/// A validated vehicle model. Deserialising one validates it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "WrittenVehicle", into = "WrittenVehicle")]
pub struct VehicleModel {
    spec: VehicleSpec,
    /// `None` for a deterministic model (σ 0 is none).
    noise: Option<Noise>,
}

/// The largest additive noise σ a vehicle takes (m/s²): beyond any
/// actuator, and far beyond what keeps a cut-in's outcome tied to its
/// scenario.
pub const MAX_NOISE: f64 = crate::noise::MAX_ADDITIVE;

impl TryFrom<WrittenVehicle> for VehicleModel {
    type Error = ParamError;
    fn try_from(written: WrittenVehicle) -> Result<Self, ParamError> {
        let model = Self::try_from(written.spec)?;
        let Some(noise) = written.noise else {
            return Ok(model);
        };
        let parameter = match noise {
            Noise::Additive(_) => "noise",
            _ => "noise.sigma",
        };
        let requirement = noise.check().err().unwrap_or("");
        check(
            model.name(),
            parameter,
            noise.sigma(),
            |_| noise.check().is_ok(),
            requirement,
        )?;
        Ok(Self {
            noise: noise.is_some().then_some(noise),
            ..model
        })
    }
}

impl From<VehicleModel> for WrittenVehicle {
    fn from(model: VehicleModel) -> Self {
        Self {
            spec: model.spec,
            noise: model.noise,
        }
    }
}

/// Names of the built-in models, in the order `tslg exact` reports them.
pub const BUILTIN_MODELS: [&str; 4] = ["idm", "fvdm", "switching-acc", "acc-aeb"];

impl TryFrom<VehicleSpec> for VehicleModel {
    type Error = ParamError;
    fn try_from(spec: VehicleSpec) -> Result<Self, ParamError> {
        match &spec {
            VehicleSpec::Idm(p) => p.validate(),
            VehicleSpec::Fvdm(p) => p.validate(),
            VehicleSpec::SwitchingAcc(p) => p.validate(),
            VehicleSpec::AccAeb(p) => p.validate(),
        }?;
        Ok(Self { spec, noise: None })
    }
}

/// An unknown built-in model name.
#[derive(Debug, Error, PartialEq)]
#[error("unknown vehicle model `{0}`; built-in models are idm, fvdm, switching-acc, acc-aeb")]
pub struct UnknownModel(pub String);

impl VehicleModel {
    /// A built-in model with its default parameters.
    pub fn builtin(name: &str) -> Result<Self, UnknownModel> {
        let spec = match name {
            "idm" => VehicleSpec::Idm(IdmParams::default()),
            "fvdm" => VehicleSpec::Fvdm(FvdmParams::default()),
            "switching-acc" => VehicleSpec::SwitchingAcc(SwitchingAccParams::default()),
            "acc-aeb" => VehicleSpec::AccAeb(AccAebParams::default()),
            other => return Err(UnknownModel(other.to_owned())),
        };
        Ok(Self { spec, noise: None })
    }

    /// The model's name as used on the command line and in files.
    pub fn name(&self) -> &'static str {
        match self.spec {
            VehicleSpec::Idm(_) => "idm",
            VehicleSpec::Fvdm(_) => "fvdm",
            VehicleSpec::SwitchingAcc(_) => "switching-acc",
            VehicleSpec::AccAeb(_) => "acc-aeb",
        }
    }

    /// The model as written, with its parameters.
    pub fn spec(&self) -> &VehicleSpec {
        &self.spec
    }

    /// The parameters that differ from `defaults` (the same model as a
    /// case writes it when nothing is given), by name, in the order the
    /// model writes them (`[("v0", 25.0)]` for `{"model": "idm", "v0": 25}`
    /// on cut-in); the noise is not a parameter here.
    pub fn differing_parameters(&self, defaults: &VehicleModel) -> Vec<(String, f64)> {
        let written = |spec: &VehicleSpec| match serde_json::to_value(spec) {
            Ok(serde_json::Value::Object(map)) => map,
            _ => serde_json::Map::new(),
        };
        let (mine, theirs) = (written(&self.spec), written(&defaults.spec));
        mine.iter()
            .filter(|(key, value)| theirs.get(*key) != Some(*value))
            .filter_map(|(key, value)| Some((key.clone(), value.as_f64()?)))
            .collect()
    }

    /// Its name with the parameters that differ from `defaults`, and its
    /// noise: `idm`, `idm (v0 25)`, `acc-aeb (actuator_lag 0.3, noise 0.5)`.
    pub fn label(&self, defaults: &VehicleModel) -> String {
        let mut parts: Vec<String> = self
            .differing_parameters(defaults)
            .into_iter()
            .map(|(key, value)| format!("{key} {}", crate::number::Num(value)))
            .collect();
        if let Some(noise) = &self.noise {
            parts.push(noise.label());
        }
        if parts.is_empty() {
            self.name().to_owned()
        } else {
            format!("{} ({})", self.name(), parts.join(", "))
        }
    }

    /// The noise on its runs; `None` for a deterministic model.
    pub fn noise(&self) -> Option<Noise> {
        self.noise
    }

    /// Whether two runs of one scenario may differ.
    pub fn is_noisy(&self) -> bool {
        self.noise.is_some()
    }

    /// The same model without noise (a surrogate's view of it).
    pub fn without_noise(&self) -> Self {
        Self {
            noise: None,
            ..*self
        }
    }

    /// A controller with fresh memory, for one test of a deterministic
    /// model; a noisy one takes its noise from [`VehicleModel::noisy_controller`].
    pub fn controller(&self) -> Controller {
        Controller {
            spec: self.spec,
            acc_state: SwitchingAccState::default(),
            delivered: None,
            noise: None,
        }
    }

    /// A controller for one test whose noise, if the model has any, is
    /// drawn from `stream` (the test's own, [`crate::noise::noise_rng`]).
    pub fn noisy_controller(&self, stream: NoiseRng) -> Controller {
        Controller {
            noise: self
                .noise
                .map(|noise| Box::new(RunNoise::new(noise, stream))),
            ..self.controller()
        }
    }
}

/// One vehicle's controller during one test.
#[derive(Debug, Clone)]
pub struct Controller {
    spec: VehicleSpec,
    acc_state: SwitchingAccState,
    /// The acceleration the actuator delivered at the last step (for a
    /// model with an actuator lag).
    delivered: Option<f64>,
    /// The noise on its runs, for a noisy model (boxed: a stream is some
    /// 300 bytes, and deterministic controllers stay small).
    noise: Option<Box<RunNoise>>,
}

impl Controller {
    /// The acceleration over the next step of `dt` seconds, clipped to
    /// `clip = (a_min, a_max)`. A noisy model acts on the gap its noise
    /// lets it perceive and its actuator delivers what its noise makes of
    /// the command, before the clip ([`RunNoise`]; additive noise adds `σ
    /// Z`, `Z` standard normal from the test's noise stream). A model with
    /// an actuator lag τ delivers a first-order response to its command
    /// `c`: `a ← a + (c − a)(1 − e^{−Δt/τ})`, starting from the first
    /// command.
    pub fn acceleration(&mut self, obs: &FollowerObservation, clip: (f64, f64), dt: f64) -> f64 {
        let perceived;
        let obs = match &mut self.noise {
            Some(noise) => {
                perceived = FollowerObservation {
                    gap: noise.perceived_gap(obs.gap),
                    ..*obs
                };
                &perceived
            }
            None => obs,
        };
        let (command, lag) = match &self.spec {
            VehicleSpec::Idm(p) => (p.acceleration(obs), 0.0),
            VehicleSpec::Fvdm(p) => (p.acceleration(obs), 0.0),
            VehicleSpec::SwitchingAcc(p) => {
                let command = self.acc_state.acceleration(p, obs, clip);
                return match &mut self.noise {
                    Some(noise) => noise.deliver(command, dt).clamp(clip.0, clip.1),
                    None => command,
                };
            }
            VehicleSpec::AccAeb(p) => (p.acceleration(obs), p.actuator_lag),
        };
        let command = match &mut self.noise {
            Some(noise) => noise.deliver(command, dt),
            None => command,
        };
        let command = command.clamp(clip.0, clip.1);
        if lag <= 0.0 {
            return command;
        }
        let delivered = match self.delivered {
            None => command,
            Some(a) => a + (command - a) * (1.0 - (-dt / lag).exp()),
        };
        self.delivered = Some(delivered);
        delivered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLIP: (f64, f64) = (-3.0, 3.0);

    fn obs(speed: f64, lead_speed: f64, gap: f64) -> FollowerObservation {
        FollowerObservation {
            speed,
            lead_speed,
            gap,
        }
    }

    #[test]
    fn a_label_names_the_parameters_that_differ_from_the_defaults() {
        let label = |json: &str| {
            let m = serde_json::from_str::<VehicleModel>(json).unwrap();
            m.label(&VehicleModel::builtin(m.name()).unwrap())
        };
        assert_eq!(label(r#"{"model": "idm"}"#), "idm");
        assert_eq!(label(r#"{"model": "idm", "v0": 25}"#), "idm (v0 25)");
        // A default given explicitly is no difference.
        let v0 = IdmParams::default().v0;
        assert_eq!(label(&format!(r#"{{"model": "idm", "v0": {v0}}}"#)), "idm");
        assert_eq!(
            label(r#"{"model": "acc-aeb", "actuator_lag": 0.3, "noise": 0.5}"#),
            "acc-aeb (actuator_lag 0.3, noise 0.5)"
        );
    }

    #[test]
    fn idm_matches_a_hand_computation() {
        // v = 20, v_lead = 15, R = 30: s* = 2 + 20 + 20·5/(2√6) = 42.4124,
        // a = 2 (1 − (20/18)⁴ − (42.4124/26)²) = −6.3696, clipped to −3.
        let p = IdmParams::default();
        let a = p.acceleration(&obs(20.0, 15.0, 30.0));
        let s = 2.0 + 20.0 + 100.0 / (2.0 * 6f64.sqrt());
        let expected = 2.0 * (1.0 - (20.0f64 / 18.0).powi(4) - (s / 26.0).powi(2));
        assert!((a - expected).abs() < 1e-12);
        assert!((a + 6.3696).abs() < 1e-3);
        let mut c = VehicleModel::builtin("idm").unwrap().controller();
        assert_eq!(c.acceleration(&obs(20.0, 15.0, 30.0), CLIP, 0.1), -3.0);
    }

    #[test]
    fn idm_at_r_equal_l_brakes_fully() {
        let mut c = VehicleModel::builtin("idm").unwrap().controller();
        assert_eq!(c.acceleration(&obs(0.0, 0.0, 4.0), CLIP, 0.1), -3.0);
    }

    #[test]
    fn fvdm_relaxes_toward_the_optimal_speed() {
        let p = FvdmParams::default();
        // At R − L = C₂/C₁ the tanh vanishes and the optimal speed is V₁.
        let gap = 5.0 + 1.57 / 0.13;
        assert!((p.acceleration(&obs(6.75, 0.0, gap))).abs() < 1e-12);
        assert!((p.acceleration(&obs(0.0, 0.0, gap)) - 0.85 * 6.75).abs() < 1e-12);
    }

    #[test]
    fn switching_acc_brakes_when_ttc_is_below_target_and_integrates_otherwise() {
        let model = VehicleModel::builtin("switching-acc").unwrap();
        let mut c = model.controller();
        // Closing at 10 m/s from 20 m: TTC ≈ 2 s < 5 s → brake.
        assert_eq!(c.acceleration(&obs(20.0, 10.0, 20.0), CLIP, 0.1), -3.0);
        let mut c = model.controller();
        // The authors' first step: e_prev = 100/5 − 5 = 15 (no guard),
        // e = 100/5.01 − 5 = 14.960; a = Kp (e − e_prev) + Ki (e + e_prev) Ts/2
        // = −38.6 · (−0.0399) − 1.35 · 29.96 · 0.05 = −0.4814.
        let a = c.acceleration(&obs(20.0, 15.0, 100.0), CLIP, 0.1);
        let (e, e_prev) = (100.0 / 5.01 - 5.0, 15.0);
        let expected = -38.6 * (e - e_prev) - 1.35 * (e + e_prev) * 0.1 / 2.0;
        assert!((a - expected).abs() < 1e-12, "{a}");
        assert!((a + 0.4814).abs() < 1e-4, "{a}");
        // Equal speeds: the authors' ttc.m divides by 0.01, e_prev = 9995.
        let mut c = model.controller();
        let a = c.acceleration(&obs(20.0, 20.0, 100.0), CLIP, 0.1);
        let e = 100.0 / 0.01 - 5.0;
        let expected = (-1.35 * (2.0 * e) * 0.1 / 2.0_f64).clamp(CLIP.0, CLIP.1);
        assert_eq!(a, expected);
    }

    #[test]
    fn acc_aeb_triggers_the_emergency_brake_on_low_ttc() {
        let p = AccAebParams::default();
        assert_eq!(p.acceleration(&obs(20.0, 10.0, 15.0)), -8.0);
        // Far behind a leader at set speed: cruise toward the set speed.
        let a = p.acceleration(&obs(25.0, 30.0, 200.0));
        assert!((a - 1.5).abs() < 1e-12);
    }

    #[test]
    fn an_actuator_lag_delivers_a_first_order_response_to_the_command() {
        let model: VehicleModel =
            serde_json::from_str(r#"{"model":"acc-aeb","actuator_lag":0.5}"#).unwrap();
        let mut c = model.controller();
        // Cruising below the set speed far behind: the first command (1.5)
        // is delivered at once.
        assert!((c.acceleration(&obs(25.0, 30.0, 200.0), (-4.0, 2.0), 0.1) - 1.5).abs() < 1e-12);
        // Then the AEB commands −8, clipped to −4: after one 0.1 s step the
        // delivered value moved (1 − e^{−0.2}) of the way.
        let a = c.acceleration(&obs(20.0, 10.0, 15.0), (-4.0, 2.0), 0.1);
        let expected = 1.5 + (-4.0 - 1.5) * (1.0 - (-0.2f64).exp());
        assert!((a - expected).abs() < 1e-12, "{a} vs {expected}");
        // Without a lag the command is delivered as is.
        let mut ideal = VehicleModel::builtin("acc-aeb").unwrap().controller();
        ideal.acceleration(&obs(25.0, 30.0, 200.0), (-4.0, 2.0), 0.1);
        assert_eq!(
            ideal.acceleration(&obs(20.0, 10.0, 15.0), (-4.0, 2.0), 0.1),
            -4.0
        );
        let err = serde_json::from_str::<VehicleModel>(r#"{"model":"acc-aeb","actuator_lag":-1}"#)
            .unwrap_err();
        assert!(err.to_string().contains("actuator_lag"), "{err}");
    }

    #[test]
    fn specs_deserialize_with_defaults_and_reject_bad_values() {
        let m: VehicleModel = serde_json::from_str(r#"{"model":"idm","v0":30}"#).unwrap();
        match m.spec() {
            VehicleSpec::Idm(p) => {
                assert_eq!(p.v0, 30.0);
                assert_eq!(p.alpha, 2.0);
            }
            other => panic!("wrong model {other:?}"),
        }
        let err = serde_json::from_str::<VehicleModel>(r#"{"model":"idm","b":-1}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("idm: parameter `b` = -1 must be > 0"), "{err}");
        assert!(serde_json::from_str::<VehicleModel>(r#"{"model":"idm","bogus":1}"#).is_err());
        assert!(serde_json::from_str::<VehicleModel>(r#"{"model":"tesla"}"#).is_err());
        assert_eq!(
            VehicleModel::builtin("tesla"),
            Err(UnknownModel("tesla".into()))
        );
    }
}
