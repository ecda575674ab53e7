//! Tidy: the rules of the house that the compiler does not check, checked on every test run
//! (rust-analyzer's `tidy.rs` is the model). Formatting, the floors between and inside the
//! crates, what the core may depend on, module docs, file sizes and no project history in
//! the code, and no import circles between files. Clippy runs in `tests/run.sh`, beside this
//! test: run from inside `cargo test`, it would wait on the build directory that `cargo test`
//! holds. Long file: every house rule in one place, each a test with its tables beside it.

#[path = "tidy/imports.rs"]
mod imports;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The core's modules from the ground floor up: each may import only those before it.
const CORE_FLOORS: &[&str] = &[
    "checkpoint",
    "settings",
    "sim",
    "nav",
    "localise",
    "tracker",
    "radio",
    "planner",
    "bots",
    "world",
    "difficulty",
    "env",
];

/// Inside the core's `sim`: `mod.rs` (poses, physics, constants) is the floor, then the
/// segment index, the arena (with the map format's rules), and the rest stand on the arena.
const SIM_FLOORS: &[&str] = &[
    "mod",
    "segments",
    "arena",
    "map_rules",
    "motion",
    "sensors",
    "views",
    "rules",
    "still",
];

/// The server library's modules from the ground floor up.
const SERVER_FLOORS: &[&str] = &[
    "config", "access", "names", "metrics", "schema", "maps", "store", "game", "protocol", "fleet",
    "agones", "service", "http", "process",
];

/// The only crates the core may depend on: geometry, seeded randomness and typed errors.
const CORE_DEPENDENCIES: &[&str] = &[
    "nalgebra",
    "parry2d",
    "rand",
    "rand_chacha",
    "rand_distr",
    "thiserror",
];

/// Crates that must not appear anywhere in the core's dependency tree.
const CORE_FORBIDDEN_CRATES: &[&str] = &[
    "tokio",
    "serde",
    "serde_json",
    "axum",
    "hyper",
    "tracing",
    "plotters",
    "indicatif",
    "getrandom",
];

/// What the core's sources must not name: clocks, I/O, threads, tasks, serialisation.
const CORE_FORBIDDEN_WORDS: &[&str] = &[
    "tokio",
    "serde",
    "Instant",
    "SystemTime",
    "std::fs",
    "std::net",
    "std::thread",
    "std::io",
    "thread_rng",
    "from_entropy",
    "from_os_rng",
];

/// Lines a source file may have before it must say at its top why it is longer.
const LINE_BUDGET: usize = 600;

/// The marker, in a file's module doc, that says why it is over the budget.
const LONG_FILE_MARKER: &str = "Long file:";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file below `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                if p.file_name().is_some_and(|n| n != "target") {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The project's own Rust sources (the fuzz crate included, its build output not).
fn all_sources() -> Vec<PathBuf> {
    [
        "core", "policy", "server", "lab", "tests", "benches", "examples", "fuzz",
    ]
    .iter()
    .flat_map(|d| rust_files(&root().join(d)))
    .collect()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string()
}

/// The code of a source file without its comments (line comments only: the project writes
/// no block comments), so that a doc mentioning a module is not an import; and without its
/// unit tests (a `#[cfg(test)]` module closes every file that has one), which may build
/// whole matches to test a floor below the world.
fn code_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let end = text
        .lines()
        .position(|l| l.trim() == "#[cfg(test)]")
        .unwrap_or(usize::MAX);
    text.lines().take(end).enumerate().filter_map(|(i, l)| {
        let code = match l.find("//") {
            Some(at) => &l[..at],
            None => l,
        };
        (!code.trim().is_empty()).then_some((i + 1, code))
    })
}

/// The modules `prefix` names in `code` (`crate::sim::arena` with prefix `crate::` → `sim`).
fn named_modules(code: &str, prefix: &str) -> Vec<String> {
    code.match_indices(prefix)
        .filter(|(at, _)| {
            // `lasertag_core::` must not match inside a longer name.
            code[..*at]
                .chars()
                .next_back()
                .is_none_or(|c| !(c.is_alphanumeric() || c == '_'))
        })
        .map(|(at, _)| {
            code[at + prefix.len()..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect::<String>()
        })
        .filter(|m| !m.is_empty())
        .collect()
}

/// Checks that each file of a crate imports only modules on floors below its own; returns
/// one line per violation.
fn floor_violations(crate_dir: &Path, floors: &[&str]) -> Vec<String> {
    let rank = |m: &str| floors.iter().position(|f| *f == m);
    let mut bad = Vec::new();
    for file in rust_files(crate_dir) {
        let rel = file.strip_prefix(crate_dir).unwrap_or(&file);
        let Some(own) = rel
            .components()
            .next()
            .and_then(|c| c.as_os_str().to_str())
            .map(|s| s.trim_end_matches(".rs").to_string())
        else {
            continue;
        };
        if own == "lib" || own == "main" {
            continue;
        }
        let Some(own_rank) = rank(&own) else {
            bad.push(format!(
                "{}: module `{own}` is on no floor of tests/tidy.rs",
                relative(&file)
            ));
            continue;
        };
        for (line, code) in code_lines(&read(&file)) {
            for m in named_modules(code, "crate::") {
                match rank(&m) {
                    Some(r) if r > own_rank => bad.push(format!(
                        "{}:{line}: `{own}` imports `{m}`, a floor above it",
                        relative(&file)
                    )),
                    None => bad.push(format!(
                        "{}:{line}: `crate::{m}` is on no floor of tests/tidy.rs",
                        relative(&file)
                    )),
                    _ => {}
                }
            }
        }
    }
    bad
}

#[test]
fn the_code_is_formatted() {
    let out = Command::new(env!("CARGO"))
        .current_dir(root())
        .args(["fmt", "--all", "--", "--check"])
        .output()
        .expect("cargo fmt runs");
    assert!(
        out.status.success(),
        "cargo fmt --check: run `cargo fmt --all`\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn the_cores_modules_import_only_floors_below_their_own() {
    let bad = floor_violations(&root().join("core"), CORE_FLOORS);
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn the_sim_files_import_only_floors_below_their_own() {
    let sim = root().join("core/sim");
    let rank = |m: &str| SIM_FLOORS.iter().position(|f| *f == m);
    let mut bad = Vec::new();
    for file in rust_files(&sim) {
        let own = file
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        let Some(own_rank) = rank(&own) else {
            bad.push(format!("{}: not on SIM_FLOORS", relative(&file)));
            continue;
        };
        for (line, code) in code_lines(&read(&file)) {
            // `crate::sim::{Pose, …}` names mod.rs's items; `crate::sim::arena` a file.
            for m in named_modules(code, "crate::sim::") {
                let r = rank(&m).unwrap_or(0);
                if r > own_rank {
                    bad.push(format!(
                        "{}:{line}: `{own}` imports `sim::{m}`, a floor above it",
                        relative(&file)
                    ));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn the_servers_modules_import_only_floors_below_their_own() {
    let bad = floor_violations(&root().join("server"), SERVER_FLOORS);
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn only_the_binary_uses_the_lab() {
    let mut bad = Vec::new();
    for file in rust_files(&root().join("server")) {
        if file.ends_with("main.rs") {
            continue;
        }
        for (line, code) in code_lines(&read(&file)) {
            if code.contains("lasertag_lab") {
                bad.push(format!("{}:{line}", relative(&file)));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "the server library must not use the lab (plots stay out of it): {}",
        bad.join(", ")
    );
}

/// The core, and the policy runtime beside it (the match runs it on its tick).
#[test]
fn the_core_names_no_clock_io_task_or_serialisation() {
    let mut bad = Vec::new();
    let floors = [root().join("core"), root().join("policy")];
    for file in floors.iter().flat_map(|d| rust_files(d)) {
        for (line, code) in code_lines(&read(&file)) {
            for word in CORE_FORBIDDEN_WORDS {
                if code.contains(word) {
                    bad.push(format!("{}:{line}: `{word}`", relative(&file)));
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "the core must stay pure:\n{}",
        bad.join("\n")
    );
}

/// The core's manifest lists only the allowed crates, and its whole normal dependency tree
/// (what `cargo tree -p lasertag-core -e normal` prints) holds none of the forbidden ones.
#[test]
fn the_core_depends_only_on_maths_randomness_and_errors() {
    let manifest = read(&root().join("core/Cargo.toml"));
    let mut in_dependencies = false;
    let mut listed = BTreeSet::new();
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_dependencies = line == "[dependencies]";
        } else if in_dependencies && !line.is_empty() && !line.starts_with('#') {
            let name = line
                .split(['=', '.', ' '])
                .next()
                .unwrap_or_default()
                .to_string();
            listed.insert(name);
        }
    }
    let extra: Vec<_> = listed
        .iter()
        .filter(|d| !CORE_DEPENDENCIES.contains(&d.as_str()))
        .collect();
    assert!(extra.is_empty(), "core/Cargo.toml depends on {extra:?}");
    assert!(
        !manifest.contains("[build-dependencies]"),
        "the core has no build script"
    );

    let out = Command::new(env!("CARGO"))
        .current_dir(root())
        .args([
            "tree",
            "--offline",
            "-p",
            "lasertag-core",
            "-e",
            "normal",
            "--prefix",
            "none",
            "--format",
            "{p}",
        ])
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tree = String::from_utf8_lossy(&out.stdout);
    let crates: BTreeSet<&str> = tree
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert!(crates.contains("nalgebra"), "cargo tree printed: {tree}");
    let found: Vec<_> = CORE_FORBIDDEN_CRATES
        .iter()
        .filter(|c| crates.contains(**c))
        .collect();
    assert!(found.is_empty(), "the core's tree holds {found:?}");
}

#[test]
fn every_source_file_starts_with_a_module_doc() {
    let bad: Vec<_> = all_sources()
        .into_iter()
        .filter(|f| !read(f).starts_with("//!"))
        .map(|f| relative(&f))
        .collect();
    assert!(
        bad.is_empty(),
        "files without a `//!` doc at the top: {}",
        bad.join(", ")
    );
}

#[test]
fn no_source_file_is_over_its_line_budget_without_saying_why() {
    let mut bad = Vec::new();
    for file in all_sources() {
        let text = read(&file);
        let lines = text.lines().count();
        let says_why = text
            .lines()
            .take_while(|l| l.starts_with("//!"))
            .any(|l| l.contains(LONG_FILE_MARKER));
        if lines > LINE_BUDGET && !says_why {
            bad.push(format!("{} ({lines} lines)", relative(&file)));
        }
    }
    assert!(
        bad.is_empty(),
        "over {LINE_BUDGET} lines: split along the seams, or say why in the module doc \
         (`{LONG_FILE_MARKER} …`): {}",
        bad.join(", ")
    );
}

/// Code and docs say what is and why, not when or by which ticket.
#[test]
fn no_project_history_in_code_or_docs() {
    let mut files = all_sources();
    files.extend(rust_files(&root().join("web")));
    for dir in ["web", "docs"] {
        if let Ok(entries) = std::fs::read_dir(root().join(dir)) {
            files.extend(entries.flatten().map(|e| e.path()).filter(|p| {
                p.extension()
                    .is_some_and(|x| x == "js" || x == "md" || x == "html")
            }));
        }
    }
    files.extend(["README.md", "ARCHITECTURE.md"].map(|f| root().join(f)));
    let mut bad = Vec::new();
    for file in files {
        let text = read(&file).to_lowercase();
        for (i, line) in text.lines().enumerate() {
            for word in ["issue ", "session ", "stop "] {
                let mut rest = line;
                while let Some(at) = rest.find(word) {
                    let after = &rest[at + word.len()..];
                    if after.starts_with(|c: char| c.is_ascii_digit()) {
                        bad.push(format!("{}:{}: {}", relative(&file), i + 1, line.trim()));
                    }
                    rest = after;
                }
            }
        }
    }
    assert!(bad.is_empty(), "history in the text:\n{}", bad.join("\n"));
}

/// The files every crate of the workspace starts from: the libraries, the binary, each
/// integration test, benchmark, example and fuzz target.
fn crate_roots() -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = [
        "core/lib.rs",
        "lab/lib.rs",
        "server/lib.rs",
        "server/main.rs",
    ]
    .iter()
    .map(|f| root().join(f))
    .collect();
    for dir in ["tests", "benches", "examples", "fuzz/fuzz_targets"] {
        let Ok(entries) = std::fs::read_dir(root().join(dir)) else {
            continue;
        };
        for p in entries.flatten().map(|e| e.path()) {
            if p.extension().is_some_and(|x| x == "rs") {
                roots.push(p);
            } else if p.join("main.rs").is_file() {
                roots.push(p.join("main.rs"));
            }
        }
    }
    roots.sort();
    roots
}

/// No file imports itself through other files. File A imports file B when A's code (as
/// [`code_lines`] reads it: no comments, no unit-test tail) names a path that resolves to B:
/// a path from `crate`, `super` or `self`, from a module A declares (`mod child;` then
/// `child::X`) or from a module A `use`d (`use crate::maps;` then `maps::X`), resolved to its
/// longest prefix that is a file module. `use` and `pub use` paths count, braces expanded;
/// `mod child;` alone does not. The rule in full, and the graph, are in `tests/tidy/imports.rs`.
/// A shared type or trait belongs in a file below every file that uses it, not in the file
/// that dispatches to them.
#[test]
fn no_file_imports_itself_through_other_files() {
    let code_of = |text: &str| {
        code_lines(text)
            .map(|(_, line)| line)
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut found = BTreeSet::new();
    for crate_root in crate_roots() {
        let graph = imports::file_graph(&crate_root, &code_of);
        found.extend(imports::circles(&graph, &root()));
    }
    assert!(
        found.is_empty(),
        "files that import themselves through other files (move what they share into a \
         file below them, or pass it down):\n{}",
        found
            .iter()
            .map(|c| c.as_str())
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// Each crate's features as `cargo tree -f '{p} {f}'` prints them, with `extra` arguments
/// (`-e no-dev` for the plain build).
fn features_of_every_crate(extra: &[&str]) -> BTreeSet<(String, String)> {
    let out = Command::new(env!("CARGO"))
        .current_dir(root())
        .args([
            "tree",
            "--offline",
            "--prefix",
            "none",
            "--format",
            "{p}|{f}",
        ])
        .args(extra)
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_once('|'))
        .map(|(p, f)| (p.to_string(), f.trim_end_matches(" (*)").to_string()))
        .collect()
}

/// A crate that both the build and the tests, examples or benchmarks use has the same
/// features in both (Cargo.toml, "Shared with the dev-dependencies"): otherwise
/// `cargo test` and `cargo build --examples` compile it, and every crate above it up to the
/// server, a second time.
#[test]
fn the_tests_reuse_the_builds_crates() {
    let build = features_of_every_crate(&["-e", "no-dev"]);
    let all = features_of_every_crate(&[]);
    let in_build: BTreeSet<&str> = build.iter().map(|(p, _)| p.as_str()).collect();
    let differ: Vec<String> = all
        .iter()
        .filter(|pf| in_build.contains(pf.0.as_str()) && !build.contains(*pf))
        .map(|(p, f)| format!("{p}: [{f}] with the dev-dependencies"))
        .collect();
    assert!(
        differ.is_empty(),
        "features that only the dev-dependencies turn on:\n{}",
        differ.join("\n")
    );
}

/// The project's markdown pages: the README, ARCHITECTURE.md and every `.md` under `docs/`,
/// `deploy/` and `python/`.
fn markdown_pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for p in entries.flatten().map(|e| e.path()) {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    let mut pages = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    for dir in ["docs", "deploy", "python"] {
        walk(&root().join(dir), &mut pages);
    }
    pages.sort();
    pages
}

/// Every relative link and picture in the markdown (`[text](target)`, `![alt](target)`)
/// names a file or folder that exists, so moving a page or a picture cannot leave a dead
/// link behind. Web addresses and in-page anchors are not checked.
#[test]
fn every_relative_link_in_the_docs_resolves() {
    let mut dead = Vec::new();
    for page in markdown_pages() {
        let text = read(&page);
        let mut in_code = false;
        for (i, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                in_code = !in_code;
            }
            if in_code {
                continue;
            }
            let mut rest = line;
            while let Some(at) = rest.find("](") {
                rest = &rest[at + 2..];
                let Some(end) = rest.find(')') else { break };
                let target = rest[..end].split('#').next().unwrap_or("");
                let target = target.split_whitespace().next().unwrap_or("");
                rest = &rest[end..];
                if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                let dir = page.parent().unwrap_or(Path::new("."));
                if !dir.join(target).exists() {
                    dead.push(format!("{}:{}: {target}", relative(&page), i + 1));
                }
            }
        }
    }
    assert!(dead.is_empty(), "links to nothing:\n{}", dead.join("\n"));
}

/// The container builds the workspace: its Dockerfile copies every member crate (cargo
/// refuses a workspace with one missing).
#[test]
fn the_dockerfile_copies_every_workspace_member() {
    let manifest = read(&root().join("Cargo.toml"));
    let members = manifest
        .lines()
        .find(|l| l.trim_start().starts_with("members"))
        .expect("the workspace lists its members");
    let dockerfile = read(&root().join("Dockerfile"));
    let missing: Vec<&str> = members
        .split('"')
        .skip(1)
        .step_by(2)
        .filter(|m| !dockerfile.contains(&format!("COPY {m} {m}")))
        .collect();
    assert!(
        missing.is_empty(),
        "the Dockerfile does not copy {missing:?}"
    );
    assert!(dockerfile.contains("COPY server server"));
}
