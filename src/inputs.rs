//! Turning command-line arguments into the method's types, with errors that
//! say which argument is wrong and why. Every case is opened through its
//! descriptor and the registry (`tslg_method::cases`), so these commands
//! work the same on each.

use crate::{CaseArgs, RuleArgs};
use anyhow::Context;
use std::path::Path;
use std::sync::Arc;
use tslg_method::cases::open_case;
use tslg_method::estimator::StoppingRule;
use tslg_method::library::{read_head, LibraryHead};
use tslg_method::registry::{ExposureSource, ScenarioCase};

/// An exposure table file: its name (the file's) and its text.
pub fn read_table(path: &Path) -> anyhow::Result<(String, String)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the NDD table {}", path.display()))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string());
    Ok((name, text))
}

/// The exposure of table `path`, or the case's built-in model.
pub fn exposure_source(path: Option<&Path>) -> anyhow::Result<ExposureSource> {
    Ok(match path {
        None => ExposureSource::Builtin,
        Some(path) => {
            let (name, text) = read_table(path)?;
            ExposureSource::Table { name, text }
        }
    })
}

/// The case `args` names on its exposure and preset. What the user should
/// know about how the exposure was read (a table renormalised to 1) is
/// printed on stderr.
pub fn open(args: &CaseArgs) -> anyhow::Result<Arc<dyn ScenarioCase>> {
    let exposure = exposure_source(args.ndd_table.as_deref())?;
    let case = open_case(args.name(), args.preset.as_deref(), &exposure).with_context(|| {
        match &args.ndd_table {
            Some(path) => format!("case {} with NDD table {}", args.name(), path.display()),
            None => format!("case {}", args.name()),
        }
    })?;
    if let Some(note) = case.exposure_note() {
        eprintln!("note: {note}");
    }
    Ok(case)
}

/// A library file's bytes and its head (the case, preset and exposure it
/// was built for).
pub fn read_library_file(path: &Path) -> anyhow::Result<(Vec<u8>, LibraryHead)> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("cannot read the library file {}", path.display()))?;
    let head =
        read_head(&bytes).with_context(|| format!("library file {} rejected", path.display()))?;
    Ok((bytes, head))
}

/// `args` with the case and preset of a library built for them: a command
/// given a library runs on the simulation it was built on. A `--case` or
/// `--preset` that says otherwise is an error with the reason.
pub fn case_of_library(args: &CaseArgs, head: &LibraryHead) -> anyhow::Result<CaseArgs> {
    if let Some(case) = &args.case {
        anyhow::ensure!(
            *case == head.case,
            "--case {case}: the library was built for case {}; leave --case out",
            head.case
        );
    }
    if let Some(preset) = &args.preset {
        anyhow::ensure!(
            *preset == head.preset,
            "--preset {preset}: the library was built on preset {}, and its criticality means \
             nothing on another simulation; leave --preset out or build the library with \
             --preset {preset}",
            head.preset
        );
    }
    Ok(CaseArgs {
        case: Some(head.case.clone()),
        preset: Some(head.preset.clone()),
        ndd_table: args.ndd_table.clone(),
    })
}

/// A vehicle given as a built-in name or as a JSON specification, written
/// out in full by `case` (its defaults for what the specification leaves
/// out), or why `case` cannot run it.
pub fn vehicle_spec(
    case: &dyn ScenarioCase,
    text: &str,
    what: &str,
) -> anyhow::Result<serde_json::Value> {
    let spec = if text.trim_start().starts_with('{') {
        serde_json::from_str(text).with_context(|| format!("invalid {what} specification"))?
    } else {
        serde_json::json!({ "model": text })
    };
    case.normalise_vehicle(&spec)
        .with_context(|| format!("invalid {what} `{text}`"))
}

/// A vehicle specification's short name: its model or its program.
pub fn vehicle_name(spec: &serde_json::Value) -> String {
    spec.get("model")
        .or_else(|| spec.get("external"))
        .and_then(|m| m.as_str())
        .unwrap_or("?")
        .to_owned()
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
