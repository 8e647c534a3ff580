//! The vehicle under test as an external program, without I/O: what a test
//! tells the program and what the program answers (protocol version
//! [`PROTOCOL_VERSION`], specified in `docs/vut-protocol.md`), and the trait a
//! runner implements to carry the messages (the worker's child process, or
//! an in-process double in tests).
//!
//! Each case translates its simulation state into an [`Observation`] with
//! the adapters here ([`ExternalFollower`] for one-lane cases; the highway
//! has its own), so a program sees every case in one vocabulary: its own
//! vehicle (`ego`), the other vehicles, lanes and time.

use crate::vehicle::{FollowDriver, FollowStep};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The protocol version this build speaks. Version 2 added an episode's
/// optional `criticality`; programs speaking version 1 keep working.
pub const PROTOCOL_VERSION: u32 = 2;

/// The oldest protocol version a program may speak.
pub const OLDEST_PROTOCOL_VERSION: u32 = 1;

/// Longest program name.
pub const MAX_NAME_LENGTH: usize = 64;

/// The length of every vehicle in the one-lane worlds (cut-in,
/// car-following), where only the bumper gap enters the dynamics; it fixes
/// the vehicles' `position`s (front bumpers) for programs that want them.
pub const NOMINAL_LENGTH: f64 = 5.0;

/// How a program is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExternalMode {
    /// Closed loop: the worker simulates the world and asks for a control
    /// at every step.
    #[default]
    Step,
    /// The worker sends the whole scenario and the program reports the
    /// outcome (a test track, a heavy simulator).
    Episode,
}

impl ExternalMode {
    /// The mode's name in the protocol (`step`, `episode`).
    pub fn as_str(self) -> &'static str {
        match self {
            ExternalMode::Step => "step",
            ExternalMode::Episode => "episode",
        }
    }
}

/// A campaign's vehicle under test when it is a program:
/// `{"external": "NAME", "mode": "step"}`. Workers map `NAME` to a command
/// (`tslg-worker --vut-exec NAME=COMMAND`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExternalVut {
    /// The program's name, as workers offer it (`--vut-exec NAME=…`).
    pub external: String,
    /// How the program is driven (`step` by default).
    #[serde(default)]
    pub mode: ExternalMode,
}

impl ExternalVut {
    /// `None` when `spec` names no external program (a built-in model);
    /// otherwise the parsed, validated specification or why it is not one.
    pub fn from_spec(spec: &serde_json::Value) -> Option<Result<Self, String>> {
        spec.get("external")?;
        Some(
            serde_json::from_value::<ExternalVut>(spec.clone())
                .map_err(|e| format!("external vehicle: {e}"))
                .and_then(|vut| check_program_name(&vut.external).map(|()| vut)),
        )
    }

    /// The key a campaign requires and a worker offers: `NAME:case:mode`.
    pub fn requirement(&self, case: &str) -> String {
        requirement(&self.external, case, self.mode)
    }
}

/// `NAME:case:mode`, the unit of routing between campaigns and workers.
pub fn requirement(name: &str, case: &str, mode: ExternalMode) -> String {
    format!("{name}:{case}:{}", mode.as_str())
}

/// Program names are 1 to 64 of `A–Z a–z 0–9 . _ -`: they appear in URLs,
/// logs and command lines.
pub fn check_program_name(name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= MAX_NAME_LENGTH
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "external program name `{name}` must be 1 to {MAX_NAME_LENGTH} characters of \
             A-Z, a-z, 0-9, '.', '_' and '-'"
        ))
    }
}

/// The start of one test (`reset`): the program drops everything it
/// remembers of earlier tests.
#[derive(Debug, Clone, Serialize)]
pub struct TestStart<'a> {
    /// The case of the test.
    pub case: &'a str,
    /// Step or episode mode.
    pub mode: ExternalMode,
    /// The test's index in its campaign.
    pub index: u64,
    /// A seed of the test's own ([`crate::noise::noise_seed`] of the
    /// campaign's seed and the index): a program that draws its noise from
    /// it runs one test the same way every time, and both vehicles of a
    /// paired test get the same one (common random numbers).
    pub noise_seed: u64,
    /// The case's constants: time step, horizon, bounds, lanes.
    pub world: &'a serde_json::Value,
}

/// The vehicle under test's own state. Positions are front bumpers (m)
/// along the road, 0 where the test starts; lane 0 is the rightmost.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ego {
    /// Front bumper position (m).
    pub position: f64,
    /// Speed (m/s).
    pub speed: f64,
    /// Lane number (0 is the rightmost).
    pub lane: u32,
}

/// Another vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Other {
    /// The vehicle's id, stable over the test.
    pub id: u32,
    /// Front bumper position (m).
    pub position: f64,
    /// Speed (m/s).
    pub speed: f64,
    /// Lane number (0 is the rightmost).
    pub lane: u32,
    /// The bumper gap as the simulation measures it (its rear bumper to the
    /// ego's front bumper), present only for the vehicle directly ahead in
    /// the ego's lane.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gap: Option<f64>,
}

/// What the program sees at one control step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Observation {
    /// Control step `k` since the test started; `time = k · dt`.
    pub step: u32,
    /// Seconds since the test started.
    pub time: f64,
    /// The vehicle under test.
    pub ego: Ego,
    /// The other vehicles.
    pub vehicles: Vec<Other>,
}

/// The program's answer to an observation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Control {
    /// Commanded acceleration (m/s²); the world clips it to its bounds.
    pub acceleration: f64,
    /// Change into the lane to the right now (highway exit only).
    #[serde(default)]
    pub change_lane: bool,
}

/// The program's answer to a whole scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeOutcome {
    /// Whether the event happened (an accident; on the highway exit, a
    /// failure to exit).
    pub event: bool,
    /// How close the vehicle came to the event, in `[0, 1]` (0 for the
    /// event, small for a near miss; e.g. the minimum normalised time to
    /// collision): adaptive campaigns search from near misses. Protocol
    /// version 2; optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub criticality: Option<f64>,
    /// Anything the program wants logged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl EpisodeOutcome {
    /// The criticality, checked: `None` when not sent; an error when it
    /// is not a number in `[0, 1]`.
    pub fn checked_criticality(&self) -> Result<Option<f64>, DriverError> {
        match self.criticality {
            None => Ok(None),
            Some(c) if (0.0..=1.0).contains(&c) => Ok(Some(if self.event { 0.0 } else { c })),
            Some(c) => Err(DriverError(format!(
                "the program reported criticality {c}; it must be a number in [0, 1]"
            ))),
        }
    }
}

/// Why a test with an external program has no valid outcome: the reason
/// goes into the `invalid` record.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct DriverError(pub String);

/// A channel to a program acting as the vehicle under test. One value
/// serves one test at a time.
pub trait ExternalVehicle {
    /// Starts a test.
    fn reset(&mut self, start: &TestStart) -> Result<(), DriverError>;
    /// One control step (step mode).
    fn step(&mut self, observation: &Observation) -> Result<Control, DriverError>;
    /// A whole scenario given by its named parameters (episode mode).
    fn episode(&mut self, scenario: &serde_json::Value) -> Result<EpisodeOutcome, DriverError>;
}

/// One run of a program: given a fresh, handshaken program, the test's
/// conversation (reset, then steps or an episode) and what it gave.
pub type ProgramConversation<'a> =
    dyn Fn(&mut dyn ExternalVehicle) -> Result<(bool, Option<f64>), DriverError> + Sync + 'a;

/// Programs run in this process (the command line's, a worker's): what lets
/// a case use a program as a surrogate, or as a vehicle it runs itself,
/// without knowing how processes are started, pooled and retried.
pub trait ProgramHost: Send + Sync {
    /// Whether program `name` is here.
    fn has(&self, name: &str) -> bool;
    /// Holds `conversation` with program `name`: the event and criticality
    /// it gave, or why the program gave none (after the host's retries).
    fn converse(
        &self,
        name: &str,
        conversation: &ProgramConversation<'_>,
    ) -> Result<(bool, Option<f64>), String>;
}

/// Checks a control before the world applies it.
pub fn checked_control(control: Control) -> Result<Control, DriverError> {
    if control.acceleration.is_finite() {
        Ok(control)
    } else {
        Err(DriverError(format!(
            "the program answered a non-finite acceleration {}",
            control.acceleration
        )))
    }
}

/// A program driving the follower of a one-lane world (cut-in,
/// car-following): the leader is vehicle 1, [`NOMINAL_LENGTH`] long,
/// `gap` ahead.
pub struct ExternalFollower<'a> {
    /// The program, reset for this test.
    pub vut: &'a mut dyn ExternalVehicle,
}

impl FollowDriver for ExternalFollower<'_> {
    type Error = DriverError;

    fn decide(&mut self, s: &FollowStep) -> Result<f64, DriverError> {
        let observation = Observation {
            step: s.step as u32,
            time: s.time,
            ego: Ego {
                position: s.position,
                speed: s.obs.speed,
                lane: 0,
            },
            vehicles: vec![Other {
                id: 1,
                position: s.position + s.obs.gap + NOMINAL_LENGTH,
                speed: s.obs.lead_speed,
                lane: 0,
                gap: Some(s.obs.gap),
            }],
        };
        Ok(checked_control(self.vut.step(&observation)?)?.acceleration)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn external_specifications_parse_validate_and_route() {
        assert!(ExternalVut::from_spec(&json!({"model": "idm"})).is_none());
        let vut = ExternalVut::from_spec(&json!({"external": "py-idm"}))
            .unwrap()
            .unwrap();
        assert_eq!(vut.mode, ExternalMode::Step);
        assert_eq!(vut.requirement("cut-in"), "py-idm:cut-in:step");
        let episode = ExternalVut::from_spec(&json!({"external": "track", "mode": "episode"}))
            .unwrap()
            .unwrap();
        assert_eq!(
            episode.requirement("highway-exit"),
            "track:highway-exit:episode"
        );
        for bad in [
            json!({"external": ""}),
            json!({"external": "a b"}),
            json!({"external": "x:y"}),
            json!({"external": "a".repeat(65)}),
            json!({"external": "ok", "mode": "batch"}),
            json!({"external": "ok", "model": "idm"}),
            json!({"external": 3}),
        ] {
            assert!(
                ExternalVut::from_spec(&bad).unwrap().is_err(),
                "accepted {bad}"
            );
        }
    }

    #[test]
    fn an_episode_may_report_its_criticality_from_protocol_version_2() {
        let outcome = |json: &str| serde_json::from_str::<EpisodeOutcome>(json).unwrap();
        // Version 1: no criticality; still an outcome.
        let v1 = outcome(r#"{"event": false}"#);
        assert_eq!(v1.checked_criticality(), Ok(None));
        let near = outcome(r#"{"event": false, "criticality": 0.03}"#);
        assert_eq!(near.checked_criticality(), Ok(Some(0.03)));
        // An event is criticality 0 whatever the program says.
        let event = outcome(r#"{"event": true, "criticality": 0.4}"#);
        assert_eq!(event.checked_criticality(), Ok(Some(0.0)));
        for bad in ["1.5", "-0.1"] {
            let wrong = outcome(&format!(r#"{{"event": false, "criticality": {bad}}}"#));
            let error = wrong.checked_criticality().unwrap_err();
            assert!(error.0.contains("must be a number in [0, 1]"), "{error}");
        }
    }

    #[test]
    fn messages_have_the_documented_shape() {
        let o = Observation {
            step: 3,
            time: 0.3,
            ego: Ego {
                position: 6.0,
                speed: 20.0,
                lane: 0,
            },
            vehicles: vec![Other {
                id: 1,
                position: 31.0,
                speed: 15.0,
                lane: 0,
                gap: Some(20.0),
            }],
        };
        assert_eq!(
            serde_json::to_value(&o).unwrap(),
            json!({"step": 3, "time": 0.3, "ego": {"position": 6.0, "speed": 20.0, "lane": 0},
                   "vehicles": [{"id": 1, "position": 31.0, "speed": 15.0, "lane": 0, "gap": 20.0}]})
        );
        let c: Control = serde_json::from_value(json!({"acceleration": -1.5})).unwrap();
        assert!(!c.change_lane);
        assert!(checked_control(Control {
            acceleration: f64::NAN,
            change_lane: false
        })
        .is_err());
    }
}
