//! Car-following library generation (SPEC §6): the surrogate's transitions
//! and zones on the 45,885-state grid, then the Q-table by backward dynamic
//! programming and by the paper's TD(0), with their times and their largest
//! difference. Run with `cargo bench -p tslg-method --bench carfollow`.

use std::time::Instant;
use tslg_method::cases::carfollow::{
    dynamic_programming, temporal_difference, FollowExposure, FollowExposureModel, FollowSampler,
    FollowState, FollowWorld, StateGrid, Transitions,
};

fn main() {
    let world = FollowWorld::paper();
    let grid = StateGrid::paper();
    let model = FollowExposureModel::default();
    let exposure = FollowExposure::from_model(&model, &world, &grid);
    let idm = tslg_method::cases::carfollow::highway_vehicle("idm").expect("built-in");
    println!("| measurement | value |");
    println!("|---|---|");
    // NDD tests one after another on one thread: 30 BV decisions, 300
    // steps of the vehicle each (fewer when it crashes).
    let ndd = FollowSampler::ndd(world, grid, &exposure);
    for name in ["idm", "fvdm"] {
        let vut = tslg_method::vehicle::VehicleModel::builtin(name).expect("built-in");
        let tests = 200_000u64;
        let t = Instant::now();
        let crashes = (0..tests)
            .filter(|&i| std::hint::black_box(ndd.run(&vut, 1, i)).accident)
            .count();
        let seconds = t.elapsed().as_secs_f64();
        println!(
            "| NDD test per core, {name} ({tests} tests, {crashes} accidents) | {:.2} µs |",
            seconds * 1e6 / tests as f64
        );
        let follower = tslg_method::vehicle::batch::BatchFollower::of(&vut).expect("batched");
        let indices: Vec<u64> = (0..tests).collect();
        let t = Instant::now();
        let crashes: usize = indices
            .chunks(tslg_method::vehicle::batch::LANES)
            .map(|lanes| {
                std::hint::black_box(ndd.run_batch(&follower, 1, lanes))
                    .iter()
                    .filter(|test| test.accident)
                    .count()
            })
            .sum();
        let seconds = t.elapsed().as_secs_f64();
        println!(
            "| NDD test per core, batched, {name} ({tests} tests, {crashes} accidents) | {:.2} µs |",
            seconds * 1e6 / tests as f64
        );
    }
    let t = Instant::now();
    let transitions = Transitions::compute(&world, grid, &exposure, &idm);
    println!(
        "| zones and transitions of the IDM surrogate, {} states × {} actions, all threads | {:.2} s |",
        grid.len(),
        world.actions,
        t.elapsed().as_secs_f64()
    );
    println!(
        "| dangerous share of the states | {:.3} |",
        transitions.dangerous_share()
    );
    let t = Instant::now();
    let dp = dynamic_programming(&transitions, 1e-12);
    println!(
        "| dynamic programming to 1e-12 ({} sweeps), one thread | {:.3} s |",
        dp.iterations,
        t.elapsed().as_secs_f64()
    );
    let t = Instant::now();
    let td = temporal_difference(&transitions, 0.1, 1e-10, 0);
    println!(
        "| TD(0), α 0.1, to abs(δ) < 1e-10 ({} updates), one thread | {:.3} s |",
        td.iterations,
        t.elapsed().as_secs_f64()
    );
    println!(
        "| largest abs(Q_DP − Q_TD) | {:.2e} |",
        dp.max_difference(&td)
    );
    let initial = &exposure.initial;
    let mu: f64 = initial.iter().zip(&dp.challenge).map(|(p, c)| p * c).sum();
    println!("| μ_S = Σ_s P(s) P(S|s) (the SM's accident rate on the grid chain) | {mu:.3e} |");
    let s = grid
        .nearest(&FollowState {
            bv_speed: 38.0,
            range: 6.0,
            range_rate: -2.0,
        })
        .expect("on the grid");
    let ndd = model.actions(&world, 38.0);
    if let Some(lib) = dp.action_distribution(s) {
        let peak = (0..world.actions)
            .max_by(|&a, &b| lib[a].total_cmp(&lib[b]))
            .expect("actions");
        println!(
            "| s = (38, 6, −2): P(S|s); library peak; P(u ≤ −3) library vs NDD | {:.3e}; u = {:.1}; {:.3} vs {:.2e} |",
            dp.challenge[s],
            world.action(peak),
            (0..world.actions).filter(|&k| world.action(k) <= -3.0 + 1e-9).map(|k| lib[k]).sum::<f64>(),
            (0..world.actions).filter(|&k| world.action(k) <= -3.0 + 1e-9).map(|k| ndd[k]).sum::<f64>(),
        );
    } else {
        println!("| s = (38, 6, −2) | not dangerous |");
    }
}
