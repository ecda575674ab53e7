#!/usr/bin/env bash
# Checks that two builds of lasertag write byte-identical experiment CSVs: every experiment
# (filters, capture, reacquire, localisation, uncertainty, and capture again as two shards
# merged), each at a small size that takes a few minutes in all on 2 cores, run by both
# binaries with the same flags, then every CSV compared with `cmp`. For a change that must
# not move any figure (a refactoring): build the binary before and after it, then
#
#   tests/csv_identity.sh BEFORE/lasertag AFTER/lasertag /tmp/csv-identity
#
# The maps are this checkout's `maps/`. Exits non-zero when a CSV differs, or when one
# binary wrote a CSV the other did not. Not part of tests/run.sh: it needs two builds.
set -euo pipefail
if [ "$#" -ne 3 ]; then
  echo "usage: $0 BASE_BINARY NEW_BINARY OUT_DIR" >&2
  exit 2
fi
base=$(realpath "$1")
new=$(realpath "$2")
out=$(realpath -m "$3")
cd "$(dirname "$0")/.."

# Each line: an output folder's name, then the experiment's arguments (`--out` is added).
EXPERIMENTS=(
  "filters      filters --runs 2 --opponents 6 --particles 300"
  "capture      capture --runs 2 --time-limit 40 --on office,warehouse"
  "reacquire    reacquire --runs 2 --limit 15"
  "localisation localisation --runs 1 --seconds 20"
  "uncertainty  uncertainty --runs 2 --hunt-s 15 --time-limit 30 --on office"
)
SHARDED="capture --runs 2 --time-limit 40 --on office"

run() { # binary, side
  local bin=$1 side=$2 line name
  for line in "${EXPERIMENTS[@]}"; do
    read -r name args <<<"$line"
    # shellcheck disable=SC2086 # the arguments are words
    "$bin" experiment $args --out "$out/$side/$name" >>"$out/$side.log" 2>&1
  done
  for shard in 0/2 1/2; do
    # shellcheck disable=SC2086
    "$bin" experiment $SHARDED --shard "$shard" --out "$out/$side/sharded" >>"$out/$side.log" 2>&1
  done
  "$bin" experiment merge "$out/$side/sharded/parts" --out "$out/$side/merged" \
    >>"$out/$side.log" 2>&1
}

rm -rf "$out"
mkdir -p "$out"
for side in base new; do
  bin=$base
  [ "$side" = new ] && bin=$new
  started=$SECONDS
  if ! run "$bin" "$side"; then
    echo "csv_identity: the $side binary failed; see $out/$side.log" >&2
    exit 1
  fi
  echo "csv_identity: $side ($bin) ran every experiment in $((SECONDS - started)) s"
done

status=0
list() { (cd "$out/$1" && find . -name '*.csv' | sort); }
if ! diff <(list base) <(list new) >"$out/files.diff"; then
  echo "csv_identity: the binaries wrote different sets of CSVs:" >&2
  cat "$out/files.diff" >&2
  status=1
fi
count=0
bytes=0
while read -r csv; do
  [ -f "$out/new/$csv" ] || continue
  count=$((count + 1))
  bytes=$((bytes + $(stat -c %s "$out/base/$csv")))
  if ! cmp "$out/base/$csv" "$out/new/$csv"; then
    status=1
  fi
done < <(list base)
echo "csv_identity: compared $count CSVs ($bytes bytes)"
[ "$status" = 0 ] && echo "csv_identity: identical" || echo "csv_identity: DIFFERENT" >&2
exit "$status"
