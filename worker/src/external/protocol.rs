//! The wire form of the external-vehicle protocol: one JSON object per
//! line, tagged by `type` (`docs/vut-protocol.md`).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tslg_method::external::{Control, EpisodeOutcome, ExternalMode, Observation, TestStart};

/// Longest line a program may print (1 MiB): a runaway program cannot
/// make the worker buffer without bound.
pub const MAX_LINE: usize = 1 << 20;

/// Worker → program.
#[derive(Debug, Serialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum Request<'a> {
    /// The first message: the protocol version and who asks.
    Hello { protocol: u32, worker: &'a str },
    /// A new test: forget everything from the last one.
    Reset {
        campaign: i64,
        #[serde(flatten)]
        start: &'a TestStart<'a>,
    },
    /// One control step (step mode).
    Step(&'a Observation),
    /// A whole scenario (episode mode).
    Episode { scenario: &'a serde_json::Value },
}

/// Program → worker.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum Reply {
    Hello {
        protocol: u32,
        #[serde(default)]
        name: Option<String>,
        /// The cases the program drives and in which modes.
        cases: BTreeMap<String, Vec<ExternalMode>>,
        /// `false`: two runs of one test may differ (thread timing,
        /// sensor noise, learned parts).
        #[serde(default = "deterministic_by_default")]
        deterministic: bool,
    },
    Ready,
    Control(Control),
    Outcome(EpisodeOutcome),
    /// The program cannot run this test.
    Error {
        message: String,
    },
}

/// A program that does not say otherwise is taken to be deterministic.
fn deterministic_by_default() -> bool {
    true
}

impl Reply {
    pub fn kind(&self) -> &'static str {
        match self {
            Reply::Hello { .. } => "hello",
            Reply::Ready => "ready",
            Reply::Control(_) => "control",
            Reply::Outcome(_) => "outcome",
            Reply::Error { .. } => "error",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;
    use tslg_method::external::Ego;

    #[test]
    fn requests_and_replies_have_the_documented_form() {
        let world = json!({"dt": 0.1});
        let start = TestStart {
            case: "cut-in",
            mode: ExternalMode::Step,
            index: 7,
            noise_seed: 99,
            world: &world,
        };
        let reset = serde_json::to_value(Request::Reset {
            campaign: 3,
            start: &start,
        })
        .unwrap();
        assert_eq!(
            reset,
            json!({"type": "reset", "campaign": 3, "case": "cut-in", "mode": "step",
                   "index": 7, "noise_seed": 99, "world": {"dt": 0.1}})
        );
        let step = Observation {
            step: 0,
            time: 0.0,
            ego: Ego {
                position: 0.0,
                speed: 20.0,
                lane: 0,
            },
            vehicles: vec![],
        };
        assert_eq!(
            serde_json::to_value(Request::Step(&step)).unwrap()["type"],
            "step"
        );
        let hello: Reply = serde_json::from_str(
            r#"{"type":"hello","protocol":1,"cases":{"cut-in":["step","episode"]}}"#,
        )
        .unwrap();
        assert!(
            matches!(hello, Reply::Hello { protocol: 1, ref cases, .. } if cases["cut-in"].len() == 2)
        );
        let control: Reply =
            serde_json::from_str(r#"{"type":"control","acceleration":-2.5}"#).unwrap();
        assert!(matches!(control, Reply::Control(c) if c.acceleration == -2.5 && !c.change_lane));
        assert!(serde_json::from_str::<Reply>(r#"{"type":"control"}"#).is_err());
        assert!(serde_json::from_str::<Reply>(r#"{"type":"dance"}"#).is_err());
    }
}
