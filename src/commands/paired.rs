//! `tslg evaluate --vut A --paired-with B`: a paired regression campaign in
//! this process. Both vehicles run the same tests (same seed, library, ε),
//! and the difference of their rates comes with its paired interval
//! (`tslg_method::paired`); on a grid case small enough to enumerate, the
//! exact difference is printed beside it.

use crate::commands::exact::exact_answer;
use crate::inputs::vehicle_spec;
use serde::Serialize;
use tslg_method::estimator::StoppingRule;
use tslg_method::paired::{run_paired, PairedResult, PairedStop};
use tslg_method::registry::ScenarioCase;
use tslg_method::sampling::{OutsideSpread, Split};

/// What both campaigns share: the case, the library (none for the NDD) and
/// how tests are drawn from it.
pub struct Plan<'a> {
    pub case: &'a dyn ScenarioCase,
    pub file: Option<&'a [u8]>,
    pub epsilon: f64,
    pub outside: OutsideSpread,
    pub split: Split,
    pub seed: u64,
}

#[derive(Serialize)]
struct Report<'a> {
    case: &'static str,
    vut: &'a serde_json::Value,
    paired_with: &'a serde_json::Value,
    #[serde(flatten)]
    result: &'a PairedResult,
    /// The exact P(A) of each and their difference, where the grid can be
    /// enumerated here.
    exact: Option<(f64, f64, f64)>,
}

pub fn run(
    plan: &Plan<'_>,
    vut: &serde_json::Value,
    other: &str,
    rule: &StoppingRule,
    json: bool,
) -> anyhow::Result<()> {
    let other = vehicle_spec(plan.case, other, "paired vehicle")?;
    let tests = |vehicle: &serde_json::Value| {
        plan.case.campaign(
            plan.file,
            vehicle,
            plan.epsilon,
            plan.outside,
            plan.split,
            plan.seed,
        )
    };
    let (a, b) = (tests(vut)?, tests(&other)?);
    anyhow::ensure!(
        a.external().is_none() && b.external().is_none(),
        "--paired-with runs built-in vehicles in this process; external programs run on workers"
    );
    let result = run_paired(a.as_ref(), b.as_ref(), rule);
    let exact = exact_answer(plan.case, vut)
        .zip(exact_answer(plan.case, &other))
        .map(|(pa, pb)| (pa, pb, pa - pb));
    let report = Report {
        case: plan.case.descriptor().name,
        vut,
        paired_with: &other,
        result: &result,
        exact,
    };
    if json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    let name = |spec: &serde_json::Value| crate::inputs::vehicle_name(spec, report.case);
    let r = &result;
    let interval = |(m, lo, hi): (f64, f64, f64)| format!("{m:.4e}  [{lo:.4e}, {hi:.4e}]");
    outln!("case               {}", report.case);
    // Two builds of one model differ in parameters: show them then.
    let (na, nb) = (name(vut), name(&other));
    if na == nb {
        outln!("vehicles           a = {vut}");
        outln!("                   b = {other}");
    } else {
        outln!("vehicles           a = {na}, b = {nb}");
    }
    outln!(
        "stopped            {} after {} tests",
        match r.stop {
            PairedStop::Precision => "the difference is within beta of the larger rate",
            PairedStop::Significant => "the difference's interval excludes zero",
            PairedStop::Exhausted => "max tests reached (exhausted)",
        },
        r.tests
    );
    outln!(
        "events             a {}, b {}, discordant (one failed) {}",
        r.events.0,
        r.events.1,
        r.events.2
    );
    outln!("P(A) of a          {}", interval(r.rate_a));
    outln!("P(A) of b          {}", interval(r.rate_b));
    outln!("difference a - b   {}", interval(r.difference));
    if let Some(level) = r.look_confidence {
        outln!("                   (zero excluded at confidence {level:.4})");
    }
    if let Some(t) = r.independent_tests {
        outln!(
            "independent        two separate campaigns: about {t:.0} tests each for this \
             half-width ({:.1} x)",
            t / r.tests as f64
        );
    }
    if let Some((pa, pb, d)) = exact {
        outln!("exact              a {pa:.4e}, b {pb:.4e}, difference {d:.4e}");
    }
    Ok(())
}
