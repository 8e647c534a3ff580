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
}
