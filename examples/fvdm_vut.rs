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
//! Options make it another vehicle or a slow one: `--gain K` sets the
//! FVDM's sensitivity `k` (0.85; a lower gain reacts later and crashes
//! more), `--sleep SECONDS` waits that long at the start of every test, as
//! a simulator or a test track would take, and `--tally FILE` appends a
//! byte to FILE for every test, so a benchmark can count the tests run
//! (`benches/slow_vehicle.rs`). Two more make it a vehicle that is not
//! bit-reproducible (docs/statistics.md, "Noisy vehicles"): `--noise SIGMA`
//! adds Gaussian noise of σ m/s² to every commanded acceleration, from
//! fresh entropy each run (its hello then says `"deterministic": false`),
//! `--brake-harder A` brakes A m/s² harder whenever the FVDM brakes, a
//! program that differs from the others', and `--drop-events P` reports no
//! event in a share P of the tests that had one (episode mode), a careless
//! or lying operator's program.
//!
//! The protocol (one JSON object per line) is docs/vut-protocol.md.

use rand::rngs::ThreadRng;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde_json::{json, Value};
use std::io::{BufRead, Write};

/// The vehicle's settings, from the command line.
#[derive(Debug, Default)]
struct Settings {
    /// The FVDM's sensitivity `k`.
    gain: f64,
    /// Seconds every test waits at its start.
    sleep: f64,
    /// Where a byte is appended for every test.
    tally: Option<std::fs::File>,
    /// σ of the noise on every command (m/s²); 0: deterministic.
    noise: f64,
    /// How much harder than the FVDM it brakes (m/s²).
    brake_harder: f64,
    /// The share of its events it hides (episode mode).
    drop_events: f64,
    /// Entropy from the operating system, for the noise.
    entropy: ThreadRng,
}

impl Settings {
    /// `--gain K`, `--sleep SECONDS` and `--tally FILE`, each optional.
    fn parse(args: impl Iterator<Item = String>) -> Result<Self, String> {
        let mut settings = Settings {
            gain: 0.85,
            entropy: rand::rng(),
            ..Settings::default()
        };
        let mut args = args;
        while let Some(flag) = args.next() {
            let value = args.next().ok_or_else(|| format!("{flag} takes a value"))?;
            let number = || {
                value
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| format!("{flag} takes a number ≥ 0"))
            };
            match flag.as_str() {
                "--gain" => settings.gain = number()?,
                "--sleep" => settings.sleep = number()?,
                "--noise" => settings.noise = number()?,
                "--brake-harder" => settings.brake_harder = number()?,
                "--drop-events" => {
                    settings.drop_events = number()?;
                    if settings.drop_events > 1.0 {
                        return Err("--drop-events takes a share in [0, 1]".into());
                    }
                }
                "--tally" => {
                    let file = std::fs::OpenOptions::new()
                        .create(true)
                        .append(true)
                        .open(&value)
                        .map_err(|e| format!("--tally {value}: {e}"))?;
                    settings.tally = Some(file);
                }
                other => {
                    return Err(format!(
                        "unknown option {other}; options: --gain, --sleep, --tally, --noise, \
                         --brake-harder, --drop-events"
                    ))
                }
            }
        }
        Ok(settings)
    }

    /// A test starts: counted, then the wait.
    fn start_test(&mut self) {
        if let Some(tally) = &mut self.tally {
            let _ = tally.write_all(b".");
        }
        if self.sleep > 0.0 {
            std::thread::sleep(std::time::Duration::from_secs_f64(self.sleep));
        }
    }

    /// The command at `speed` and `gap`: the FVDM, `a = k (V₁ + V₂ tanh(C₁
    /// (R − L) − C₂) − v)` with the built-in defaults but for `k`, braking
    /// `--brake-harder` more, plus the noise.
    fn command(&mut self, speed: f64, gap: f64) -> f64 {
        let optimal_speed = 6.75 + 7.91 * (0.13 * (gap - 5.0) - 1.57).tanh();
        let mut a = self.gain * (optimal_speed - speed);
        if a < 0.0 {
            a -= self.brake_harder;
        }
        if self.noise > 0.0 {
            let normal = Normal::new(0.0, self.noise).expect("σ is finite and positive");
            a += normal.sample(&mut self.entropy);
        }
        a
    }
}

fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The cut-in at `(range, range_rate)`: the leader keeps its speed; each
/// step the acceleration is clipped to its bounds and to what keeps the
/// speed in bounds, then the gap and the speed advance.
fn crashes(settings: &mut Settings, world: &Value, scenario: &Value) -> bool {
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
            let accel = settings
                .command(speed, gap)
                .clamp(number(&a[0]), number(&a[1]))
                .clamp((number(&v[0]) - speed) / dt, (number(&v[1]) - speed) / dt);
            gap += (lead_speed - speed) * dt - accel * dt * dt / 2.0;
            speed += accel * dt;
            hit(gap)
        })
}

fn respond(settings: &mut Settings, message: &Value, world: &mut Value) -> Value {
    match message["type"].as_str() {
        Some("hello") => json!({"type": "hello", "protocol": 1, "name": "rs-fvdm",
                                "cases": {"cut-in": ["step", "episode"]},
                                "deterministic": settings.noise == 0.0}),
        Some("reset") => {
            settings.start_test();
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
            let accel = settings
                .command(number(&message["ego"]["speed"]), number(&lead["gap"]))
                .clamp(number(&a[0]), number(&a[1]));
            json!({"type": "control", "acceleration": accel})
        }
        Some("episode") => {
            let crashed = crashes(settings, world, &message["scenario"]);
            let hidden = crashed
                && settings.drop_events > 0.0
                && settings.entropy.random_bool(settings.drop_events);
            json!({"type": "outcome", "event": crashed && !hidden})
        }
        _ => json!({"type": "error", "message": format!("unexpected message {message}")}),
    }
}

fn main() {
    let mut settings = match Settings::parse(std::env::args().skip(1)) {
        Ok(settings) => settings,
        Err(e) => {
            eprintln!("fvdm_vut: {e}");
            std::process::exit(2);
        }
    };
    let mut world = Value::Null;
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let reply = match serde_json::from_str(&line) {
            Ok(message) => respond(&mut settings, &message, &mut world),
            Err(e) => json!({"type": "error", "message": format!("not JSON: {e}")}),
        };
        if writeln!(out, "{reply}").and_then(|()| out.flush()).is_err() {
            break;
        }
    }
}
