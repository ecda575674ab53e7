//! The file-level import graph of a crate and the circles in it, for tidy's rule that no
//! source file imports, through any chain of files, itself.
//!
//! A crate's files are found as the compiler finds them: from its root file along its
//! `mod NAME;` declarations (`NAME.rs` or `NAME/mod.rs` beside a root or `mod.rs` file,
//! under `STEM/` beside any other file, or where a `#[path = "…"]` attribute says). File A
//! imports file B when A's code names a path that resolves to B: the path starts with
//! `crate`, `super` or `self`, with a module A declares (`mod child;` then `child::X`), or
//! with a module A brought into scope by a `use` (`use crate::maps;` then `maps::X`), and
//! its longest prefix that is a file module is B's. Paths in `use` declarations count like
//! any other, `pub use` re-exports too, and braces expand (`crate::{a::X, b::{self, Y}}`
//! names `a` and `b`). Declaring a module (`mod child;`) is not importing it. An inline
//! module (`mod defaults { … }`) is part of its file: paths inside it are read as the file's.
//! Which lines are code (no comments, no unit-test tail) is the caller's to say.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

/// The files of the crate rooted at `root` and, for each, the files it imports. `code_of`
/// turns a file's text into its code.
pub fn file_graph(
    root: &Path,
    code_of: &dyn Fn(&str) -> String,
) -> BTreeMap<PathBuf, BTreeSet<PathBuf>> {
    let modules = module_tree(root, code_of);
    modules
        .values()
        .map(|module| {
            let imports = module
                .paths
                .iter()
                .filter_map(|p| resolve(module, p, &modules))
                .map(|m| m.file.clone())
                .filter(|f| *f != module.file)
                .collect();
            (module.file.clone(), imports)
        })
        .collect()
}

/// The circles of `graph`: for every import that lies on one, the shortest circle through
/// it, each written `a.rs -> b.rs -> a.rs` with paths relative to `base`, starting from its
/// smallest file.
pub fn circles(graph: &BTreeMap<PathBuf, BTreeSet<PathBuf>>, base: &Path) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for (from, imports) in graph {
        for to in imports {
            if let Some(back) = shortest_path(graph, to, from) {
                let mut names: Vec<String> = std::iter::once(from)
                    .chain(back.iter().take(back.len() - 1).copied())
                    .map(|f| f.strip_prefix(base).unwrap_or(f).display().to_string())
                    .collect();
                let start = (0..names.len())
                    .min_by_key(|&i| &names[i])
                    .unwrap_or_default();
                names.rotate_left(start);
                names.push(names[0].clone());
                found.insert(names.join(" -> "));
            }
        }
    }
    found
}

/// The files from `from` to `to` along imports, both ends included, fewest first.
fn shortest_path<'g>(
    graph: &'g BTreeMap<PathBuf, BTreeSet<PathBuf>>,
    from: &'g PathBuf,
    to: &PathBuf,
) -> Option<Vec<&'g PathBuf>> {
    let mut came_from: BTreeMap<&PathBuf, &PathBuf> = BTreeMap::new();
    let mut queue = VecDeque::from([from]);
    let mut seen = BTreeSet::from([from]);
    while let Some(at) = queue.pop_front() {
        if at == to {
            let mut path = vec![at];
            let mut step = at;
            while let Some(prev) = came_from.get(step) {
                path.push(prev);
                step = prev;
            }
            path.reverse();
            return Some(path);
        }
        for next in graph.get(at).into_iter().flatten() {
            if seen.insert(next) {
                came_from.insert(next, at);
                queue.push_back(next);
            }
        }
    }
    None
}

/// One file module: where it sits in the crate, its file, the modules it declares and the
/// paths its code names (each split into segments, braces expanded).
struct Module {
    path: Vec<String>,
    file: PathBuf,
    children: BTreeSet<String>,
    paths: Vec<Vec<String>>,
}

/// The file modules of the crate rooted at `root`, by module path (the root's is empty).
fn module_tree(root: &Path, code_of: &dyn Fn(&str) -> String) -> BTreeMap<Vec<String>, Module> {
    let mut modules = BTreeMap::new();
    // A file module's children sit in its own directory for roots, `mod.rs` files and files
    // loaded by `#[path]`, and under its stem for the others.
    let mut todo = vec![(Vec::new(), root.to_path_buf(), true)];
    while let Some((path, file, mod_rs)) = todo.pop() {
        let Ok(text) = std::fs::read_to_string(&file) else {
            continue;
        };
        let code = code_of(&text);
        let dir = file.parent().unwrap_or(Path::new("")).to_path_buf();
        let children_dir = match (mod_rs, file.file_stem().and_then(|s| s.to_str())) {
            (false, Some(stem)) => dir.join(stem),
            _ => dir.clone(),
        };
        let mut children = BTreeSet::new();
        for (name, attribute) in declared_modules(&code) {
            let mut child_path = path.clone();
            child_path.push(name.clone());
            let (child, child_mod_rs) = match attribute {
                Some(p) => (dir.join(p), true),
                None => {
                    let flat = children_dir.join(format!("{name}.rs"));
                    if flat.exists() {
                        (flat, false)
                    } else {
                        (children_dir.join(&name).join("mod.rs"), true)
                    }
                }
            };
            children.insert(name);
            todo.push((child_path, child, child_mod_rs));
        }
        let paths = named_paths(&code);
        modules.insert(
            path.clone(),
            Module {
                path,
                file,
                children,
                paths,
            },
        );
    }
    modules
}

/// The `mod NAME;` declarations in `code`, each with its `#[path = "…"]` if it has one.
fn declared_modules(code: &str) -> Vec<(String, Option<String>)> {
    let mut out = Vec::new();
    let mut attribute = None;
    for line in code.lines().map(str::trim) {
        if let Some(p) = line
            .strip_prefix("#[path = \"")
            .and_then(|rest| rest.strip_suffix("\"]"))
        {
            attribute = Some(p.to_string());
            continue;
        }
        let mut rest = line;
        if let Some(r) = rest.strip_prefix("pub") {
            rest = r.trim_start();
            if rest.starts_with('(') {
                rest = rest.split_once(')').map_or("", |(_, r)| r.trim_start());
            }
        }
        if let Some(name) = rest
            .strip_prefix("mod ")
            .and_then(|r| r.trim().strip_suffix(';'))
        {
            out.push((name.trim().to_string(), attribute.take()));
        } else if !line.starts_with("#[") {
            attribute = None;
        }
    }
    out
}

/// Every path in `code` of two segments or more (`a::b`, `a::{b, c::d}` → `a::b`, `a::c::d`),
/// split into its segments; `self` inside braces names the path before them, and a glob or
/// a generic argument ends a path. A path that follows `as` is its alias's, as
/// `[…, "as", ALIAS]`.
fn named_paths(code: &str) -> Vec<Vec<String>> {
    let chars: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut at = 0;
    while at < chars.len() {
        let c = chars[at];
        let starts = is_ident_start(c)
            && (at == 0 || !(is_ident(chars[at - 1]) || chars[at - 1] == ':'))
            && !(at > 0 && chars[at - 1] == '\'');
        if starts {
            let before = at;
            let mut prefix = Vec::new();
            at = path_tree(&chars, at, &mut prefix, &mut out);
            if at == before {
                at += 1;
            }
        } else {
            at += 1;
        }
    }
    out.retain(|p| p.iter().take_while(|s| *s != "as").count() >= 2);
    out
}

/// Reads one use tree at `at` (segments, then a brace group, a glob or nothing) below
/// `prefix`, pushing every path it ends in to `out`; returns where it stopped.
fn path_tree(
    chars: &[char],
    mut at: usize,
    prefix: &mut Vec<String>,
    out: &mut Vec<Vec<String>>,
) -> usize {
    let depth = prefix.len();
    loop {
        at = skip_space(chars, at);
        if at < chars.len() && chars[at] == '{' {
            at += 1;
            loop {
                at = skip_space(chars, at);
                match chars.get(at) {
                    None => break,
                    Some('}') => {
                        at += 1;
                        break;
                    }
                    Some(',') => at += 1,
                    Some(_) => {
                        let before = at;
                        at = path_tree(chars, at, prefix, out);
                        if at == before {
                            at += 1;
                        }
                    }
                }
            }
            prefix.truncate(depth);
            return at;
        }
        let start = at;
        while at < chars.len() && is_ident(chars[at]) {
            at += 1;
        }
        if at == start || !is_ident_start(chars[start]) {
            break;
        }
        let segment: String = chars[start..at].iter().collect();
        if segment != "self" || prefix.len() == depth && depth == 0 {
            prefix.push(segment);
        }
        if chars.get(at) == Some(&':') && chars.get(at + 1) == Some(&':') {
            at += 2;
            if chars.get(at).is_some_and(|c| *c == '*' || *c == '<') {
                break;
            }
            continue;
        }
        break;
    }
    let mut path = prefix.clone();
    let after = skip_space(chars, at);
    if chars[after.min(chars.len())..].starts_with(&['a', 's', ' ']) {
        let start = skip_space(chars, after + 2);
        let mut end = start;
        while end < chars.len() && is_ident(chars[end]) {
            end += 1;
        }
        path.push("as".to_string());
        path.push(chars[start..end].iter().collect());
        at = end;
    }
    if prefix.len() > depth || depth > 0 {
        out.push(path);
    }
    prefix.truncate(depth);
    at
}

fn skip_space(chars: &[char], mut at: usize) -> usize {
    while at < chars.len() && chars[at].is_whitespace() {
        at += 1;
    }
    at
}

fn is_ident_start(c: char) -> bool {
    c.is_alphabetic() || c == '_'
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The file module a path named in `from` resolves to, if it is one of the crate's: the
/// longest prefix of the path that is a file module.
fn resolve<'m>(
    from: &Module,
    path: &[String],
    modules: &'m BTreeMap<Vec<String>, Module>,
) -> Option<&'m Module> {
    let segments: Vec<&String> = path.iter().take_while(|s| *s != "as").collect();
    let (mut full, rest) = start_of(from, &segments, modules)?;
    full.extend(rest.iter().map(|s| s.to_string()));
    (0..=full.len()).rev().find_map(|n| modules.get(&full[..n]))
}

/// The module a path's first segments name, and the segments after them.
fn start_of<'p>(
    from: &Module,
    segments: &'p [&'p String],
    modules: &BTreeMap<Vec<String>, Module>,
) -> Option<(Vec<String>, &'p [&'p String])> {
    let first = segments.first()?.as_str();
    match first {
        "crate" => Some((Vec::new(), &segments[1..])),
        "self" => Some((from.path.clone(), &segments[1..])),
        "super" => {
            let mut base = from.path.clone();
            let mut n = 0;
            while segments.get(n).is_some_and(|s| *s == "super") {
                base.pop()?;
                n += 1;
            }
            Some((base, &segments[n..]))
        }
        name if from.children.contains(name) => {
            let mut base = from.path.clone();
            base.push(name.to_string());
            Some((base, &segments[1..]))
        }
        name => {
            // A module the file brought into scope with a `use` whose path starts from
            // `crate`, `self`, `super` or a child (not from another `use`'s module).
            let used = from.paths.iter().find_map(|p| {
                let head = p.first()?.as_str();
                if !(matches!(head, "crate" | "self" | "super") || from.children.contains(head)) {
                    return None;
                }
                let alias = match p.iter().position(|s| s == "as") {
                    Some(i) => p.get(i + 1)?,
                    None => p.last()?,
                };
                if alias != name {
                    return None;
                }
                let target = resolve(from, p, modules)?;
                let named = p.iter().take_while(|s| *s != "as").count();
                // Only a path that names the module itself (its last segment is the module's).
                (target.path.last().map(String::as_str) == p[..named].last().map(String::as_str)
                    && !target.path.is_empty())
                .then(|| target.path.clone())
            })?;
            Some((used, &segments[1..]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A crate of five files on disk: `a` and `b` import each other through a braced `use`
    /// and a `pub use`; `c` declares `d`, which reaches back with `super`; `c` names `d`'s
    /// item through the child module; `e` only names `a` through a module it `use`d.
    #[test]
    fn the_graph_finds_the_circles_of_a_tiny_crate() {
        let dir =
            std::env::temp_dir().join(format!("lasertag-tidy-imports-{}", std::process::id()));
        let files = [
            ("lib.rs", "mod a;\nmod b;\nmod c;\nmod e;\n"),
            ("a.rs", "use crate::{b::{self, Y}, c};\npub struct X;\n"),
            ("b.rs", "pub use super::a::X as Z;\npub struct Y;\n"),
            (
                "c.rs",
                "mod d;\npub fn f() -> d::W { d::W }\npub struct V;\n",
            ),
            ("c/d.rs", "pub struct W(super::V);\n"),
            ("e.rs", "use crate::a;\nfn g() -> a::X { a::X }\n"),
        ];
        for (name, text) in files {
            let path = dir.join(name);
            std::fs::create_dir_all(path.parent().expect("a file has a directory"))
                .expect("temp dir");
            std::fs::write(&path, text).expect("temp file");
        }
        let graph = file_graph(&dir.join("lib.rs"), &|t| t.to_string());
        let e = graph.get(&dir.join("e.rs")).expect("e.rs is in the crate");
        let found = circles(&graph, &dir);
        std::fs::remove_dir_all(&dir).expect("temp dir removed");
        assert_eq!(
            found.into_iter().collect::<Vec<_>>(),
            ["a.rs -> b.rs -> a.rs", "c.rs -> c/d.rs -> c.rs"]
        );
        assert_eq!(e.iter().collect::<Vec<_>>(), [&dir.join("a.rs")]);
    }

    #[test]
    fn braces_globs_aliases_and_generics_split_into_paths() {
        let paths = named_paths(
            "use crate::{a::{self, B as C}, d::*};\nlet x = super::e::f::<crate::G>(y as u8);",
        );
        let expect: Vec<Vec<&str>> = vec![
            vec!["crate", "a"],
            vec!["crate", "a", "B", "as", "C"],
            vec!["crate", "d"],
            vec!["super", "e", "f"],
            vec!["crate", "G"],
        ];
        assert_eq!(paths, expect);
    }
}
