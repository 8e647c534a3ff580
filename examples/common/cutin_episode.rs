//! What the example programs that drive a whole cut-in themselves share
//! (episode mode, docs/vut-protocol.md): the world's settings as the
//! coordinator sends them, the cut-in stepped under them, and the protocol
//! loop on stdin/stdout. A program brings its driver ([`Driver`]): what it
//! asks of the actuator at each step, from the true state it may perceive
//! wrongly. It links nothing of tslg, as a user's program would not.
//!
//! The cut-in: the leader keeps its speed `v₀ + range_rate`; the vehicle
//! starts at `v₀`, `range` behind it; each step of `dt` the driver's
//! acceleration is clipped to the world's bounds, the speed bounds act as
//! the world's `speed_bound` says, and the run is an accident once the gap
//! falls below the world's accident gap.

use serde_json::{json, Value};
use std::io::{BufRead, Write};

/// Time to collision that counts as far from the event (s).
const TTC_CEILING: f64 = 10.0;

/// What a driver sees of the world at one step (the truth: a driver with
/// a noisy sensor perturbs it itself).
#[derive(Debug, Clone, Copy)]
pub struct State {
    /// Time since the cut-in (s).
    pub time: f64,
    /// The step (s).
    pub dt: f64,
    /// The vehicle's speed (m/s).
    pub speed: f64,
    /// The leader's speed (m/s).
    pub lead_speed: f64,
    /// The gap to the leader (m).
    pub gap: f64,
}

/// A vehicle under test that drives a cut-in one step at a time.
pub trait Driver {
    /// The name its hello gives.
    fn name(&self) -> &'static str;
    /// Whether its runs of one scenario are all the same.
    fn deterministic(&self) -> bool;
    /// A new run begins (draw what a run draws once).
    fn begin(&mut self);
    /// The acceleration it delivers at this step (m/s², before the
    /// world's bounds).
    fn acceleration(&mut self, state: State) -> f64;
}

fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// One cut-in at `(range, range_rate)` under `world`: the event, and the
/// smallest time to collision over the run divided by its ceiling.
pub fn run(driver: &mut dyn Driver, world: &Value, scenario: &Value) -> (bool, f64) {
    let (dt, v0) = (number(&world["dt"]), number(&world["initial_speed"]));
    let (a_min, a_max) = (
        number(&world["acceleration"][0]),
        number(&world["acceleration"][1]),
    );
    let (v_min, v_max) = (number(&world["speed"][0]), number(&world["speed"][1]));
    let clips_speed = world["speed_bound"].as_str() == Some("clips-speed");
    let accident_gap = number(&world["accident_gap"]);
    let inclusive = world["inclusive"].as_bool() == Some(true);
    let hit = |gap: f64| {
        if inclusive {
            gap <= accident_gap
        } else {
            gap < accident_gap
        }
    };
    let lead_speed = v0 + number(&scenario["range_rate"]);
    let (mut gap, mut speed) = (number(&scenario["range"]), v0);
    let ttc = |gap: f64, speed: f64| {
        let closing = speed - lead_speed;
        if closing > 0.0 {
            (gap / closing / TTC_CEILING).min(1.0)
        } else {
            1.0
        }
    };
    if hit(gap) {
        return (true, 0.0);
    }
    driver.begin();
    let mut closest = ttc(gap, speed);
    let steps = world["steps"].as_u64().unwrap_or(0);
    for k in 0..steps {
        let state = State {
            time: k as f64 * dt,
            dt,
            speed,
            lead_speed,
            gap,
        };
        let mut accel = driver.acceleration(state).clamp(a_min, a_max);
        if clips_speed {
            let pushes_past = (speed >= v_max && accel > 0.0) || (speed <= v_min && accel < 0.0);
            if pushes_past {
                accel = 0.0;
            }
            gap += (lead_speed - speed) * dt - accel * dt * dt / 2.0;
            speed = (speed + accel * dt).clamp(v_min, v_max);
        } else {
            accel = accel.clamp((v_min - speed) / dt, (v_max - speed) / dt);
            gap += (lead_speed - speed) * dt - accel * dt * dt / 2.0;
            speed += accel * dt;
        }
        if hit(gap) {
            return (true, 0.0);
        }
        closest = closest.min(ttc(gap, speed));
    }
    (false, closest)
}

fn respond(
    driver: &mut dyn Driver,
    criticality: bool,
    message: &Value,
    world: &mut Value,
) -> Value {
    match message["type"].as_str() {
        Some("hello") => json!({"type": "hello", "protocol": 2, "name": driver.name(),
                                "cases": {"cut-in": ["episode"]},
                                "deterministic": driver.deterministic()}),
        Some("reset") if message["case"] == "cut-in" && message["mode"] == "episode" => {
            *world = message["world"].clone();
            json!({"type": "ready"})
        }
        Some("reset") => json!({"type": "error",
            "message": format!("cannot drive {} in {} mode", message["case"], message["mode"])}),
        Some("episode") => {
            let (event, closest) = run(driver, world, &message["scenario"]);
            if criticality {
                json!({"type": "outcome", "event": event, "criticality": closest})
            } else {
                json!({"type": "outcome", "event": event})
            }
        }
        _ => json!({"type": "error", "message": format!("unexpected message {message}")}),
    }
}

/// Answers the coordinator's worker on stdin/stdout until it hangs up;
/// with `criticality`, an outcome also says how close the run came.
pub fn serve(driver: &mut dyn Driver, criticality: bool) {
    let mut world = Value::Null;
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let reply = match serde_json::from_str(&line) {
            Ok(message) => respond(driver, criticality, &message, &mut world),
            Err(e) => json!({"type": "error", "message": format!("not JSON: {e}")}),
        };
        if writeln!(out, "{reply}").and_then(|()| out.flush()).is_err() {
            break;
        }
    }
}

/// The options every such program reads: `--criticality`, and numbers ≥ 0
/// by name (`--noise 1.5`), handed to `set` (which refuses what it does
/// not know, naming its options).
pub fn parse_options(program: &str, mut set: impl FnMut(&str, f64) -> Result<(), String>) -> bool {
    let mut args = std::env::args().skip(1);
    let mut criticality = false;
    let result = (|| {
        while let Some(flag) = args.next() {
            if flag == "--criticality" {
                criticality = true;
                continue;
            }
            let value = args.next().ok_or_else(|| format!("{flag} takes a value"))?;
            let number = value
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| format!("{flag} takes a number ≥ 0, not {value}"))?;
            set(&flag, number)?;
        }
        Ok::<(), String>(())
    })();
    if let Err(e) = result {
        eprintln!("{program}: {e}");
        std::process::exit(2);
    }
    criticality
}
