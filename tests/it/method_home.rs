//! A campaign method's one home (docs/architecture.md, "Adding a campaign
//! method"): outside `api/src/method.rs`, the code of the service, the
//! worker and the command line asks a method's spec, and names a method
//! only where the section says it may: the files that choose a method's
//! sampler, the builds that start their own campaigns, and the commands
//! that start a given method by name.

use std::path::{Path, PathBuf};
use syn::visit::Visit;

fn workspace() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The variants of `tslg_api::Method`, read from its home.
fn method_variants() -> Vec<String> {
    let text = std::fs::read_to_string(workspace().join("api/src/method.rs")).unwrap();
    let file = syn::parse_file(&text).unwrap();
    file.items
        .iter()
        .find_map(|item| match item {
            syn::Item::Enum(e) if e.ident == "Method" => {
                Some(e.variants.iter().map(|v| v.ident.to_string()).collect())
            }
            _ => None,
        })
        .expect("api/src/method.rs defines `enum Method`")
}

/// Whether `attrs` hold `#[cfg(test)]`.
fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.parse_args::<syn::Ident>()
                .is_ok_and(|ident| ident == "test")
    })
}

/// The methods a file's code (not its tests) names as `Method::Variant`,
/// in paths and inside macros (`matches!`).
struct Namer<'a> {
    variants: &'a [String],
    named: Vec<String>,
}

impl Namer<'_> {
    fn note(&mut self, variant: &str) {
        if self.variants.iter().any(|v| v == variant) && !self.named.iter().any(|n| n == variant) {
            self.named.push(variant.to_owned());
        }
    }
}

impl<'ast> Visit<'ast> for Namer<'_> {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        let attrs = match item {
            syn::Item::Mod(m) => &m.attrs,
            syn::Item::Fn(f) => &f.attrs,
            syn::Item::Impl(i) => &i.attrs,
            syn::Item::Const(c) => &c.attrs,
            syn::Item::Use(u) => &u.attrs,
            _ => return syn::visit::visit_item(self, item),
        };
        if !is_test(attrs) {
            syn::visit::visit_item(self, item);
        }
    }

    fn visit_path(&mut self, path: &'ast syn::Path) {
        let segments: Vec<String> = path.segments.iter().map(|s| s.ident.to_string()).collect();
        if let [.., method, variant] = segments.as_slice() {
            if method == "Method" {
                self.note(variant);
            }
        }
        syn::visit::visit_path(self, path);
    }

    fn visit_use_path(&mut self, path: &'ast syn::UsePath) {
        // `use tslg_api::Method::{Adaptive, Ndd}`, `Method::*`, `as`.
        if path.ident == "Method" {
            let mut trees = vec![&*path.tree];
            while let Some(tree) = trees.pop() {
                match tree {
                    syn::UseTree::Name(n) => self.note(&n.ident.to_string()),
                    syn::UseTree::Rename(r) => self.note(&r.ident.to_string()),
                    syn::UseTree::Glob(_) => {
                        let variants = self.variants;
                        for v in variants {
                            self.note(v);
                        }
                    }
                    syn::UseTree::Group(g) => trees.extend(g.items.iter()),
                    syn::UseTree::Path(_) => {}
                }
            }
        }
        syn::visit::visit_use_path(self, path);
    }

    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        let tokens: Vec<String> = mac.tokens.clone().into_iter().flat_map(flatten).collect();
        for window in tokens.windows(4) {
            if let [method, colon, colon2, variant] = window {
                if method == "Method" && colon == ":" && colon2 == ":" {
                    self.note(variant);
                }
            }
        }
        syn::visit::visit_macro(self, mac);
    }
}

/// A token tree's leaves, as text.
fn flatten(tree: proc_macro2::TokenTree) -> Vec<String> {
    match tree {
        proc_macro2::TokenTree::Group(g) => g.stream().into_iter().flat_map(flatten).collect(),
        other => vec![other.to_string()],
    }
}

/// Every `.rs` file under `dir` that is not a test file.
fn code_files(dir: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if name != "tests" {
                code_files(&path, found);
            }
        } else if name.ends_with(".rs") && name != "tests.rs" && !name.ends_with("_tests.rs") {
            found.push(path);
        }
    }
}

/// The paths docs/architecture.md's "Adding a campaign method" names in
/// code quotes: files (`….rs`) and folders (`…/`).
fn listed_paths() -> Vec<String> {
    let doc = std::fs::read_to_string(workspace().join("docs/architecture.md")).unwrap();
    let start = doc
        .find("## Adding a campaign method")
        .expect("docs/architecture.md has a section `## Adding a campaign method`");
    let rest = &doc[start + 3..];
    let section = &rest[..rest.find("\n## ").unwrap_or(rest.len())];
    section
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|quoted| {
            (quoted.ends_with(".rs") || quoted.ends_with('/')) && !quoted.contains('…')
        })
        .map(str::to_owned)
        .collect()
}

/// Outside its home, the service's, the worker's and the command line's
/// code names a campaign method only in the files docs/architecture.md
/// lists for it; a `match` on methods anywhere else (a rule the spec should
/// hold) fails here, naming the file and the methods.
#[test]
fn a_campaign_method_is_named_only_in_its_home_and_the_files_that_choose_its_tests() {
    let variants = method_variants();
    assert!(variants.len() >= 5, "{variants:?}");
    let listed = listed_paths();
    for path in &listed {
        assert!(
            workspace().join(path).exists(),
            "docs/architecture.md lists `{path}`, which does not exist"
        );
    }
    let mut files = Vec::new();
    for root in [
        "server/src",
        "worker/src",
        "client/src",
        "figures/src",
        "src",
    ] {
        code_files(&workspace().join(root), &mut files);
    }
    let mut stray = Vec::new();
    let mut named_somewhere = 0;
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        let ast = syn::parse_file(&text).unwrap();
        let mut namer = Namer {
            variants: &variants,
            named: Vec::new(),
        };
        namer.visit_file(&ast);
        if namer.named.is_empty() {
            continue;
        }
        named_somewhere += 1;
        let shown = file
            .strip_prefix(workspace())
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let allowed = listed
            .iter()
            .any(|p| shown == *p || (p.ends_with('/') && shown.starts_with(p.as_str())));
        if !allowed {
            stray.push(format!("{shown}: {}", namer.named.join(", ")));
        }
    }
    // The check sees the files that do name methods (the sampler choice).
    assert!(
        named_somewhere >= 2,
        "the check found no file naming a method"
    );
    assert!(
        stray.is_empty(),
        "files that name a campaign method outside its home (ask `Method::spec()` \
         instead, or list the file in docs/architecture.md, \"Adding a campaign method\"):\n  {}",
        stray.join("\n  ")
    );
}

/// The check itself: a `match` on methods in a function's body and inside
/// `matches!` is seen, a test's is not.
#[test]
fn the_method_check_sees_paths_and_macros_but_not_tests() {
    let variants: Vec<String> = ["Library", "Ndd", "Adaptive"].map(String::from).to_vec();
    let names = |code: &str| {
        let mut namer = Namer {
            variants: &variants,
            named: Vec::new(),
        };
        namer.visit_file(&syn::parse_file(code).unwrap());
        namer.named
    };
    assert_eq!(
        names("fn f(m: Method) -> bool { m == tslg_api::Method::Adaptive }"),
        ["Adaptive"]
    );
    assert_eq!(
        names("fn f(m: Method) -> bool { matches!(m, Method::Library | Method::Ndd) }"),
        ["Library", "Ndd"]
    );
    assert!(names("fn f(m: Method) -> bool { m.in_stages() }").is_empty());
    assert!(names("#[cfg(test)]\nmod tests { fn t() { let _ = Method::Ndd; } }").is_empty());
    assert!(names("fn f() { let _ = SearchMethod::Library; }").is_empty());
    assert_eq!(
        names("use tslg_api::Method::{Adaptive, Ndd as N};"),
        ["Ndd", "Adaptive"]
    );
    assert_eq!(names("use tslg_api::Method::*;").len(), 3);
}

/// The dashboard's scripts compare no campaign's method to a name: they
/// read the view's `method_facts` and `adaptive` stages, so a new method
/// shows as what its spec says.
#[test]
fn the_dashboard_asks_a_campaign_s_facts_not_its_method_s_name() {
    let assets = workspace().join("server/assets");
    let mut found = Vec::new();
    for entry in std::fs::read_dir(&assets).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        for (k, line) in text.lines().enumerate() {
            let compact: String = line.split_whitespace().collect();
            if ["method===", "method!==", "method==", "method!="]
                .iter()
                .any(|op| compact.contains(op))
            {
                found.push(format!("{}:{}: {}", path.display(), k + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "method names compared in the dashboard:\n  {}",
        found.join("\n  ")
    );
}
