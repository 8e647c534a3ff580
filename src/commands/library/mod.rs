//! `tslg library …`: `build` and `show` in this process, for every case
//! through its descriptor and the registry; `create`, `delete` and `list`
//! on a coordinator ([`coordinator`], [`crate::commands::listing`]).

mod coordinator;

pub use coordinator::wait_for_library;

use crate::args::{wire_name, CaseArgs, SearchArgs, ServerArgs};
use crate::commands::listing;
use crate::commands::progress::with_progress;
use crate::inputs::{open, read_library_file, surrogate_or_default, vehicle_name, vehicle_spec};
use anyhow::Context;
use clap::{Args, Subcommand};
use std::path::Path;
use std::path::PathBuf;
use std::time::Instant;
use tslg_method::cases::open_case;
use tslg_method::library::{Library, LibrarySearch, SearchMethod};
use tslg_method::registry::cells::grid_library_summary;
use tslg_method::registry::{BuildRequest, ExposureSource, LibraryBuilder, LibrarySummary};

#[derive(Debug, Subcommand)]
pub enum LibraryCommand {
    /// Search the critical scenarios of a surrogate model and write a library file.
    Build(BuildArgs),
    /// Print a summary of a library file.
    Show {
        /// The library file.
        file: PathBuf,
    },
    /// Ask a running coordinator to build a library.
    Create(coordinator::LibraryCreateArgs),
    /// Delete a library no campaign uses from a coordinator (with its file).
    Delete {
        /// The library's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the coordinator's libraries, newest first, a line each.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Only those in this state: building, ready or failed.
        #[arg(long, value_parser = wire_name::<tslg_api::LibraryStatus>)]
        status: Option<tslg_api::LibraryStatus>,
        /// Print JSON (as `GET /api/v1/libraries` answers).
        #[arg(long)]
        json: bool,
    },
}

/// Runs `tslg library …`.
pub fn run(command: LibraryCommand) -> anyhow::Result<()> {
    match command {
        LibraryCommand::Build(args) => build(&args),
        LibraryCommand::Show { file } => show(&file),
        LibraryCommand::Create(args) => coordinator::create_library(&args),
        LibraryCommand::Delete { id, server } => coordinator::delete_library(&server, id),
        LibraryCommand::List {
            server,
            status,
            json,
        } => listing::libraries(&server, status, json),
    }
}

#[derive(Debug, Args)]
pub struct BuildArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model: a built-in name (`tslg cases` lists each case's)
    /// or a JSON specification such as '{"model":"idm","v0":25}' (default:
    /// the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Also run the exhaustive search and report the recall of a multistart
    /// search (grid cases).
    #[arg(long)]
    pub recall: bool,
    /// Where to write the library (JSON for grid cases, the binary policy
    /// format for car-following; docs/library-format.md).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Replace `--out` if it exists (without it the command refuses).
    #[arg(long)]
    pub force: bool,
}

fn build(args: &BuildArgs) -> anyhow::Result<()> {
    crate::inputs::check_overwrite(std::slice::from_ref(&args.out), args.force)?;
    let case = open(&args.case)?;
    let descriptor = case.descriptor().clone();
    let surrogate = vehicle_spec(
        case.as_ref(),
        surrogate_or_default(&args.case, &args.surrogate)?,
        "surrogate",
    )?;
    if let Some(threshold) = args.search.threshold() {
        threshold.validate().context("invalid threshold")?;
    }
    if args.search.starts == Some(0) {
        anyhow::bail!("--starts must be at least 1");
    }
    let request = BuildRequest {
        threshold: args.search.threshold(),
        search: args.search.search(&descriptor),
    };
    case.check_request(&request)?;
    let started = Instant::now();
    let built = with_progress(descriptor.build_unit, |progress| {
        case.build_library_observed(&surrogate, &request, progress)
    })?;
    let elapsed = started.elapsed();
    let mut file = built.file;
    let multistart = matches!(
        request.search.unwrap_or(descriptor.default_search),
        LibrarySearch::Cells(SearchMethod::Multistart { .. })
    );
    if args.recall {
        anyhow::ensure!(
            descriptor.is_grid(),
            "--recall measures a multistart search against the exhaustive one: grid cases only"
        );
        // An exhaustive library is its own reference.
        if multistart {
            file = with_recall(case.as_ref(), &surrogate, &request, &file)?;
        }
    }
    std::fs::write(&args.out, &file)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    print_summary(&case.library_summary(&file)?, descriptor.scenario_unit);
    outln!("build time         {:.3} s", elapsed.as_secs_f64());
    outln!("written to         {}", args.out.display());
    Ok(())
}

/// The grid library `file` with the recall of its multistart search against
/// an exhaustive search of the same surrogate.
fn with_recall(
    case: &dyn LibraryBuilder,
    surrogate: &serde_json::Value,
    request: &BuildRequest,
    file: &[u8],
) -> anyhow::Result<Vec<u8>> {
    let exhaustive = BuildRequest {
        search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
        ..*request
    };
    let reference = with_progress("recall", |progress| {
        case.build_library_observed(surrogate, &exhaustive, progress)
    })?;
    let read = |bytes: &[u8]| -> anyhow::Result<Library> {
        Ok(Library::from_json(std::str::from_utf8(bytes)?)?)
    };
    let mut library = read(file)?;
    library.search.recall = Some(library.recall_against(&read(&reference.file)?));
    Ok(library.to_json().into_bytes())
}

fn show(path: &Path) -> anyhow::Result<()> {
    let (file, head) = read_library_file(path)?;
    // The summary reads the file alone: a built-in case opens on its
    // built-in exposure whatever the library was built on; a user-defined
    // case's library is a self-describing grid library.
    let (summary, unit) = match open_case(&head.case, Some(&head.preset), &ExposureSource::Builtin)
    {
        Ok(case) => (case.library_summary(&file), case.descriptor().scenario_unit),
        Err(_) => (grid_library_summary(&file), "scenarios"),
    };
    let summary = summary.with_context(|| format!("library file {} rejected", path.display()))?;
    print_summary(&summary, unit);
    Ok(())
}

fn print_summary(library: &LibrarySummary, unit: &str) {
    let n = library.total;
    outln!("case               {} ({})", library.case, library.preset);
    outln!(
        "surrogate          {}",
        vehicle_name(&library.surrogate, &library.case)
    );
    outln!(
        "exposure           {} (fingerprint {})",
        library.exposure.name,
        library.exposure.fingerprint
    );
    outln!(
        "library size       {} of {} {unit} ({:.2}%)",
        library.size,
        n,
        100.0 * library.size as f64 / n as f64
    );
    outln!("mu_S               {:.6e}", library.mu_s);
    outln!(
        "W                  {:.6e} ({:.2}% of mu_S)",
        library.w,
        100.0 * library.w / library.mu_s
    );
    if let Some(gamma) = library.gamma {
        outln!("gamma              {gamma:.6e}");
    }
    outln!("search             {}", library.search);
    outln!("SM evaluations     {}", library.sm_evaluations);
    if let Some(recall) = library.recall {
        outln!(
            "recall             {:.2}% of the exhaustive library's criticality",
            100.0 * recall
        );
    }
}
