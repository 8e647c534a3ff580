//! The layering of docs/architecture.md, checked on the sources: no two
//! files of a crate import each other, directly or around a loop.

use crate::module_graph::{workspace_roots, ModuleGraph};
use std::path::Path;

fn workspace() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every crate of the workspace (each library, binary and test root) is a
/// tree of files without an import cycle. A cycle names its files and what
/// each of them imports of the others.
#[test]
fn no_file_imports_itself_around_a_loop() {
    let roots = workspace_roots(workspace());
    assert!(roots.len() >= 10, "the workspace's crate roots: {roots:?}");
    let mut report = String::new();
    let mut files = 0;
    for root in &roots {
        let graph = ModuleGraph::read(workspace(), root).unwrap();
        files += graph.files.len();
        for cycle in graph.cycles() {
            report.push_str(&format!("cycle in {}:\n", root.display()));
            for file in &cycle {
                for (to, paths) in graph.imports_of(file) {
                    if cycle.iter().any(|c| c == to) {
                        report.push_str(&format!(
                            "  {} -> {}: {}\n",
                            file.display(),
                            to.display(),
                            paths.join(", ")
                        ));
                    }
                }
            }
        }
    }
    assert!(files > 200, "read only {files} files");
    assert!(report.is_empty(), "import cycles between files:\n{report}");
}

/// The coordinator's layers (docs/architecture.md): the routes (with
/// `lib.rs`, which serves them) over the domain (`report/`, `leasing/`,
/// `builds/`, the views, campaign starts…) over `store/` over `db/`. Every
/// import points down or sideways; only the routes speak HTTP (`axum`,
/// `hyper`, `tower`); only `store/` and `db/` hold SQL statements; the
/// store answers in its own error type.
#[test]
fn the_coordinator_s_layers_point_down() {
    let root = workspace().join("server/src/lib.rs");
    let graph = ModuleGraph::read(workspace(), &root).unwrap();
    let layer = |file: &Path| -> u8 {
        let path = file.to_string_lossy();
        if path.starts_with("server/src/db/") {
            0
        } else if path.starts_with("server/src/store/") {
            1
        } else if path.starts_with("server/src/routes/") || path == "server/src/lib.rs" {
            3
        } else {
            2
        }
    };
    let mut wrong = Vec::new();
    for (from, to) in &graph.edges {
        let (a, b) = (&graph.files[*from], &graph.files[*to]);
        if layer(a) < layer(b) {
            wrong.push(format!("{} imports {} above it", a.display(), b.display()));
        }
    }
    for (file, crates) in graph.files.iter().zip(&graph.crates) {
        let http: Vec<&String> = crates
            .iter()
            .filter(|c| ["axum", "hyper", "tower", "tower_http"].contains(&c.as_str()))
            .collect();
        if layer(file) < 3 && !http.is_empty() {
            wrong.push(format!("{} speaks HTTP ({http:?})", file.display()));
        }
    }
    for (file, sql) in graph.files.iter().zip(&graph.sql) {
        if layer(file) > 1 && !sql.is_empty() {
            wrong.push(format!("{} holds SQL: {:?}", file.display(), sql[0]));
        }
    }
    let store_errors = graph
        .files
        .iter()
        .filter(|f| layer(f) <= 1)
        .filter_map(|f| {
            let text = std::fs::read_to_string(workspace().join(f)).unwrap();
            (text.contains("ServiceError") && !f.ends_with("store/error.rs"))
                .then(|| f.display().to_string())
        })
        .collect::<Vec<_>>();
    for f in store_errors {
        wrong.push(format!("{f} names the service's error type"));
    }
    assert!(wrong.is_empty(), "layering broken:\n{}", wrong.join("\n"));
    // What the check relies on: it read the layers, their HTTP and SQL.
    let sql_files = graph.sql.iter().filter(|s| !s.is_empty()).count();
    assert!(sql_files >= 8, "{sql_files} files with SQL found");
    assert!(graph.crates.iter().any(|c| c.contains("axum")));
}

/// The coordinator's domain folders (`campaign/`, `report/`, `leasing/`,
/// `builds/`, `telemetry/`) import each other one way only: a folder is
/// a concept, and two that need each other are one concept split, or a
/// piece in the wrong one (issue 69: `report/tests_cache` and
/// `report/explored`, `leasing/claim` and `report/dodging`).
#[test]
fn the_coordinator_s_domain_folders_import_each_other_one_way() {
    let root = workspace().join("server/src/lib.rs");
    let graph = ModuleGraph::read(workspace(), &root).unwrap();
    let folder = |file: &Path| -> Option<String> {
        let rest = file.strip_prefix("server/src").ok()?;
        let mut parts = rest.components();
        let first = parts.next()?.as_os_str().to_string_lossy().into_owned();
        // A top-level file is its own module, not a folder.
        parts.next().map(|_| first)
    };
    let mut pairs = std::collections::BTreeMap::<(String, String), Vec<String>>::new();
    for &(from, to) in &graph.edges {
        let (a, b) = (&graph.files[from], &graph.files[to]);
        if let (Some(fa), Some(fb)) = (folder(a), folder(b)) {
            if fa != fb {
                pairs.entry((fa, fb)).or_default().push(format!(
                    "{} -> {}",
                    a.display(),
                    b.display()
                ));
            }
        }
    }
    assert!(pairs.len() >= 5, "folder imports read: {:?}", pairs.keys());
    let mut both_ways = Vec::new();
    for ((a, b), files) in &pairs {
        if a < b {
            if let Some(back) = pairs.get(&(b.clone(), a.clone())) {
                both_ways.push(format!("{a}/ <-> {b}/: {files:?} and {back:?}"));
            }
        }
    }
    assert!(
        both_ways.is_empty(),
        "folders importing each other:\n{}",
        both_ways.join("\n")
    );
}

/// The check finds what it is for, in a crate written for the purpose: a
/// cycle through a parent that uses its child's type, and one made of a
/// path in code and a path inside a macro. It does not count as an import
/// a parent declaring or re-exporting its child, `pub(crate)`, or a test
/// module using its own file.
#[test]
fn the_cycle_check_sees_uses_paths_and_macros() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir_all(src.join("store")).unwrap();
    std::fs::create_dir_all(src.join("vehicle")).unwrap();
    let write = |name: &str, text: &str| std::fs::write(src.join(name), text).unwrap();
    write(
        "lib.rs",
        "mod store;\nmod report;\nmod routes;\nmod vehicle;\n\
         pub(crate) fn f() { let _ = format!(\"{}\", crate::report::N); }\n",
    );
    // store/mod.rs uses its child's type, re-exported; the child uses its
    // parent's type: a cycle of two files.
    write(
        "store/mod.rs",
        "mod rows;\npub use rows::Row;\npub struct Store;\npub fn open() -> Option<Row> { None }\n",
    );
    write(
        "store/rows.rs",
        "use super::Store;\npub struct Row(Store);\n",
    );
    // vehicle/mod.rs only re-exports its child, which uses the parent's
    // type: no cycle.
    write(
        "vehicle/mod.rs",
        "mod idm;\npub use idm::Idm;\npub struct Obs;\n",
    );
    write(
        "vehicle/idm.rs",
        "use super::Obs;\npub struct Idm(pub Obs);\n",
    );
    // report -> routes through a path in code, routes -> report through a
    // macro's tokens: a cycle that no `use` shows.
    write(
        "report.rs",
        "pub const N: u8 = 1;\npub fn g() -> u8 { crate::routes::M }\n#[cfg(test)]\nmod tests { use super::*; }\n",
    );
    write(
        "routes.rs",
        "pub const M: u8 = 2;\npub fn h() { assert!(crate::report::N > 0); }\n",
    );
    let graph = ModuleGraph::read(dir.path(), &src.join("lib.rs")).unwrap();
    let cycles: Vec<Vec<String>> = graph
        .cycles()
        .into_iter()
        .map(|c| c.iter().map(|p| p.display().to_string()).collect())
        .collect();
    assert_eq!(
        cycles,
        vec![
            vec!["src/report.rs".to_string(), "src/routes.rs".to_string()],
            vec![
                "src/store/mod.rs".to_string(),
                "src/store/rows.rs".to_string()
            ],
        ]
    );
    // lib.rs uses report (through format!) but nothing uses lib.rs: no cycle.
    assert_eq!(
        graph.imports_of(Path::new("src/lib.rs")),
        vec![(Path::new("src/report.rs"), vec!["crate::report::N"])]
    );
    // A store that imports its route, speaks HTTP and a route with SQL:
    // what the coordinator's layer check looks for.
    write(
        "store/rows.rs",
        "use super::Store;\nuse axum::Json;\npub struct Row(Store);\n\
         pub fn f() -> u8 { crate::routes::M }\n",
    );
    write(
        "routes.rs",
        "pub const M: u8 = 2;\npub fn h() { let _ = format!(\"SELECT {}\", 1); }\n\
         #[cfg(test)]\nmod tests { const Q: &str = \"DELETE FROM t\"; }\n",
    );
    let graph = ModuleGraph::read(dir.path(), &src.join("lib.rs")).unwrap();
    let rows = graph
        .files
        .iter()
        .position(|f| f.ends_with("store/rows.rs"))
        .unwrap();
    let routes = graph
        .files
        .iter()
        .position(|f| f.ends_with("src/routes.rs"))
        .unwrap();
    assert!(graph.edges.contains(&(rows, routes)));
    assert!(
        graph.crates[rows].contains("axum"),
        "{:?}",
        graph.crates[rows]
    );
    assert_eq!(graph.sql[routes], vec!["SELECT {}".to_string()]);
}

/// The text of docs/architecture.md from the heading `from` to the next
/// heading of the same level.
fn layout_section(from: &str) -> String {
    let doc = std::fs::read_to_string(workspace().join("docs/architecture.md")).unwrap();
    let start = doc
        .find(from)
        .unwrap_or_else(|| panic!("no `{from}` in docs/architecture.md"));
    let level = from.split(' ').next().unwrap();
    let rest = &doc[start + from.len()..];
    let end = rest
        .match_indices(&format!("\n{level} "))
        .next()
        .map_or(rest.len(), |(k, _)| k);
    rest[..end].to_owned()
}

/// The modules directly in `dir`: `name` for `name.rs`, `name/` for a
/// folder with its own `mod.rs` (a folder beside `name.rs` is the file's).
fn modules_in(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if path.join("mod.rs").exists() && name != "tests" {
                found.push(format!("{name}/"));
            }
        } else if let Some(stem) = name.strip_suffix(".rs") {
            if !matches!(stem, "mod" | "lib" | "main" | "tests") && !stem.ends_with("_tests") {
                found.push(stem.to_owned());
            }
        }
    }
    found.sort();
    found
}

/// Whether `text` names module `module` (`name` or `name/`) in code
/// quotes: `` `name` ``, `` `name/` ``, `` `name.rs` ``, a path ending in
/// it, or a rustdoc link `` [`name`] ``.
fn names(text: &str, module: &str) -> bool {
    let stem = module.trim_end_matches('/');
    [
        format!("`{stem}`"),
        format!("`{stem}/"),
        format!("`{stem}.rs"),
        format!("/{stem}`"),
        format!("/{stem}.rs"),
        format!("/{stem}/"),
        format!("`{stem}` ("),
    ]
    .iter()
    .any(|form| text.contains(form.as_str()))
        || text.contains(&format!("`{stem},"))
        || text.contains(&format!(" {stem}`"))
}

/// Every module has a line in the layout docs: each file of the
/// coordinator in docs/architecture.md's "Server modules" (and its top
/// folders in `server/src/lib.rs`'s layout), each of the method crate's
/// modules in "The method crate" and `method/src/lib.rs`'s layout, each
/// command module in "The command line", and each of `report/`'s files in
/// its `mod.rs`, each file of the API, client, figures and worker crates in
/// "The smaller crates' files". A module added without a line fails here.
#[test]
fn every_module_is_in_the_layout_docs() {
    let mut missing = Vec::new();
    let mut check = |what: &str, text: &str, modules: Vec<String>| {
        for module in modules {
            if !names(text, &module) {
                missing.push(format!("{module} (in {what})"));
            }
        }
    };
    let server = workspace().join("server/src");
    let server_doc = layout_section("### Server modules");
    check(
        "architecture.md, Server modules",
        &server_doc,
        modules_in(&server),
    );
    // A folder's files in its own row of the table (a name such as
    // `start` or `verdict` is in more than one folder).
    for entry in std::fs::read_dir(&server).unwrap() {
        let folder = entry.unwrap().path();
        if folder.is_dir() {
            let name = folder.file_name().unwrap().to_string_lossy().into_owned();
            let row = server_doc
                .lines()
                .find(|l| l.starts_with('|') && l.contains(&format!("`{name}/`")))
                .unwrap_or_else(|| panic!("no row of `{name}/` in Server modules"));
            check(
                &format!("architecture.md, Server modules, the row of {name}/"),
                row,
                modules_in(&folder),
            );
        }
    }
    let lib = std::fs::read_to_string(server.join("lib.rs")).unwrap();
    check("server/src/lib.rs", &lib, modules_in(&server));
    let report = std::fs::read_to_string(server.join("report/mod.rs")).unwrap();
    check(
        "server/src/report/mod.rs",
        &report,
        modules_in(&server.join("report")),
    );
    let method = workspace().join("method/src");
    check(
        "architecture.md, The method crate",
        &layout_section("## The method crate"),
        modules_in(&method),
    );
    let method_lib = std::fs::read_to_string(method.join("lib.rs")).unwrap();
    check("method/src/lib.rs", &method_lib, modules_in(&method));
    check(
        "architecture.md, The command line",
        &layout_section("## The command line"),
        modules_in(&workspace().join("src/commands")),
    );
    // The smaller crates, a row each (and the worker's `external/`).
    let smaller = layout_section("### The smaller crates' files");
    for (krate, dir) in [
        ("tslg-api", "api/src"),
        ("tslg-client", "client/src"),
        ("tslg-figures", "figures/src"),
        ("tslg-worker", "worker/src"),
        ("tslg-worker", "worker/src/external"),
    ] {
        let row = smaller
            .lines()
            .find(|l| l.starts_with(&format!("| `{krate}`")))
            .unwrap_or_else(|| panic!("no row of `{krate}` in The smaller crates' files"));
        check(
            &format!("architecture.md, The smaller crates' files, {krate}"),
            row,
            modules_in(&workspace().join(dir)),
        );
    }
    assert!(
        missing.is_empty(),
        "modules without a line in their layout docs:\n  {}",
        missing.join("\n  ")
    );
}
