//! An external vehicle under test for tslg, in Rust and linking nothing of
//! tslg: the FVDM of SPEC §4 on the cut-in case. In step mode it answers
//! each observation with an acceleration; in episode mode it runs the whole
//! cut-in itself from the scenario and the world's settings, as a test
//! track or a heavy simulator would, and reports whether it crashed.
//!
//! ```sh
//! cargo build --release --example fvdm_vut
//! tslg-worker --vut-exec rs-fvdm=target/release/examples/fvdm_vut
//! ```
//!
//! The protocol (one JSON object per line) is docs/vut-protocol.md.

use serde_json::{json, Value};
use std::io::{BufRead, Write};

/// `a = k (V₁ + V₂ tanh(C₁ (R − L) − C₂) − v)` with the built-in defaults.
fn fvdm(speed: f64, gap: f64) -> f64 {
    let optimal_speed = 6.75 + 7.91 * (0.13 * (gap - 5.0) - 1.57).tanh();
    0.85 * (optimal_speed - speed)
}

fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The cut-in at `(range, range_rate)`: the leader keeps its speed; each
/// step the acceleration is clipped to its bounds and to what keeps the
/// speed in bounds, then the gap and the speed advance.
fn crashes(world: &Value, scenario: &Value) -> bool {
    let (dt, v0) = (number(&world["dt"]), number(&world["initial_speed"]));
    let (a, v) = (&world["acceleration"], &world["speed"]);
    let accident_gap = number(&world["accident_gap"]);
    let hit = |gap: f64| match world["inclusive"].as_bool() {
        Some(true) => gap <= accident_gap,
        _ => gap < accident_gap,
    };
    let lead_speed = v0 + number(&scenario["range_rate"]);
    let (mut gap, mut speed) = (number(&scenario["range"]), v0);
    let steps = world["steps"].as_u64().unwrap_or(0);
    hit(gap)
        || (0..steps).any(|_| {
            let accel = fvdm(speed, gap)
                .clamp(number(&a[0]), number(&a[1]))
                .clamp((number(&v[0]) - speed) / dt, (number(&v[1]) - speed) / dt);
            gap += (lead_speed - speed) * dt - accel * dt * dt / 2.0;
            speed += accel * dt;
            hit(gap)
        })
}

fn respond(message: &Value, world: &mut Value) -> Value {
    match message["type"].as_str() {
        Some("hello") => json!({"type": "hello", "protocol": 1, "name": "rs-fvdm",
                                "cases": {"cut-in": ["step", "episode"]}}),
        Some("reset") => {
            *world = message["world"].clone();
            json!({"type": "ready"})
        }
        Some("step") => {
            let lead = message["vehicles"]
                .as_array()
                .and_then(|vs| vs.iter().find(|v| v.get("gap").is_some()));
            let Some(lead) = lead else {
                return json!({"type": "error", "message": "no vehicle ahead"});
            };
            let a = &world["acceleration"];
            let accel = fvdm(number(&message["ego"]["speed"]), number(&lead["gap"]))
                .clamp(number(&a[0]), number(&a[1]));
            json!({"type": "control", "acceleration": accel})
        }
        Some("episode") => {
            json!({"type": "outcome", "event": crashes(world, &message["scenario"])})
        }
        _ => json!({"type": "error", "message": format!("unexpected message {message}")}),
    }
}

fn main() {
    let mut world = Value::Null;
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let reply = match serde_json::from_str(&line) {
            Ok(message) => respond(&message, &mut world),
            Err(e) => json!({"type": "error", "message": format!("not JSON: {e}")}),
        };
        if writeln!(out, "{reply}").and_then(|()| out.flush()).is_err() {
            break;
        }
    }
}
