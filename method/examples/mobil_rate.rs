//! Scratch: MOBIL simulation rate and a fingerprint of every run on the paper grid.
use std::hash::{Hash, Hasher};
use std::time::Instant;
use tslg_method::case::Case;
use tslg_method::cases::highway::{ExitVehicle, HighwayExit, HighwayPreset};

fn main() {
    let case = HighwayExit::builtin(HighwayPreset::Paper);
    let cells: Vec<usize> = (0..case.grid().len())
        .filter(|&c| case.exposure().p(c) > 0.0)
        .collect();
    for name in std::env::var("MODELS")
        .unwrap_or("mobil,gap-seeker".into())
        .split(",")
    {
        let v = ExitVehicle::builtin(name).unwrap();
        if std::env::var("BATCH_ONLY").is_ok() {
            let mut ev = vec![false; cells.len()];
            let t = Instant::now();
            case.events(&v, &cells, &mut ev);
            println!(
                "{name} batched: {:.3} µs/run",
                t.elapsed().as_secs_f64() * 1e6 / cells.len() as f64
            );
            continue;
        }
        let mut h = std::collections::hash_map::DefaultHasher::new();
        let mut steps = 0.0;
        let mut left = 0.0;
        let t = Instant::now();
        for &c in &cells {
            let r = case.run(&v, c);
            r.outcome.hash(&mut h);
            r.time.to_bits().hash(&mut h);
            r.lane_change
                .map(|(a, b)| (a.to_bits(), b.to_bits()))
                .hash(&mut h);
            steps += r.time;
            left += r.lane_change.map_or(r.time, |(t, _)| t);
        }
        let s = t.elapsed().as_secs_f64();
        println!(
            "{name}: {:.3} µs/run, {:.1} ns/step, mean steps {:.1}, fingerprint {:016x}",
            s * 1e6 / cells.len() as f64,
            s * 1e9 / (steps * 10.0),
            steps * 10.0 / cells.len() as f64,
            h.finish()
        );
        println!("  left-lane share {:.3}", left / steps);
        let mut ev = vec![false; cells.len()];
        let t = Instant::now();
        case.events(&v, &cells, &mut ev);
        let s = t.elapsed().as_secs_f64();
        let mut h = std::collections::hash_map::DefaultHasher::new();
        ev.hash(&mut h);
        let mut h2 = std::collections::hash_map::DefaultHasher::new();
        let scalar: Vec<bool> = cells.iter().map(|&c| case.is_event(&v, c)).collect();
        scalar.hash(&mut h2);
        println!(
            "  batched: {:.3} µs/run, events {} , same as scalar {}",
            s * 1e6 / cells.len() as f64,
            ev.iter().filter(|&&e| e).count(),
            h.finish() == h2.finish()
        );
    }
}

#[allow(dead_code)]
fn batched() {}
