//! Turning command-line arguments into the method's types, with errors that
//! say which argument is wrong and why. Every case is opened through its
//! descriptor and the registry (`tslg_method::cases`), so these commands
//! work the same on each.

use crate::args::{CaseArgs, RuleArgs};
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;
use tslg_method::cases::open_case;
use tslg_method::cases::user::file::CaseFile;
use tslg_method::estimator::StoppingRule;
use tslg_method::external::{ProgramConversation, ProgramHost};
use tslg_method::library::{read_head, LibraryHead};
use tslg_method::registry::{CaseIdentity, ExposureSource, ScenarioCase};
use tslg_worker::external::{ProgramSettings, ProgramSpec, Programs};

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

/// A user-defined case's file, read and checked, and its folder.
pub fn read_case_file(path: &Path) -> anyhow::Result<(CaseFile, PathBuf)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the case file {}", path.display()))?;
    let file = CaseFile::parse(&text)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("case file {} rejected", path.display()))?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    Ok((file, dir))
}

/// A user-defined case's programs, started when the case first runs one
/// (a command that only reads the case starts none; a table that is wrong
/// is reported before any program runs).
struct LazyPrograms {
    names: Vec<String>,
    specs: Mutex<Option<Vec<ProgramSpec>>>,
    settings: ProgramSettings,
    started: OnceLock<Result<Programs, String>>,
}

impl ProgramHost for LazyPrograms {
    fn has(&self, name: &str) -> bool {
        self.names.iter().any(|n| n == name)
    }

    fn converse(
        &self,
        name: &str,
        conversation: &ProgramConversation<'_>,
    ) -> Result<(bool, Option<f64>), String> {
        let programs = self.started.get_or_init(|| {
            let specs = self
                .specs
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .take()
                .unwrap_or_default();
            Programs::start_specs(specs, &self.settings)
                .map_err(|e| format!("the programs could not start: {e}"))
        });
        programs
            .as_ref()
            .map_err(Clone::clone)?
            .converse(name, conversation)
    }
}

/// The user-defined case of `path` on `exposure` (its own table when
/// built-in), its program and those of `--vut-exec` started here to run
/// as its surrogates and vehicles.
fn open_user_case(
    path: &Path,
    args: &CaseArgs,
    exposure: &ExposureSource,
) -> anyhow::Result<Arc<dyn ScenarioCase>> {
    let (file, dir) = read_case_file(path)?;
    let max = tslg_worker::MAX_VUT_SECONDS;
    anyhow::ensure!(
        args.vut_timeout_seconds.is_finite()
            && args.vut_timeout_seconds > 0.0
            && args.vut_timeout_seconds <= max,
        "--vut-timeout {} must be in (0, {max}] seconds",
        args.vut_timeout_seconds
    );
    let table_path = dir.join(&file.exposure);
    let table = std::fs::read_to_string(&table_path).with_context(|| {
        format!(
            "case file {}: cannot read its exposure table {}",
            path.display(),
            table_path.display()
        )
    })?;
    let mut own: ProgramSpec = format!("{}={}", file.program, file.command)
        .parse()
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("case file {}", path.display()))?;
    own.dir = Some(dir);
    let mut specs = vec![own];
    for text in &args.vut_exec {
        specs.push(text.parse().map_err(anyhow::Error::msg)?);
    }
    let settings = ProgramSettings {
        worker: "tslg".into(),
        timeout: Duration::from_secs_f64(args.vut_timeout_seconds),
        max_failures: 5,
        cooldown: Duration::from_secs(1),
    };
    let programs = LazyPrograms {
        names: specs.iter().map(|s| s.name.clone()).collect(),
        specs: Mutex::new(Some(specs)),
        settings,
        started: OnceLock::new(),
    };
    let table_name = file.exposure.clone();
    Ok(tslg_method::cases::user::descriptor::open(
        file,
        &table_name,
        &table,
        args.preset.as_deref(),
        exposure,
        Some(Arc::new(programs)),
    )?)
}

/// The case `args` names on its exposure and preset. What the user should
/// know about how the exposure was read (a table renormalised to 1) is
/// printed on stderr.
pub fn open(args: &CaseArgs) -> anyhow::Result<Arc<dyn ScenarioCase>> {
    let exposure = exposure_source(args.ndd_table.as_deref())?;
    let case = match &args.case_file {
        Some(path) => open_user_case(path, args, &exposure)?,
        None => {
            open_case(args.name(), args.preset.as_deref(), &exposure).with_context(
                || match &args.ndd_table {
                    Some(path) => format!("case {} with NDD table {}", args.name(), path.display()),
                    None => format!("case {}", args.name()),
                },
            )?
        }
    };
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
    if let Some(path) = &args.case_file {
        let (file, _) = read_case_file(path)?;
        anyhow::ensure!(
            file.name == head.case,
            "--case-file {}: the library was built for case {}, the file defines {}",
            path.display(),
            head.case,
            file.name
        );
        return Ok(args.clone());
    }
    anyhow::ensure!(
        tslg_method::cases::descriptor(&head.case).is_ok(),
        "the library was built for case {}, which is not built in: give its --case-file",
        head.case
    );
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
        ..args.clone()
    })
}

/// A vehicle given as a built-in name (a program's, on a user-defined
/// case) or as a JSON specification, written
/// out in full by `case` (its defaults for what the specification leaves
/// out), or why `case` cannot run it.
pub fn vehicle_spec(
    case: &dyn CaseIdentity,
    text: &str,
    what: &str,
) -> anyhow::Result<serde_json::Value> {
    let spec = if text.trim_start().starts_with('{') {
        serde_json::from_str(text).with_context(|| format!("invalid {what} specification"))?
    } else if case.descriptor().vehicles.is_empty() {
        // A user-defined case's vehicles are programs.
        serde_json::json!({ "external": text, "mode": "episode" })
    } else {
        serde_json::json!({ "model": text })
    };
    case.normalise_vehicle(&spec)
        .with_context(|| format!("invalid {what} `{text}`"))
}

/// A vehicle specification's short name on case `case`: its model or its
/// program, the parameters that differ from the model's defaults there
/// (`idm (v0 25)`), and the noise on its commands when it has some
/// (`idm (noise 1.5)`); [`tslg_method::cases::vehicle_label`].
pub fn vehicle_name(spec: &serde_json::Value, case: &str) -> String {
    tslg_method::cases::vehicle_label(spec, case)
}

/// The rule of `args`; `exploring_share` sets the default `n_min`
/// ([`tslg_method::estimator::default_n_min`]), `guard_by_default` whether
/// the guard is on unless the flags say (a noisy vehicle's campaign that
/// can take it, [`tslg_method::noise::guards_by_default`]).
pub fn stopping_rule(
    args: &RuleArgs,
    exploring_share: Option<f64>,
    guard_by_default: bool,
) -> anyhow::Result<StoppingRule> {
    let rule = StoppingRule {
        beta: args.beta,
        confidence: args.confidence,
        n_min: args.n_min.unwrap_or_else(|| {
            tslg_method::estimator::default_n_min(exploring_share, args.max_tests)
        }),
        min_events: args.min_events,
        max_tests: args.max_tests,
        guard_outside: args.guard_request().unwrap_or(guard_by_default),
        interval: args.interval,
    };
    rule.validate().context("invalid stopping rule")?;
    Ok(rule)
}

/// ε must be 0 or in the method's range.
pub fn check_epsilon(epsilon: f64) -> anyhow::Result<()> {
    tslg_method::sampling::check_epsilon(epsilon).map_err(|e| anyhow::anyhow!("--epsilon: {e}"))
}

/// The case `case` names: a built-in or registered one by its descriptor,
/// a user-defined one from its case file.
pub fn case_descriptor(case: &CaseArgs) -> anyhow::Result<tslg_method::cases::CaseDescriptor> {
    match &case.case_file {
        Some(path) => Ok(tslg_method::cases::user::descriptor::descriptor(
            &read_case_file(path)?.0,
        )),
        None => Ok(tslg_method::cases::descriptor(case.name())?),
    }
}

/// `given`, or the default surrogate of the case `case` names.
pub fn surrogate_or_default<'a>(
    case: &CaseArgs,
    given: &'a Option<String>,
) -> anyhow::Result<&'a str> {
    Ok(match given {
        Some(v) => v.as_str(),
        None => case_descriptor(case)?.default_surrogate,
    })
}

/// Refuses to replace any of `paths` that exists unless `force`: a command
/// that writes results says so before it does the work, not after.
pub fn check_overwrite(paths: &[std::path::PathBuf], force: bool) -> anyhow::Result<()> {
    if force {
        return Ok(());
    }
    if let Some(existing) = paths.iter().find(|p| p.exists()) {
        anyhow::bail!("{} exists; pass --force to replace it", existing.display());
    }
    Ok(())
}
