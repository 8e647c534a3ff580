//! A highway-exit vehicle under test for tslg, in Rust and linking nothing
//! of tslg: a cautious merger, a driver unlike the MOBIL surrogate and the
//! gap-seeker (issue 54's own 4-D check). It runs in step mode: the worker
//! simulates the world and measures the criticality; the program answers
//! each observation with a control.
//!
//! ```sh
//! cargo build --release --example merger_vut
//! tslg validate --quick --cases highway-exit --methods adaptive,adaptive-guarded \
//!     --vut-exec merger=target/release/examples/merger_vut
//! ```
//!
//! Its rule, with `d` the distance left to the exit `L − p`:
//!
//! - **left lane, `d > D`** (`--merge-at D`; by default it looks from the
//!   start, a smaller `D` makes it a late merger): cruise,
//!   `a = k (v_c − v)` with `k` 0.5/s and `v_c` the starting speed;
//! - **left lane, `d ≤ D`**: change lanes when every BV in the right lane
//!   leaves a bumper gap of at least `max(h, t_min)` times the follower's
//!   speed, `t_min` times the BV's and 1 m, plus `w²/(2 · 3 m/s²)` when the
//!   follower closes at `w` (`--gap h`, 0.8 s; `t_min` the world's safe
//!   time gap); otherwise, against the nearest BV that blocks, accelerate
//!   at the world's upper bound to pass it when it is more than 4 m/s
//!   slower, else brake at the lower bound to let it go;
//! - **right lane**: IDM behind the BV ahead (v₀ 33 m/s, T 1 s, s₀ 2 m,
//!   a 1.5, b 2 m/s²).
//!
//! It misses the exit when it cannot let a BV go, or pass it, before the
//! off-ramp: failures of another shape than the surrogate's, and many of
//! them away from any of the surrogate's failures or near misses.
//! The protocol (one JSON object per line) is docs/vut-protocol.md.

use serde_json::{json, Value};
use std::io::{BufRead, Write};

/// The driver's settings, from the command line.
#[derive(Debug, Clone, Copy)]
struct Settings {
    /// Distance to the exit from which it looks for a gap (m).
    merge_at: f64,
    /// Time gap it accepts, at the follower's speed (s).
    gap: f64,
}

impl Settings {
    /// `--merge-at D` and `--gap H`, each optional.
    fn parse(mut args: impl Iterator<Item = String>) -> Result<Self, String> {
        let mut settings = Settings {
            merge_at: f64::INFINITY,
            gap: 0.8,
        };
        while let Some(flag) = args.next() {
            let value = args.next().ok_or_else(|| format!("{flag} takes a value"))?;
            let number = value
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| format!("{flag} takes a number > 0, not {value}"))?;
            match flag.as_str() {
                "--merge-at" => settings.merge_at = number,
                "--gap" => settings.gap = number,
                other => {
                    return Err(format!(
                        "unknown option {other}; options: --merge-at, --gap"
                    ))
                }
            }
        }
        Ok(settings)
    }
}

fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// A vehicle in the right lane, as a step shows it.
struct Other {
    position: f64,
    speed: f64,
}

/// The IDM's acceleration at `speed` behind a vehicle `gap` metres ahead
/// closing at `closing` m/s (none: free road).
fn idm(speed: f64, ahead: Option<(f64, f64)>) -> f64 {
    let (v0, headway, s0, a, b) = (33.0, 1.0, 2.0, 1.5, 2.0);
    let free = 1.0 - (speed / v0).powi(4);
    match ahead {
        None => a * free,
        Some((gap, closing)) => {
            let desired = s0 + speed * headway + speed * closing / (2.0 * (a * b).sqrt());
            a * (free - (desired.max(0.0) / gap.max(0.1)).powi(2))
        }
    }
}

/// The control at one step: `(acceleration, change_lane)`.
fn control(settings: &Settings, world: &Value, message: &Value) -> (f64, bool) {
    let ego = &message["ego"];
    let (p, v, lane) = (
        number(&ego["position"]),
        number(&ego["speed"]),
        ego["lane"].as_u64(),
    );
    let length = number(&world["vehicle_length"]);
    let others: Vec<Other> = message["vehicles"]
        .as_array()
        .map(|vs| {
            vs.iter()
                .filter(|o| o["lane"].as_u64() == Some(0))
                .map(|o| Other {
                    position: number(&o["position"]),
                    speed: number(&o["speed"]),
                })
                .collect()
        })
        .unwrap_or_default();
    if lane == Some(0) {
        let ahead = others
            .iter()
            .filter(|o| o.position > p)
            .min_by(|a, b| a.position.total_cmp(&b.position))
            .map(|o| (o.position - p - length, v - o.speed));
        return (idm(v, ahead), false);
    }
    let distance_left = number(&world["exit"]) - p;
    let cruise = number(&world["start_speed"]);
    if distance_left > settings.merge_at {
        return (0.5 * (cruise - v), false);
    }
    let t_min = number(&world["safe_time_gap"]);
    let time_gap = settings.gap.max(t_min);
    // A BV blocks when the gap on either side is short of the time gap at
    // the follower's speed, of the world's safe gap at the BV's, or of 1 m.
    let blocks = |o: &Other| {
        // Closing at w, the follower needs w²/(2·3 m/s²) more to match speeds.
        let closing = |follower: f64, leader: f64| (follower - leader).max(0.0).powi(2) / 6.0;
        if o.position >= p {
            o.position - p - length
                < (time_gap * v).max(t_min * o.speed).max(1.0) + closing(v, o.speed)
        } else {
            p - o.position - length < (time_gap * o.speed).max(1.0) + closing(o.speed, v)
        }
    };
    let nearest = others
        .iter()
        .filter(|o| blocks(o))
        .min_by(|a, b| (a.position - p).abs().total_cmp(&(b.position - p).abs()));
    let (brake, accelerate) = (
        number(&world["acceleration"][0]),
        number(&world["acceleration"][1]),
    );
    match nearest {
        None => (0.0, true),
        // Pass a much slower one, let any other go.
        Some(o) => (if o.speed + 4.0 < v { accelerate } else { brake }, false),
    }
}

fn respond(settings: &Settings, message: &Value, world: &mut Value) -> Value {
    match message["type"].as_str() {
        Some("hello") => json!({"type": "hello", "protocol": 1, "name": "merger",
                                "cases": {"highway-exit": ["step"]},
                                "deterministic": true}),
        Some("reset") => {
            *world = message["world"].clone();
            json!({"type": "ready"})
        }
        Some("step") => {
            let (acceleration, change_lane) = control(settings, world, message);
            json!({"type": "control", "acceleration": acceleration, "change_lane": change_lane})
        }
        _ => json!({"type": "error", "message": format!("unexpected message {message}")}),
    }
}

fn main() {
    let settings = match Settings::parse(std::env::args().skip(1)) {
        Ok(settings) => settings,
        Err(e) => {
            eprintln!("merger_vut: {e}");
            std::process::exit(2);
        }
    };
    let mut world = Value::Null;
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let reply = match serde_json::from_str(&line) {
            Ok(message) => respond(&settings, &message, &mut world),
            Err(e) => json!({"type": "error", "message": format!("not JSON: {e}")}),
        };
        if writeln!(out, "{reply}").and_then(|()| out.flush()).is_err() {
            break;
        }
    }
}
