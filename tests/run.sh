#!/usr/bin/env bash
# Runs every test of the project: unit, integration (a real server on an ephemeral port) and
# the benchmarks' smoke runs. This is the README's test command and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --locked --all-targets
