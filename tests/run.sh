#!/usr/bin/env bash
# Runs every test of the project: unit, integration (a real server on an ephemeral port),
# browser tests (headless Chromium) and the benchmarks' smoke runs. This is the README's test
# command and what CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
# What the tests need from Debian, installed when missing (CI runs as root on a fresh
# machine; elsewhere sudo is used when available): Chromium for the browser tests, Redis
# for the fleet's directory (tests/fleet.rs), PostgreSQL's server for the shared history
# (tests/store_postgres.rs), nftables and iproute2 for packet loss and the link emulator
# (tests/browser_webtransport.rs, tests/link.rs), npm for axe-core (tests/browser_a11y.rs).
# The tests start and stop their own servers.
NEED=()
if ! command -v chromium >/dev/null 2>&1 && [ -z "${LASERTAG_CHROMIUM:-}" ]; then NEED+=(chromium); fi
if ! command -v redis-server >/dev/null 2>&1 && [ -z "${LASERTAG_REDIS_SERVER:-}" ]; then NEED+=(redis-server); fi
if ! command -v nft >/dev/null 2>&1; then NEED+=(nftables); fi
if ! command -v ip >/dev/null 2>&1; then NEED+=(iproute2); fi
if ! command -v npm >/dev/null 2>&1 && [ -z "${LASERTAG_AXE:-}" ]; then NEED+=(nodejs npm); fi
if ! command -v initdb >/dev/null 2>&1 && ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 \
  && [ -z "${LASERTAG_PG_BIN:-}" ]; then NEED+=(postgresql); fi
if [ "${#NEED[@]}" -gt 0 ]; then
  echo "tests/run.sh: installing ${NEED[*]} (Debian packages) for the tests"
  SUDO=""
  if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  # Whatever services the packages start themselves are not used: the tests run servers
  # of their own on free ports.
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${NEED[@]}" >/dev/null
fi
# axe-core, the accessibility rules tests/browser_a11y.rs runs in Chromium: a pinned version
# from npm into target/axe (its one file is all the test reads), unless LASERTAG_AXE names one.
AXE_VERSION=4.14.1
AXE_DIR=target/axe
if [ -z "${LASERTAG_AXE:-}" ]; then
  if ! grep -qs "\"version\": \"$AXE_VERSION\"" "$AXE_DIR/node_modules/axe-core/package.json"; then
    echo "tests/run.sh: installing axe-core $AXE_VERSION (npm) into $AXE_DIR"
    rm -rf "$AXE_DIR"
    npm install --prefix "$AXE_DIR" --no-save --no-audit --no-fund --loglevel=error \
      "axe-core@$AXE_VERSION" >/dev/null
  fi
  export LASERTAG_AXE="$PWD/$AXE_DIR/node_modules/axe-core/axe.min.js"
fi
# No incremental compilation caches: a full run builds every test binary once, and the
# caches (as large again as the binaries) only fill the disk of a fresh machine.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
# Lints first (tests/tidy.rs checks formatting and the floors; clippy would wait on the build
# directory that `cargo test` holds if the tidy test ran it).
cargo clippy --locked --workspace --all-targets -- -D warnings
cargo test --locked --workspace --all-targets

# The Python research environment (python/, docs/research.md): its pytest suite, which starts
# its own servers from the debug binary (`cargo test` builds it for the integration tests;
# built here only if it is missing), in a venv of its own with the versions
# python/constraints.txt pins (PyPI). Installing the package builds its native engine
# (native/, by maturin from PyPI, in release mode into this workspace's target/), which the
# suite compares with the HTTP backend episode by episode.
[ -x target/debug/lasertag ] || cargo build --locked --bin lasertag
PY_DIR=target/python-env
# A venv's scripts name its path in their first line: a build directory that was moved
# (or copied from another checkout) keeps a venv whose `pip` cannot run. Ask its Python.
VENV_PY="$PY_DIR/venv/bin/python"
if ! "$VENV_PY" -m pip --version >/dev/null 2>&1; then
  rm -rf "$PY_DIR/venv"
  python3 -m venv "$PY_DIR/venv" >/dev/null 2>&1 || rm -rf "$PY_DIR/venv"
fi
if "$VENV_PY" -m pip --version >/dev/null 2>&1; then
  "$VENV_PY" -m pip install -q --disable-pip-version-check -c python/constraints.txt ./python pytest
  # The package's own version does not change with its code: reinstall it every run.
  "$VENV_PY" -m pip install -q --disable-pip-version-check --no-deps --force-reinstall ./python
  LASERTAG_BIN=target/debug/lasertag "$PY_DIR/venv/bin/python" -m pytest python/tests
  BENCH_PY="$VENV_PY"
else
  # A Python without venv (Debian's python3 without python3-venv): install into a folder.
  rm -rf "$PY_DIR/pkgs"
  python3 -m pip install -q --disable-pip-version-check -c python/constraints.txt --target "$PY_DIR/pkgs" ./python pytest
  LASERTAG_BIN=target/debug/lasertag PYTHONPATH="$PWD/$PY_DIR/pkgs" python3 -m pytest python/tests
  BENCH_PY="env PYTHONPATH=$PWD/$PY_DIR/pkgs python3"
fi
# docs/research.md's speed benchmark cannot rot: its in-process rows, a fraction of a second
# each (the figures are the script's to print, not a test's to judge).
$BENCH_PY python/benchmarks/backends.py --seconds 0.3 --warmup 0.1 --no-http --no-simple-tag --worlds 1 64

# The training example cannot rot: a few hundred PPO steps on the in-process engine, the
# evaluation and the ONNX export, in a venv of its own (PyTorch, pinned, is installed for
# this and for training only; a CPU build is not on PyPI, so it comes with its CUDA
# libraries, unused).
TRAIN_DIR=target/train-env
if ! "$TRAIN_DIR/venv/bin/python" -c 'import torch, onnx, matplotlib' 2>/dev/null; then
  rm -rf "$TRAIN_DIR"
  python3 -m venv "$TRAIN_DIR/venv"
  "$TRAIN_DIR/venv/bin/python" -m pip install -q --disable-pip-version-check -r python/examples/requirements-train.txt
fi
"$TRAIN_DIR/venv/bin/python" -m pip install -q --disable-pip-version-check -c python/constraints.txt ./python
"$TRAIN_DIR/venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps --force-reinstall ./python
SMOKE_OUT=$(mktemp -d)
"$TRAIN_DIR/venv/bin/python" python/examples/train_team.py --smoke --out "$SMOKE_OUT"
for f in policy.onnx learning_curve.png capture_times.csv; do
  [ -s "$SMOKE_OUT/$f" ] || { echo "tests/run.sh: the training smoke run wrote no $f"; exit 1; }
done
rm -rf "$SMOKE_OUT"
echo "tests/run.sh: the training example ran"

# API conformance: schemathesis (from PyPI, pinned) against the real server's OpenAPI
# document, every operation, every check but one (exceptions and reasons in
# tests/schemathesis.toml).
# Any failure (a 5xx, a response off its schema, ...) fails the run.
SCHEMATHESIS_VERSION=4.32.5
ST_DIR=target/schemathesis
ST="$ST_DIR/venv/bin/schemathesis"
if ! { [ -x "$ST" ] && "$ST" --version 2>/dev/null | grep -q "$SCHEMATHESIS_VERSION"; }; then
  echo "tests/run.sh: installing schemathesis $SCHEMATHESIS_VERSION (PyPI) into $ST_DIR"
  rm -rf "$ST_DIR"
  if python3 -m venv "$ST_DIR/venv" >/dev/null 2>&1; then
    "$ST_DIR/venv/bin/pip" install -q --disable-pip-version-check "schemathesis==$SCHEMATHESIS_VERSION"
  else
    # A Python without venv (Debian's python3 without python3-venv): install into a folder.
    python3 -m pip install -q --disable-pip-version-check --target "$ST_DIR/pkgs" "schemathesis==$SCHEMATHESIS_VERSION"
    mkdir -p "$ST_DIR/venv/bin"
    printf '#!/bin/sh\nPYTHONPATH="%s" exec python3 -m schemathesis.cli "$@"\n' "$PWD/$ST_DIR/pkgs" > "$ST"
    chmod +x "$ST"
  fi
fi
# The server `cargo test` built, on a free loopback port, without the showcase. Every request
# comes from 127.0.0.1, so the per-address request rate is lifted, and so is the number of
# matches and the tick budget they are priced against (schemathesis creates many, most of
# them manual matches that never tick; a full server would rightly answer 503, which is not
# what this run is about), as are the per-client quotas; finished matches are removed after
# 5 s. Connections per address stay at their default (256), far above schemathesis's
# workers. Schemathesis changes matches as the operator (a fresh admin token for this run).
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
ADMIN_TOKEN=$(python3 -c 'import secrets; print(secrets.token_hex(16))')
LASERTAG_ADDR="127.0.0.1:$PORT" LASERTAG_NO_SHOWCASE=true LASERTAG_ADMIN_TOKEN="$ADMIN_TOKEN" \
  LASERTAG_REQUESTS_PER_S=1000000 LASERTAG_REQUEST_BURST=1000000 \
  LASERTAG_MAX_MATCHES=100000 LASERTAG_MAX_MATCHES_PER_ADDRESS=100000 \
  LASERTAG_MAX_MAPS=100000 LASERTAG_MAX_MAPS_PER_ADDRESS=100000 LASERTAG_MAX_HOLDS_PER_ADDRESS=100000 \
  LASERTAG_MAX_POLICIES=100000 LASERTAG_MAX_POLICIES_PER_ADDRESS=100000 \
  LASERTAG_MAX_SEATS_PER_ADDRESS=100000 LASERTAG_MAX_EXPORTS_PER_ADDRESS=100000 \
  LASERTAG_MAX_NAMES_PER_ADDRESS=100000 LASERTAG_NAME_CLAIMS_PER_MINUTE=1000000 \
  LASERTAG_CLIENT_BUDGET_SHARE=1 LASERTAG_TICK_BUDGET_MS=1000000 \
  LASERTAG_FINISHED_GRACE_S=5 RUST_LOG=warn \
  target/debug/lasertag serve --data-dir "$(mktemp -d)" > target/schemathesis/server.log 2>&1 &
SERVER_PID=$!
trap 'kill "$SERVER_PID" 2>/dev/null || true' EXIT
# Bounded: 40 examples per operation and phase keep the run to a few minutes. A fixed seed
# keeps CI reproducible (each new random seed is a new exploration, and a finding belongs in
# a commit, not in someone else's CI run); LASERTAG_SCHEMATHESIS_SEED=random explores.
ST_SEED="${LASERTAG_SCHEMATHESIS_SEED:-260417942957883433998280874087315974579}"
ST_SEED_ARGS=()
if [ "$ST_SEED" != random ]; then ST_SEED_ARGS=(--seed "$ST_SEED"); fi
# Matches for the operations on one match to act on (generated ids would only ever find
# nothing): a manual one with API-driven opponents (step, command) and one with human slots
# (players); the hooks send most generated requests there (tests/schemathesis_hooks.py).
fixture() {
  python3 - "$PORT" "$1" <<'PY'
import json, sys, time, urllib.request
port, body = sys.argv[1], sys.argv[2]
for _ in range(600):
    try:
        req = urllib.request.Request(f"http://127.0.0.1:{port}/api/matches", body.encode(),
                                     {"content-type": "application/json"})
        print(json.load(urllib.request.urlopen(req, timeout=5))["id"])
        break
    except OSError:
        time.sleep(0.1)
else:
    sys.exit("tests/run.sh: the server never answered")
PY
}
LASERTAG_ST_MANUAL=$(fixture '{"map": "office", "clock": "manual", "opponent_control": "api", "opponents": 2}')
LASERTAG_ST_HUMAN=$(fixture '{"map": "office", "opponent_control": "human", "opponents": 32, "robots": 1, "planner": "idle"}')
export LASERTAG_ST_MANUAL LASERTAG_ST_HUMAN
(cd tests && SCHEMATHESIS_HOOKS=schemathesis_hooks "../$ST" --config-file schemathesis.toml \
  run "http://127.0.0.1:$PORT/api/openapi.json" --wait-for-schema 60 "${ST_SEED_ARGS[@]}" \
  -H "Authorization: Bearer $ADMIN_TOKEN" \
  --checks all --exclude-checks ignored_auth --max-examples 40 --request-timeout 60 --workers 2 --no-color)
kill "$SERVER_PID" 2>/dev/null || true
wait "$SERVER_PID" 2>/dev/null || true
echo "tests/run.sh: schemathesis passed"
