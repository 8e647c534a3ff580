//! `tslg policy`: the car-following library's action distribution at one
//! state, `P(u|s, S) = Q(s, u) / Σ_u Q(s, u)`, beside the naturalistic
//! `P(u|v)` (SPEC §6; the paper's example is s = (38, 6, −2)).

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use std::time::Instant;
use tslg_method::cases::carfollow::{
    dynamic_programming, highway_vehicle, temporal_difference, FollowExposure, FollowExposureModel,
    FollowState, FollowWorld, StateGrid, Transitions, Zone, FOLLOW_MODELS,
};

/// `v,R,Ṙ` as three numbers.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SolverArg {
    /// Backward dynamic programming.
    Dp,
    /// The paper's TD(0) (α 0.1, until every |δ| < 1e-10).
    Td,
}

#[derive(Debug, Args)]
pub struct PolicyArgs {
    /// The state `v_BV,R,Ṙ` (m/s, m, m/s); looked up at the nearest grid state.
    #[arg(long, default_value = "38,6,-2", allow_hyphen_values = true)]
    pub state: String,
    /// The surrogate: `idm` or `acc-aeb` (highway versions, docs/models.md).
    #[arg(long, default_value = "idm")]
    pub surrogate: String,
    /// How the Q-values are computed.
    #[arg(long, value_enum, default_value = "dp")]
    pub solver: SolverArg,
}

fn parse_state(text: &str) -> anyhow::Result<FollowState> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--state `{text}` must be three numbers v,R,Ṙ"))?;
    let [bv_speed, range, range_rate] = values[..] else {
        bail!("--state `{text}` must be three numbers v,R,Ṙ");
    };
    if values.iter().any(|v| !v.is_finite()) {
        bail!("--state `{text}` must be finite");
    }
    Ok(FollowState {
        bv_speed,
        range,
        range_rate,
    })
}

pub fn run(args: &PolicyArgs) -> anyhow::Result<()> {
    let state = parse_state(&args.state)?;
    let surrogate = highway_vehicle(&args.surrogate).with_context(|| {
        format!(
            "unknown car-following surrogate `{}`; models are {}",
            args.surrogate,
            FOLLOW_MODELS.join(", ")
        )
    })?;
    let (world, grid, exposure) = (
        FollowWorld::paper(),
        StateGrid::paper(),
        FollowExposureModel::default(),
    );
    let Some(s) = grid.nearest(&state) else {
        bail!(
            "--state range {} m is beyond the grid (at most 115 m): the vehicles are not following",
            state.range
        );
    };
    let started = Instant::now();
    let transitions = crate::commands::progress::with_progress("transitions", |progress| {
        let exposure = FollowExposure::from_model(&exposure, &world, &grid);
        Transitions::compute_observed(&world, grid, &exposure, &surrogate, progress)
    });
    let (library, solver) = match args.solver {
        SolverArg::Dp => (
            dynamic_programming(&transitions, 1e-12),
            "dynamic programming",
        ),
        SolverArg::Td => (
            temporal_difference(&transitions, 0.1, 1e-10, 0),
            "TD(0) learning",
        ),
    };
    let at = grid.state(s);
    let zone = match transitions.zones[s] {
        Zone::Collision => "collision",
        Zone::Safe => "safe",
        Zone::Dangerous => "dangerous",
    };
    outln!(
        "library of {} by {solver} in {:.2} s; state (v {}, R {}, Ṙ {}), zone {zone}, P(S|s) = {:.4e}",
        args.surrogate,
        started.elapsed().as_secs_f64(),
        at.bv_speed,
        at.range,
        at.range_rate,
        library.challenge[s]
    );
    // The grid's nearest state answers for an off-grid one: say so.
    let asked = (state.bv_speed, state.range, state.range_rate);
    if asked != (at.bv_speed, at.range, at.range_rate) {
        outln!(
            "(--state {} is not a grid state: the nearest one answers)",
            args.state
        );
    }
    let ndd = exposure.actions(&world, at.bv_speed);
    let guided = library.action_distribution(s);
    if transitions.zones[s] != Zone::Dangerous || guided.is_none() {
        outln!("not a dangerous state: library tests act by the NDD here");
    }
    outln!("\n{:>6} {:>12} {:>12}", "u", "NDD P(u|v)", "P(u|s, S)");
    for k in 0..world.actions {
        let library_p = guided.as_ref().map_or(f64::NAN, |g| g[k]);
        outln!(
            "{:>6.1} {:>12.4e} {:>12.4e}",
            world.action(k),
            ndd[k],
            library_p
        );
    }
    if let Some(g) = &guided {
        let peak = (0..world.actions)
            .max_by(|&a, &b| g[a].total_cmp(&g[b]))
            .expect("actions");
        outln!(
            "\nthe library's distribution peaks at u = {:.1} m/s²",
            world.action(peak)
        );
    }
    Ok(())
}
