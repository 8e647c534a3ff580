//! The file-level import graph of a crate, read from its source with `syn`,
//! and its cycles (strongly connected components of more than one file).
//!
//! Why: the layering in docs/architecture.md ("arrows point down only; no two
//! files import each other") is only true while something checks it. A file
//! `A` depends on a file `B` when a path in `A` (a `use`, a path in code or a
//! type, or a `crate::…`/`super::…` path inside a macro's tokens) names `B`'s
//! module or an item in it. `mod b;` declarations are not edges: a parent
//! owning a child is the tree, not an import. A path is resolved to the
//! file that defines the item it names, following `use` re-exports: if
//! `store/mod.rs` says `pub use fold::fold;`, then `crate::store::fold` in
//! another file points at `store/fold.rs`, while `crate::store::Store`
//! points at `store/mod.rs`, which defines it. A module re-exporting its
//! own descendants (`pub use fold::fold;` in `store/mod.rs`) is, like `mod`,
//! the shape of the tree and not an import; a private `use` of a child is.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// One crate's files and the imports between them.
pub struct ModuleGraph {
    /// Each file of the crate, relative to the crate's directory.
    pub files: Vec<PathBuf>,
    /// `(from, to)`: the file `from` names something in the file `to`.
    pub edges: BTreeSet<(usize, usize)>,
    /// For each edge, the paths that make it (as written, `::`-joined).
    pub because: BTreeMap<(usize, usize), BTreeSet<String>>,
    /// For each file, the other crates it names (`axum`, `rusqlite`…):
    /// the first segment of a path that is no module of this crate.
    pub crates: Vec<BTreeSet<String>>,
    /// For each file, its string literals that read as SQL statements
    /// (they begin with `SELECT`, `INSERT`, `UPDATE` or `DELETE FROM`),
    /// outside `#[cfg(test)]` items.
    pub sql: Vec<Vec<String>>,
}

/// A module: the file that holds it (inline modules share their file) and
/// the names it has, to follow re-exports.
#[derive(Default)]
struct Module {
    file: usize,
    /// The items it defines (functions, types, constants, traits, macros).
    defined: BTreeSet<String>,
    /// The names it imports, as absolute paths (`use a::b as c` → `c`).
    imported: BTreeMap<String, Vec<String>>,
    /// The modules it imports every name of (`use a::*`).
    globs: Vec<Vec<String>>,
}

impl ModuleGraph {
    /// Reads the crate whose root file is `root` (e.g. `server/src/lib.rs`);
    /// paths are shown relative to `base`.
    pub fn read(base: &Path, root: &Path) -> Result<Self, String> {
        let mut reader = TreeReader {
            base: base.to_path_buf(),
            files: Vec::new(),
            asts: Vec::new(),
            modules: BTreeMap::new(),
            scopes: Vec::new(),
            uses: Vec::new(),
            tests: Vec::new(),
        };
        reader.read_file(root, Vec::new(), true, false)?;
        let mut names = Names {
            modules: reader.modules,
        };
        for (module, item) in &reader.uses {
            names.import(module, item);
        }
        let mut because = BTreeMap::new();
        let mut crates = vec![BTreeSet::new(); reader.files.len()];
        let mut sql = vec![Vec::new(); reader.files.len()];
        for (file, ast) in reader.asts.iter().enumerate() {
            let mut visitor = PathCollector {
                names: &names,
                file,
                module: reader.scopes[file].clone(),
                because: &mut because,
                crates: &mut crates[file],
                sql: &mut sql[file],
            };
            visitor.visit_file(ast);
            if reader.tests[file] {
                // Test code may name anything; only its imports of this
                // crate count (a cycle through a test is a cycle).
                crates[file].clear();
                sql[file].clear();
            }
        }
        Ok(Self {
            files: reader.files,
            edges: because.keys().copied().collect(),
            because,
            crates,
            sql,
        })
    }

    /// The cycles: every strongly connected component of two or more files,
    /// each as its files' paths (sorted), in a stable order.
    pub fn cycles(&self) -> Vec<Vec<PathBuf>> {
        let n = self.files.len();
        let mut adjacency = vec![Vec::new(); n];
        for &(from, to) in &self.edges {
            adjacency[from].push(to);
        }
        let mut components: Vec<Vec<PathBuf>> = strongly_connected(&adjacency)
            .into_iter()
            .filter(|component| component.len() > 1)
            .map(|component| {
                let mut paths: Vec<PathBuf> =
                    component.iter().map(|&i| self.files[i].clone()).collect();
                paths.sort();
                paths
            })
            .collect();
        components.sort();
        components
    }

    /// The files `file` imports from, each with the paths that make the
    /// edge, for a message.
    pub fn imports_of(&self, file: &Path) -> Vec<(&Path, Vec<&str>)> {
        let Some(from) = self.files.iter().position(|f| f == file) else {
            return Vec::new();
        };
        self.because
            .range((from, 0)..(from + 1, 0))
            .map(|(&(_, to), paths)| {
                let paths = paths.iter().map(String::as_str).collect();
                (self.files[to].as_path(), paths)
            })
            .collect()
    }
}

/// Tarjan's algorithm, iterative over an explicit stack.
fn strongly_connected(adjacency: &[Vec<usize>]) -> Vec<Vec<usize>> {
    let n = adjacency.len();
    let mut index = vec![usize::MAX; n];
    let mut low = vec![0; n];
    let mut on_stack = vec![false; n];
    let mut stack = Vec::new();
    let mut components = Vec::new();
    let mut next = 0;
    for start in 0..n {
        if index[start] != usize::MAX {
            continue;
        }
        // (node, position in its adjacency list)
        let mut call = vec![(start, 0usize)];
        index[start] = next;
        low[start] = next;
        next += 1;
        stack.push(start);
        on_stack[start] = true;
        while let Some(&mut (node, ref mut position)) = call.last_mut() {
            if let Some(&child) = adjacency[node].get(*position) {
                *position += 1;
                if index[child] == usize::MAX {
                    index[child] = next;
                    low[child] = next;
                    next += 1;
                    stack.push(child);
                    on_stack[child] = true;
                    call.push((child, 0));
                } else if on_stack[child] {
                    low[node] = low[node].min(index[child]);
                }
            } else {
                call.pop();
                if let Some(&(parent, _)) = call.last() {
                    low[parent] = low[parent].min(low[node]);
                }
                if low[node] == index[node] {
                    let mut component = Vec::new();
                    loop {
                        let member = stack.pop().expect("the node is on the stack");
                        on_stack[member] = false;
                        component.push(member);
                        if member == node {
                            break;
                        }
                    }
                    components.push(component);
                }
            }
        }
    }
    components
}

/// Walks the module tree from the crate root, file by file.
struct TreeReader {
    base: PathBuf,
    files: Vec<PathBuf>,
    asts: Vec<syn::File>,
    /// Every module's path (`["store", "fold"]`) and what it holds.
    modules: BTreeMap<Vec<String>, Module>,
    /// Each file's own module path.
    scopes: Vec<Vec<String>>,
    /// Every `use` item with the module it is written in.
    uses: Vec<(Vec<String>, syn::ItemUse)>,
    /// Whether each file is test code (declared `#[cfg(test)] mod x;`, or
    /// under such a module).
    tests: Vec<bool>,
}

impl TreeReader {
    /// Reads `path` as the module `module`; `owns_directory` says whether its
    /// children live beside it (`lib.rs`, `main.rs`, `mod.rs`) or in a folder
    /// named after it.
    fn read_file(
        &mut self,
        path: &Path,
        module: Vec<String>,
        owns_directory: bool,
        test: bool,
    ) -> Result<(), String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let ast = syn::parse_file(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        let file = self.files.len();
        let shown = path.strip_prefix(&self.base).unwrap_or(path).to_path_buf();
        self.files.push(shown);
        self.scopes.push(module.clone());
        self.tests.push(test);
        let directory = if owns_directory {
            path.parent().expect("a file has a folder").to_path_buf()
        } else {
            path.with_extension("")
        };
        let items = ast.items.clone();
        self.asts.push(ast);
        self.read_items(&items, file, module, &directory)
    }

    /// Registers the module `module` in `file` with its items, and reads
    /// its child modules.
    fn read_items(
        &mut self,
        items: &[syn::Item],
        file: usize,
        module: Vec<String>,
        directory: &Path,
    ) -> Result<(), String> {
        let mut defined = BTreeSet::new();
        for item in items {
            if let Some(name) = defined_name(item) {
                defined.insert(name);
            }
            if let syn::Item::Use(used) = item {
                self.uses.push((module.clone(), used.clone()));
            }
        }
        self.modules.insert(
            module.clone(),
            Module {
                file,
                defined,
                ..Module::default()
            },
        );
        for item in items {
            let syn::Item::Mod(declared) = item else {
                continue;
            };
            let name = declared.ident.to_string();
            let mut child = module.clone();
            child.push(name.clone());
            match &declared.content {
                Some((_, inner)) => {
                    self.read_items(inner, file, child, &directory.join(&name))?;
                }
                None => {
                    let flat = directory.join(format!("{name}.rs"));
                    let nested = directory.join(&name).join("mod.rs");
                    let test = self.tests[file] || is_test(&declared.attrs);
                    if flat.exists() {
                        self.read_file(&flat, child, false, test)?;
                    } else if nested.exists() {
                        self.read_file(&nested, child, true, test)?;
                    } else {
                        return Err(format!(
                            "module {name} of {} has no file",
                            self.files[file].display()
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// The name an item defines in its module, if any (`impl` blocks and `use`
/// define none; modules are in the tree).
fn defined_name(item: &syn::Item) -> Option<String> {
    let ident = match item {
        syn::Item::Const(i) => &i.ident,
        syn::Item::Enum(i) => &i.ident,
        syn::Item::Fn(i) => &i.sig.ident,
        syn::Item::Static(i) => &i.ident,
        syn::Item::Struct(i) => &i.ident,
        syn::Item::Trait(i) => &i.ident,
        syn::Item::TraitAlias(i) => &i.ident,
        syn::Item::Type(i) => &i.ident,
        syn::Item::Union(i) => &i.ident,
        syn::Item::Macro(i) => i.ident.as_ref()?,
        _ => return None,
    };
    Some(ident.to_string())
}

/// Leaf paths of a `use` tree: (the name it binds, the path, is a glob).
fn use_leaves(prefix: &mut Vec<String>, tree: &syn::UseTree, out: &mut Vec<UseLeaf>) {
    match tree {
        syn::UseTree::Path(path) => {
            prefix.push(path.ident.to_string());
            use_leaves(prefix, &path.tree, out);
            prefix.pop();
        }
        syn::UseTree::Name(name) => {
            let name = name.ident.to_string();
            if name == "self" {
                let bound = prefix.last().cloned().unwrap_or_default();
                out.push(UseLeaf::Name(bound, prefix.clone()));
            } else {
                let mut path = prefix.clone();
                path.push(name.clone());
                out.push(UseLeaf::Name(name, path));
            }
        }
        syn::UseTree::Rename(rename) => {
            let mut path = prefix.clone();
            path.push(rename.ident.to_string());
            out.push(UseLeaf::Name(rename.rename.to_string(), path));
        }
        syn::UseTree::Glob(_) => out.push(UseLeaf::Glob(prefix.clone())),
        syn::UseTree::Group(group) => {
            for tree in &group.items {
                use_leaves(prefix, tree, out);
            }
        }
    }
}

/// One path a `use` item brings in.
enum UseLeaf {
    /// `use a::b;` binds `b` to `a::b` (or the `as` name).
    Name(String, Vec<String>),
    /// `use a::*;`
    Glob(Vec<String>),
}

/// The crate's modules and names: resolves a path written in a module to
/// the file that defines what it names.
struct Names {
    modules: BTreeMap<Vec<String>, Module>,
}

/// How deep re-exports are followed (a cycle of re-exports stops here).
const MAX_REEXPORT_DEPTH: usize = 32;

impl Names {
    /// Records the names a `use` item written in `module` binds there.
    fn import(&mut self, module: &[String], item: &syn::ItemUse) {
        let mut leaves = Vec::new();
        use_leaves(&mut Vec::new(), &item.tree, &mut leaves);
        for leaf in leaves {
            match leaf {
                UseLeaf::Name(name, path) => {
                    if let Some(absolute) = self.absolute(module, &path) {
                        if let Some(m) = self.modules.get_mut(module) {
                            m.imported.insert(name, absolute);
                        }
                    }
                }
                UseLeaf::Glob(path) => {
                    if let Some(absolute) = self.absolute(module, &path) {
                        if let Some(m) = self.modules.get_mut(module) {
                            m.globs.push(absolute);
                        }
                    }
                }
            }
        }
    }

    /// The absolute path of `segments` written in `module`, or `None` when
    /// it starts outside the crate (another crate, a prelude name, a local
    /// item or variable).
    fn absolute(&self, module: &[String], segments: &[String]) -> Option<Vec<String>> {
        let first = segments.first()?;
        let (mut absolute, mut rest): (Vec<String>, &[String]) = match first.as_str() {
            "crate" | "$crate" => (Vec::new(), &segments[1..]),
            "self" => (module.to_vec(), &segments[1..]),
            "super" => (module.to_vec(), segments),
            _ => {
                let mut child = module.to_vec();
                child.push(first.clone());
                if self.modules.contains_key(&child) {
                    (module.to_vec(), segments)
                } else if let Some(imported) =
                    self.modules.get(module).and_then(|m| m.imported.get(first))
                {
                    (imported.clone(), &segments[1..])
                } else {
                    return None;
                }
            }
        };
        while rest.first().is_some_and(|s| s == "super") {
            absolute.pop();
            rest = &rest[1..];
        }
        absolute.extend(rest.iter().cloned());
        Some(absolute)
    }

    /// The file that defines what the absolute path names: the deepest
    /// module on it, or, where the next name is a re-export there, the file
    /// it comes from.
    fn file_of(&self, absolute: &[String], depth: usize) -> Option<usize> {
        let mut module: Vec<String> = Vec::new();
        let mut file = self.modules.get(&module)?.file;
        for (i, segment) in absolute.iter().enumerate() {
            let mut child = module.clone();
            child.push(segment.clone());
            if let Some(found) = self.modules.get(&child) {
                module = child;
                file = found.file;
                continue;
            }
            if depth >= MAX_REEXPORT_DEPTH {
                return Some(file);
            }
            let here = &self.modules[&module];
            if here.defined.contains(segment) {
                return Some(file);
            }
            if let Some(target) = here.imported.get(segment) {
                let mut through: Vec<String> = target.clone();
                through.extend(absolute[i + 1..].iter().cloned());
                return self.file_of(&through, depth + 1).or(Some(file));
            }
            for glob in &here.globs {
                let Some(source) = self.modules.get(glob) else {
                    continue;
                };
                let mut child = glob.clone();
                child.push(segment.clone());
                if source.defined.contains(segment)
                    || source.imported.contains_key(segment)
                    || self.modules.contains_key(&child)
                {
                    let mut through = glob.clone();
                    through.extend(absolute[i..].iter().cloned());
                    return self.file_of(&through, depth + 1).or(Some(file));
                }
            }
            return Some(file);
        }
        Some(file)
    }
}

/// Collects the edges of one file: every path it names, resolved against
/// the module it is written in.
struct PathCollector<'a> {
    names: &'a Names,
    file: usize,
    /// The module the visitor is in (inline modules push onto it).
    module: Vec<String>,
    because: &'a mut BTreeMap<(usize, usize), BTreeSet<String>>,
    crates: &'a mut BTreeSet<String>,
    sql: &'a mut Vec<String>,
}

impl PathCollector<'_> {
    /// Resolves a path given as its segments' names and records the edge
    /// (or the other crate it names).
    fn record(&mut self, segments: &[String]) {
        let Some(absolute) = self.names.absolute(&self.module, segments) else {
            if segments.len() > 1 {
                if let Some(first) = segments.first() {
                    self.crates
                        .insert(first.trim_start_matches("::").to_owned());
                }
            }
            return;
        };
        if let Some(target) = self.names.file_of(&absolute, 0) {
            if target != self.file {
                self.because
                    .entry((self.file, target))
                    .or_default()
                    .insert(segments.join("::"));
            }
        }
    }

    /// Paths inside a macro's tokens (`format!`, `json!`, `matches!`…),
    /// which `syn` leaves unparsed: every `crate`/`self`/`super` run of
    /// `ident :: ident …`.
    fn tokens(&mut self, tokens: proc_macro2::TokenStream) {
        use proc_macro2::TokenTree;
        let trees: Vec<TokenTree> = tokens.into_iter().collect();
        let mut i = 0;
        while i < trees.len() {
            match &trees[i] {
                TokenTree::Group(group) => {
                    self.tokens(group.stream());
                    i += 1;
                }
                TokenTree::Literal(literal) => {
                    if let Ok(text) = syn::parse_str::<syn::LitStr>(&literal.to_string()) {
                        self.visit_lit_str(&text);
                    }
                    i += 1;
                }
                TokenTree::Ident(ident)
                    if matches!(ident.to_string().as_str(), "crate" | "self" | "super") =>
                {
                    let mut segments = vec![ident.to_string()];
                    let mut j = i + 1;
                    while let (
                        Some(TokenTree::Punct(a)),
                        Some(TokenTree::Punct(b)),
                        Some(TokenTree::Ident(next)),
                    ) = (trees.get(j), trees.get(j + 1), trees.get(j + 2))
                    {
                        if a.as_char() != ':' || b.as_char() != ':' {
                            break;
                        }
                        segments.push(next.to_string());
                        j += 3;
                    }
                    if segments.len() > 1 {
                        self.record(&segments);
                    }
                    i = j.max(i + 1);
                }
                _ => i += 1,
            }
        }
    }
}

/// Whether `attrs` hold `#[cfg(test)]`.
fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.parse_args::<syn::Meta>()
                .is_ok_and(|m| m.path().is_ident("test"))
    })
}

impl<'ast> Visit<'ast> for PathCollector<'_> {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        let attrs: &[syn::Attribute] = match item {
            syn::Item::Mod(i) => &i.attrs,
            syn::Item::Fn(i) => &i.attrs,
            syn::Item::Impl(i) => &i.attrs,
            syn::Item::Const(i) => &i.attrs,
            syn::Item::Use(i) => &i.attrs,
            _ => &[],
        };
        if is_test(attrs) {
            // Test code may name anything; only its imports of this crate
            // count (a cycle through a test is a cycle).
            let (sql, crates) = (std::mem::take(self.sql), std::mem::take(self.crates));
            syn::visit::visit_item(self, item);
            (*self.sql, *self.crates) = (sql, crates);
            return;
        }
        syn::visit::visit_item(self, item);
    }

    fn visit_lit_str(&mut self, lit: &'ast syn::LitStr) {
        let text = lit.value();
        let start = text.trim_start();
        if ["SELECT ", "INSERT ", "UPDATE ", "DELETE FROM "]
            .iter()
            .any(|k| start.starts_with(k))
        {
            self.sql.push(text);
        }
    }

    fn visit_item_mod(&mut self, item: &'ast syn::ItemMod) {
        if let Some((_, items)) = &item.content {
            self.module.push(item.ident.to_string());
            for inner in items {
                self.visit_item(inner);
            }
            self.module.pop();
        }
    }

    fn visit_item_use(&mut self, item: &'ast syn::ItemUse) {
        let reexport = !matches!(item.vis, syn::Visibility::Inherited);
        let mut leaves = Vec::new();
        use_leaves(&mut Vec::new(), &item.tree, &mut leaves);
        for leaf in leaves {
            let path = match leaf {
                UseLeaf::Name(_, path) | UseLeaf::Glob(path) => path,
            };
            if reexport {
                // A module's surface: re-exporting its own descendants.
                if let Some(absolute) = self.names.absolute(&self.module, &path) {
                    if absolute.len() > self.module.len() && absolute.starts_with(&self.module) {
                        continue;
                    }
                }
            }
            self.record(&path);
        }
    }

    fn visit_path(&mut self, path: &'ast syn::Path) {
        let segments: Vec<String> = path.segments.iter().map(|s| s.ident.to_string()).collect();
        // A lone name in code is a variable, a function or an item: it names
        // another file only through an import (a re-exported child's item
        // used by its parent), never as a module.
        let imported = segments.len() == 1
            && self
                .names
                .modules
                .get(&self.module)
                .is_some_and(|m| m.imported.contains_key(&segments[0]));
        if segments.len() > 1 || imported {
            self.record(&segments);
        }
        syn::visit::visit_path(self, path);
    }

    /// `pub(crate)`, `pub(super)`: visibility, not an import.
    fn visit_visibility(&mut self, _: &'ast syn::Visibility) {}

    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        self.visit_path(&mac.path);
        self.tokens(mac.tokens.clone());
    }
}

/// The crates of this workspace: their directory and root files (a library
/// and each binary target are separate module trees).
pub fn workspace_roots(workspace: &Path) -> Vec<PathBuf> {
    let mut roots = Vec::new();
    for crate_dir in [
        "", "api", "client", "figures", "method", "server", "testkit", "worker",
    ] {
        let dir = workspace.join(crate_dir);
        for root in ["src/lib.rs", "src/main.rs"] {
            let file = dir.join(root);
            if file.exists() {
                roots.push(file);
            }
        }
        if let Ok(entries) = std::fs::read_dir(dir.join("src/bin")) {
            let mut bins: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "rs"))
                .collect();
            bins.sort();
            roots.extend(bins);
        }
    }
    for tests in ["tests/it/main.rs", "method/tests/it/main.rs"] {
        let file = workspace.join(tests);
        if file.exists() {
            roots.push(file);
        }
    }
    roots
}
