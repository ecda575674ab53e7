//! Sharded experiments, through the real binary: a study run as shards (`--shard i/n`) and
//! joined by `lasertag experiment merge` writes the same files, byte for byte, as the study
//! run whole; and parts that do not make one study are refused by name.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh directory under the system's temporary directory.
fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lasertag-shards-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn experiment(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lasertag"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .arg("experiment")
        .args(args)
        .output()
        .expect("the lasertag binary runs")
}

/// Runs `args`, failing the test with its output if it fails; returns its stdout.
fn ok(args: &[&str]) -> String {
    let o = experiment(args);
    assert!(o.status.success(), "{args:?}: {o:?}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs `args`, which must fail; returns its stderr.
fn refused(args: &[&str]) -> String {
    let o = experiment(args);
    assert!(!o.status.success(), "{args:?} succeeded: {o:?}");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file directly in `dir` (the outputs; a `parts/` directory is not one), by name.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("listing {}: {e}", dir.display()))
        .flatten()
        .filter(|e| e.path().is_file())
        .map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            (name, std::fs::read(e.path()).expect("reading an output"))
        })
        .collect()
}

/// The two directories hold the same files, each the same bytes.
fn assert_same_files(whole: &Path, merged: &Path) {
    let (a, b) = (files(whole), files(merged));
    assert!(!a.is_empty(), "{} is empty", whole.display());
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "the same files"
    );
    for (name, bytes) in &a {
        assert!(
            bytes == &b[name],
            "{name} differs between the whole run and the merge"
        );
    }
}

/// A study's flags followed by `extra`.
fn args<'a>(study: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
    [study, extra].concat()
}

fn path(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 temporary path")
}

/// The acceptance check: capture in 4 shards, merged, equals capture run whole, every CSV
/// and plot byte for byte, and the merge prints the same tables.
#[test]
fn capture_in_four_shards_merges_into_the_single_runs_files() {
    let (whole, sharded, merged) = (
        out_dir("capture-whole"),
        out_dir("capture-sharded"),
        out_dir("capture-merged"),
    );
    let study = ["capture", "--runs", "3", "--time-limit", "8"];
    let printed = ok(&args(&study, &["--out", path(&whole)]));
    for i in 0..4 {
        let shard = format!("{i}/4");
        let said = ok(&args(&study, &["--shard", &shard, "--out", path(&sharded)]));
        assert!(said.contains(&format!("shard {shard} ran ")), "{said}");
    }
    assert!(
        files(&sharded).is_empty(),
        "a shard writes only its part, under parts/"
    );
    let merge_said = ok(&[
        "merge",
        path(&sharded.join("parts")),
        "--out",
        path(&merged),
    ]);
    assert_same_files(&whole, &merged);
    assert!(files(&whole).contains_key("capture_gospa_warehouse_evade.svg"));
    assert_eq!(
        merge_said.replace(path(&merged), "OUT"),
        format!("{}merged 4 parts\n", printed.replace(path(&whole), "OUT")),
        "the merge prints what the whole run prints"
    );
    for d in [whole, sharded, merged] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Another experiment, cheaper: reacquire's 8 runs over 3 shards (3, 3 and 2 runs), the
/// parts named one by one and out of order.
#[test]
fn reacquire_in_uneven_shards_merges_into_the_single_runs_files() {
    let (whole, sharded, merged) = (
        out_dir("reacquire-whole"),
        out_dir("reacquire-sharded"),
        out_dir("reacquire-merged"),
    );
    let study = ["reacquire", "--runs", "2", "--limit", "3"];
    ok(&args(&study, &["--out", path(&whole)]));
    for i in 0..3 {
        ok(&args(
            &study,
            &["--shard", &format!("{i}/3"), "--out", path(&sharded)],
        ));
    }
    let part = |i: usize| sharded.join(format!("parts/reacquire.shard-{i}-of-3.part"));
    let (p2, p0, p1) = (part(2), part(0), part(1));
    ok(&[
        "merge",
        path(&p2),
        path(&p0),
        path(&p1),
        "--out",
        path(&merged),
    ]);
    assert_same_files(&whole, &merged);
    for d in [whole, sharded, merged] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Parts that do not make one whole study, and shard flags that are no shard, are refused
/// with what is wrong, and the merge writes nothing.
#[test]
fn parts_of_no_one_study_are_refused_by_name() {
    let dir = out_dir("refused");
    let merged = dir.join("merged");
    let reacquire = |seed: &str, shard: &str, out: &str| {
        let out = dir.join(out);
        ok(&[
            "reacquire",
            "--runs",
            "1",
            "--limit",
            "2",
            "--seed",
            seed,
            "--shard",
            shard,
            "--out",
            path(&out),
        ]);
        out.join(format!(
            "parts/reacquire.shard-{}-of-{}.part",
            &shard[..1],
            &shard[2..]
        ))
    };
    let a0 = reacquire("0", "0/2", "a");
    let a1 = reacquire("0", "1/2", "a");
    let other_seed = reacquire("5", "1/2", "b");
    let other_split = reacquire("0", "1/3", "c");
    let capture = dir.join("d");
    ok(&[
        "capture",
        "--runs",
        "1",
        "--time-limit",
        "1",
        "--on",
        "office",
        "--shard",
        "0/2",
        "--out",
        path(&capture),
    ]);
    let capture_part = capture.join("parts/capture.shard-0-of-2.part");
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("an empty directory");
    let merge = |parts: &[&PathBuf]| {
        let mut args = vec!["merge"];
        args.extend(parts.iter().map(|p| path(p)));
        args.extend(["--out", path(&merged)]);
        refused(&args)
    };
    for (parts, says) in [
        (vec![&a0], "1 of 2 shards missing: 1/2"),
        (vec![&a0, &a1, &a1], "shard 1/2 twice"),
        (
            vec![&a0, &other_seed],
            "parameter `seed` is \"0\" in the first, \"5\"",
        ),
        (vec![&a0, &other_split], "is a shard of 3"),
        (vec![&a0, &capture_part], "merge one study at a time"),
        (vec![&empty], "no part files (*.part)"),
    ] {
        let err = merge(&parts);
        assert!(err.contains(says), "{parts:?}: {err}");
    }
    std::fs::write(&a1, "lasertag-experiment-part 1\nexperiment reacquire\n").expect("writing");
    let err = merge(&[&a0, &a1]);
    assert!(err.contains("ends before its `shard` line"), "{err}");
    for (shard, says) in [
        ("0/0", "the count must be at least 1"),
        ("4/4", "the index is 0-based, so shards of 4 are 0/4 to 3/4"),
        ("one/4", "expected INDEX/COUNT"),
    ] {
        let out = dir.join("bad-shard");
        let err = refused(&["reacquire", "--shard", shard, "--out", path(&out)]);
        assert!(err.contains(says), "--shard {shard}: {err}");
        assert!(!out.exists(), "--shard {shard} wrote {}", out.display());
    }
    assert!(
        !merged.exists(),
        "a refused merge wrote {}",
        merged.display()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
