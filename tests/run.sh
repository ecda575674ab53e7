#!/usr/bin/env bash
# Runs every test of the project: unit, integration (a real server on an ephemeral port),
# browser tests (headless Chromium) and the benchmarks' smoke runs. This is the README's test
# command and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
# The browser tests drive Debian's Chromium; install it when it is missing (CI runs as root on
# a fresh machine; elsewhere sudo is used when available).
if ! command -v chromium >/dev/null 2>&1 && [ -z "${LASERTAG_CHROMIUM:-}" ]; then
  echo "tests/run.sh: installing chromium (Debian package) for the browser tests"
  SUDO=""
  if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi
cargo test --locked --all-targets
