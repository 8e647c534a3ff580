//! The cost of driving a vehicle under test over the external protocol
//! against the built-in model, on one thread: car-following NDD tests (300
//! control steps each; accidents, which end a test early, have probability
//! about 10⁻⁶) in step mode, and cut-in NDD tests in episode mode. Prints a
//! table.
//!
//! ```sh
//! cargo build --release --example fvdm_vut
//! cargo bench --bench vut_protocol
//! ```

use std::path::PathBuf;
use std::time::{Duration, Instant};
use tslg_method::cases::open_case;
use tslg_method::registry::{CampaignTests, ExposureSource};
use tslg_method::sampling::{OutsideSpread, Split};
use tslg_worker::external::{Program, ProgramRun, ProgramSettings, ProgramSpec};

/// Runs tests `0..n` and returns the seconds they took.
fn time(n: u64, run: impl Fn(u64)) -> f64 {
    let started = Instant::now();
    for index in 0..n {
        run(index);
    }
    started.elapsed().as_secs_f64()
}

fn program(spec: &str) -> Option<Program> {
    let settings = ProgramSettings {
        worker: "bench".into(),
        timeout: Duration::from_secs(60),
        max_failures: 1,
        cooldown: Duration::from_secs(60),
    };
    match Program::start(spec.parse::<ProgramSpec>().ok()?, settings) {
        Ok(p) => Some(p),
        Err(e) => {
            eprintln!("skipped: {e}");
            None
        }
    }
}

fn drive(program: &Program, tests: &dyn CampaignTests, index: u64) {
    match program.run_test(tests, 0, index) {
        ProgramRun::Done(..) => {}
        other => panic!("test {index}: {other:?}"),
    }
}

/// The Rust example built in release mode, next to this benchmark.
fn rust_example() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let path = exe.parent()?.parent()?.join("examples/fvdm_vut");
    if path.exists() {
        Some(path)
    } else {
        eprintln!(
            "skipped the Rust example: build it first with `cargo build --release --example fvdm_vut`"
        );
        None
    }
}

struct Row {
    vehicle: String,
    mode: &'static str,
    tests: u64,
    steps_per_test: f64,
    seconds: f64,
}

fn main() {
    let python = format!(
        "py-idm=python3 {}/examples/python/idm_vut.py",
        env!("CARGO_MANIFEST_DIR")
    );
    let rust = rust_example().map(|p| format!("rs-fvdm={}", p.display()));
    let mut rows = Vec::new();

    // Step mode: car-following, 300 steps per test.
    let follow = open_case("car-following", None, &ExposureSource::Builtin).unwrap();
    let ndd = |vut: serde_json::Value| {
        follow
            .campaign(None, &vut, 0.0, OutsideSpread::Ndd, Split::Stratified, 1)
            .unwrap()
    };
    let builtin = ndd(serde_json::json!({"model": "idm"}));
    let n = 20_000;
    rows.push(Row {
        vehicle: "built-in idm".into(),
        mode: "in process",
        tests: n,
        steps_per_test: 300.0,
        seconds: time(n, |i| {
            builtin.run(i);
        }),
    });
    if let Some(p) = program(&python) {
        let tests = ndd(serde_json::json!({"external": "py-idm"}));
        let n = 300;
        rows.push(Row {
            vehicle: "python idm (examples/python)".into(),
            mode: "step",
            tests: n,
            steps_per_test: 300.0,
            seconds: time(n, |i| drive(&p, tests.as_ref(), i)),
        });
    }

    // Cut-in (paper-code preset: 10 steps of 1 s) in both modes.
    let cut_in = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let ndd = |vut: serde_json::Value| {
        cut_in
            .campaign(
                None,
                &vut,
                0.0,
                OutsideSpread::Uniform,
                Split::Stratified,
                1,
            )
            .unwrap()
    };
    let builtin = ndd(serde_json::json!({"model": "fvdm"}));
    let n = 1_000_000;
    rows.push(Row {
        vehicle: "built-in fvdm, cut-in".into(),
        mode: "in process",
        tests: n,
        steps_per_test: 10.0,
        seconds: time(n, |i| {
            builtin.run(i);
        }),
    });
    if let Some(p) = rust.as_deref().and_then(program) {
        for (mode, n) in [("step", 10_000), ("episode", 20_000)] {
            let tests = ndd(serde_json::json!({"external": "rs-fvdm", "mode": mode}));
            rows.push(Row {
                vehicle: "rust fvdm (examples/fvdm_vut.rs), cut-in".into(),
                mode,
                tests: n,
                steps_per_test: 10.0,
                seconds: time(n, |i| drive(&p, tests.as_ref(), i)),
            });
        }
        // The Rust FVDM in step mode on car-following too, for the
        // per-step cost over 300 steps.
        let tests = follow
            .campaign(
                None,
                &serde_json::json!({"external": "rs-fvdm"}),
                0.0,
                OutsideSpread::Ndd,
                Split::Stratified,
                1,
            )
            .unwrap();
        let n = 500;
        rows.push(Row {
            vehicle: "rust fvdm (examples/fvdm_vut.rs), car-following".into(),
            mode: "step",
            tests: n,
            steps_per_test: 300.0,
            seconds: time(n, |i| {
                // The example declares cut-in only; the protocol does not
                // care, so it drives car-following observations as well.
                let _ = p.run_test(tests.as_ref(), 0, i);
            }),
        });
    }

    println!(
        "| vehicle | mode | tests | tests/s | control steps/s | µs per step |\n|---|---|---:|---:|---:|---:|"
    );
    for r in &rows {
        let steps = r.tests as f64 * r.steps_per_test;
        println!(
            "| {} | {} | {} | {:.0} | {:.0} | {:.3} |",
            r.vehicle,
            r.mode,
            r.tests,
            r.tests as f64 / r.seconds,
            steps / r.seconds,
            r.seconds / steps * 1e6
        );
    }
}
