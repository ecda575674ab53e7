//! The hostile battery's probes that need the real binary and its log: what an operator asks
//! of the server is what it does, and every warning it logs is one to act on.
//!
//! - A connection cap per address the operator gives is used as given, within the open files
//!   (a load test from one address is not cut to a sixteenth of them); the default is
//!   derived from the files; a cap the files cannot hold is lowered with one warning naming
//!   what was asked and what was granted.
//! - A server stopping with a finished match in its store logs nothing about it: the match is
//!   not "suspended", and nothing more of it is written.

#![cfg(unix)]

mod common;
#[path = "common/process.rs"]
mod process;

use std::time::Duration;

use process::Server;
use serde_json::json;
use tokio::io::AsyncReadExt;
use tokio::net::TcpStream;

/// The open files the servers here run with: 768 connections once 256 are kept for files.
const FILES: u64 = 1024;
/// What [`FILES`] leaves for connections.
const ROOM: usize = 768;

/// Opens `n` connections to `s` from 127.0.0.1 that send nothing, then counts those the
/// server closed within a moment: the ones over its cap for the address.
async fn closed_of(s: &Server, n: usize) -> (Vec<TcpStream>, usize) {
    let mut open = Vec::with_capacity(n);
    for _ in 0..n {
        open.push(TcpStream::connect(s.addr).await.expect("connect"));
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut closed = 0;
    let mut buf = [0u8; 64];
    for stream in &mut open {
        // A refused connection is closed at once; a held one has nothing to read yet.
        if let Ok(Ok(0) | Err(_)) =
            tokio::time::timeout(Duration::from_millis(5), stream.read(&mut buf)).await
        {
            closed += 1;
        }
    }
    (open, closed)
}

fn warnings(s: &Server) -> Vec<String> {
    s.warnings.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

fn log_lines(s: &Server, containing: &str) -> Vec<String> {
    let log = s.log.lock().unwrap_or_else(|e| e.into_inner());
    log.iter()
        .filter(|l| l.contains(containing))
        .cloned()
        .collect()
}

/// Waits until `s` has logged its connection caps: its accept loop starts, and whatever it
/// warns of at start is logged by then.
async fn accepting(s: &Server) {
    for _ in 0..200 {
        if !log_lines(s, "connection caps").is_empty() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("no connection caps logged");
}

fn serve_args<'a>(data: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "--no-showcase",
        "--no-webtransport",
        "--data-dir",
        data,
        // The probe's connections send nothing: they must not be closed for it meanwhile.
        "--header-read-timeout-s",
        "60",
    ];
    args.extend_from_slice(extra);
    args
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_operators_connection_cap_is_used_as_given_within_the_open_files() {
    let data = common::temp_dir("operator-caps").display().to_string();

    // The default is derived from the files: a sixteenth of what they leave (48).
    let s = Server::start_with_files(FILES, &serve_args(&data, &[]));
    accepting(&s).await;
    let (_held, closed) = closed_of(&s, 60).await;
    assert_eq!(
        closed,
        60 - ROOM / 16,
        "{:?}",
        log_lines(&s, "connection caps")
    );
    assert_eq!(warnings(&s), Vec::<String>::new());
    drop(s);

    // Given, below what the files leave: every one of them, far past a sixteenth.
    let s = Server::start_with_files(FILES, &serve_args(&data, &["--max-tcp-per-address", "600"]));
    accepting(&s).await;
    let (_held, closed) = closed_of(&s, 610).await;
    assert_eq!(closed, 10);
    assert_eq!(warnings(&s), Vec::<String>::new());
    drop(s);

    // Given, past what the files leave: granted what they leave, and one warning says so.
    let s = Server::start_with_files(
        FILES,
        &serve_args(
            &data,
            &[
                "--max-tcp-per-address",
                "1000000",
                "--max-connections",
                "1000000",
            ],
        ),
    );
    accepting(&s).await;
    let warned = warnings(&s);
    assert_eq!(warned.len(), 2, "one warning for each flag: {warned:?}");
    for (flag, line) in ["--max-connections", "--max-tcp-per-address"]
        .iter()
        .zip(&warned)
    {
        assert!(line.contains(flag), "{line}");
        assert!(line.contains("asked=1000000"), "{line}");
        assert!(line.contains(&format!("granted={ROOM}")), "{line}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_finished_match_is_not_suspended_nor_written_at_a_stop() {
    let data = common::temp_dir("operator-stop").display().to_string();
    let s = Server::start(&serve_args(&data, &[]));
    let http = reqwest::Client::new();
    let (id, token) = process::create_with(
        &http,
        &s,
        json!({"map": "office", "clock": "manual", "time_limit_s": 5, "seed": 3}),
    )
    .await;
    let state = process::step(&http, &s, &id, &token, 200).await;
    assert_eq!(state["status"], "finished", "{state}");
    // A few of the task's housekeeping rounds, each of which may flush to the store.
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let pid = s.child.id().to_string();
    let killed = std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let mut s = s;
    let _ = s.child.wait();
    // The log's last lines, read by the harness's thread.
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(warnings(&s), Vec::<String>::new());
    assert_eq!(log_lines(&s, "suspended"), Vec::<String>::new());
    assert_eq!(log_lines(&s, "shut down cleanly").len(), 1);
}
