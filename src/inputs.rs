//! Turning command-line arguments into the method's types, with errors that
//! say which argument is wrong and why.

use crate::{CaseArgs, RuleArgs};
use anyhow::{bail, Context};
use std::path::Path;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::estimator::StoppingRule;
use tslg_method::library::Library;
use tslg_method::vehicle::VehicleModel;

/// The cut-in case on the requested exposure and preset. A table whose sum
/// was off 1 by a little is renormalised, and the user is told.
pub fn load_case(args: &CaseArgs) -> anyhow::Result<CutIn> {
    tslg_method::cases::descriptor(&args.case)?;
    if args.case != "cut-in" {
        bail!(
            "case `{}` is not supported by the offline commands (library build, evaluate, exact), which run cut-in only; every case runs through the service (tslg demo --case, tslg campaign start)",
            args.case
        );
    }
    let preset: CutInPreset = match &args.preset {
        None => CutInPreset::default(),
        Some(p) => p.parse().map_err(|e: String| anyhow::anyhow!(e))?,
    };
    let Some(path) = &args.ndd_table else {
        return Ok(CutIn::builtin(preset));
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the NDD table {}", path.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string());
    let (case, table) = CutIn::from_table(&text, name, preset)
        .with_context(|| format!("NDD table {} rejected", path.display()))?;
    if table.mass.was_renormalised() {
        eprintln!(
            "note: the NDD table {} sums to {:.7}; it was renormalised to 1",
            path.display(),
            table.mass.original_sum()
        );
    }
    Ok(case)
}

/// A vehicle given as a built-in name or as a JSON specification.
pub fn parse_vehicle(text: &str, what: &str) -> anyhow::Result<VehicleModel> {
    if text.trim_start().starts_with('{') {
        serde_json::from_str(text).with_context(|| format!("invalid {what} specification"))
    } else {
        VehicleModel::builtin(text).with_context(|| format!("invalid {what}"))
    }
}

pub fn read_library(path: &Path) -> anyhow::Result<Library> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the library file {}", path.display()))?;
    Library::from_json(&text).with_context(|| format!("library file {} rejected", path.display()))
}

/// The rule of `args`; `exploring_share` sets the default `n_min`
/// ([`tslg_method::estimator::default_n_min`]).
pub fn stopping_rule(
    args: &RuleArgs,
    exploring_share: Option<f64>,
) -> anyhow::Result<StoppingRule> {
    let rule = StoppingRule {
        beta: args.beta,
        confidence: args.confidence,
        n_min: args.n_min.unwrap_or_else(|| {
            tslg_method::estimator::default_n_min(exploring_share, args.max_tests)
        }),
        min_events: args.min_events,
        max_tests: args.max_tests,
        guard_outside: args.guard_outside,
    };
    rule.validate().context("invalid stopping rule")?;
    Ok(rule)
}

/// ε must be 0 or in the method's range.
pub fn check_epsilon(epsilon: f64) -> anyhow::Result<()> {
    tslg_method::sampling::check_epsilon(epsilon).map_err(|e| anyhow::anyhow!("--epsilon: {e}"))
}
