//! `tslg library build` and `tslg library show`.

use crate::commands::progress::with_progress;
use crate::inputs::{load_case, parse_vehicle, read_library};
use crate::{BuildArgs, SearchArg};
use anyhow::{bail, Context};
use std::path::Path;
use std::time::Instant;
use tslg_method::library::{
    build_library_observed, Library, LibraryRequest, SearchMethod, Threshold,
};

pub fn build(args: &BuildArgs) -> anyhow::Result<()> {
    let case = load_case(&args.case)?;
    let surrogate = parse_vehicle(&args.surrogate, "surrogate")?;
    let threshold = match args.gamma {
        Some(gamma) => Threshold::Absolute { gamma },
        None => Threshold::Relative {
            m: args.threshold_m,
        },
    };
    threshold.validate().context("invalid threshold")?;
    let search = match args.search {
        SearchArg::DynamicProgramming | SearchArg::TemporalDifference => bail!(
            "dynamic-programming and temporal-difference learn car-following libraries, \
             which the service builds: tslg library create --case car-following"
        ),
        SearchArg::Exhaustive => SearchMethod::Exhaustive,
        SearchArg::Multistart => {
            if args.starts == 0 {
                bail!("--starts must be at least 1");
            }
            SearchMethod::Multistart {
                starts: args.starts,
                seed: args.seed,
            }
        }
    };
    let spec = serde_json::to_value(surrogate)?;
    let preset = case.preset().name();
    let started = Instant::now();
    let mut library = with_progress("search", |progress| {
        build_library_observed(
            &case,
            &surrogate,
            spec.clone(),
            preset,
            &LibraryRequest { threshold, search },
            progress,
        )
    });
    let elapsed = started.elapsed();
    if args.recall && search != SearchMethod::Exhaustive {
        let reference = with_progress("recall", |progress| {
            build_library_observed(
                &case,
                &surrogate,
                spec,
                preset,
                &LibraryRequest {
                    threshold,
                    search: SearchMethod::Exhaustive,
                },
                progress,
            )
        });
        library.search.recall = Some(library.recall_against(&reference));
    }
    std::fs::write(&args.out, library.to_json())
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    print_summary(&library);
    println!("build time         {:.3} s", elapsed.as_secs_f64());
    println!("written to         {}", args.out.display());
    Ok(())
}

pub fn show(file: &Path) -> anyhow::Result<()> {
    print_summary(&read_library(file)?);
    Ok(())
}

fn print_summary(library: &Library) {
    let n = library.total_scenarios();
    println!("case               {} ({})", library.case, library.preset);
    println!(
        "surrogate          {}",
        library
            .surrogate
            .get("model")
            .and_then(|m| m.as_str())
            .unwrap_or("?")
    );
    println!(
        "exposure           {} (fingerprint {})",
        library.exposure.name, library.exposure.fingerprint
    );
    println!(
        "library size       {} of {} scenarios ({:.2}%)",
        library.size(),
        n,
        100.0 * library.size() as f64 / n as f64
    );
    println!("mu_S               {:.6e}", library.mu_s);
    println!(
        "W                  {:.6e} ({:.2}% of mu_S)",
        library.w,
        100.0 * library.w / library.mu_s
    );
    println!("gamma              {:.6e}", library.gamma);
    let method = match library.search.method {
        SearchMethod::Exhaustive => "exhaustive".to_owned(),
        SearchMethod::Multistart { starts, seed } => {
            format!("multistart ({starts} starts, seed {seed})")
        }
    };
    println!("search             {method}");
    println!("SM evaluations     {}", library.search.sm_evaluations);
    if let Some(recall) = library.search.recall {
        println!(
            "recall             {:.2}% of the exhaustive library's criticality",
            100.0 * recall
        );
    }
}
