#!/usr/bin/env bash
# A lasertag experiment split over a Slurm job array: task k of n runs
# `lasertag experiment <experiment> --shard k/n` and writes its part under $OUT/parts; a merge
# job that waits for every task (--dependency=afterok) joins the parts into the CSV files and
# plots a single run writes, byte for byte. See deploy/README.md.
#
#   bash deploy/slurm/experiment-array.sh            submits the array and the merge after it
#   sbatch deploy/slurm/experiment-array.sh          submits the array alone (merge by hand)
#
# Settings (environment variables, read when submitting and passed on to the jobs):
#   EXPERIMENT  capture, filters, localisation, reacquire or uncertainty (default capture)
#   SHARDS      tasks in the array when submitted with bash (default 4; with sbatch, the
#               --array line below decides)
#   OUT         results directory on a filesystem every node sees (default ./out/$EXPERIMENT)
#   FLAGS       the experiment's other flags, the same for every shard (e.g. "--runs 200")
#   LASERTAG    the binary (default: lasertag on the PATH)
#   MAPS        the maps directory (default ./maps)
#
# Slurm reads the #SBATCH lines (flags on the sbatch command line win over them). Indexes are
# 0-based, as --shard takes them: the array must be 0-(n-1), every index once.
#SBATCH --job-name=lasertag-experiment
#SBATCH --array=0-3
#SBATCH --cpus-per-task=4
#SBATCH --mem=512M
#SBATCH --time=02:00:00
#SBATCH --output=lasertag-experiment-%A_%a.out

set -euo pipefail

EXPERIMENT=${EXPERIMENT:-capture}
OUT=${OUT:-$PWD/out/$EXPERIMENT}
FLAGS=${FLAGS:-}
LASERTAG=${LASERTAG:-lasertag}
MAPS=${MAPS:-$PWD/maps}
export EXPERIMENT OUT FLAGS LASERTAG MAPS

if [[ -z "${SLURM_ARRAY_TASK_ID:-}" ]]; then
    # Not a task of an array: submit the shards, then the merge that waits for all of them.
    if [[ -n "${SLURM_JOB_ID:-}" ]]; then
        echo "error: run this with bash (array and merge) or sbatch (the array alone)" >&2
        exit 2
    fi
    SHARDS=${SHARDS:-4}
    if ! [[ "$SHARDS" =~ ^[1-9][0-9]*$ ]]; then
        echo "error: SHARDS=$SHARDS: expected a whole number of at least 1" >&2
        exit 2
    fi
    mkdir -p "$OUT"
    # --parsable prints the job id, or `id;cluster` on a multi-cluster site.
    array=$(sbatch --parsable --job-name="lasertag-$EXPERIMENT" \
        --array="0-$((SHARDS - 1))" "$0")
    array=${array%%;*}
    # afterok on an array waits for every task to succeed; if one fails, the merge is
    # cancelled (--kill-on-invalid-dep) rather than left pending.
    merge=$(sbatch --parsable --job-name="lasertag-$EXPERIMENT-merge" \
        --dependency="afterok:$array" --kill-on-invalid-dep=yes \
        --cpus-per-task=1 --mem=512M --time=00:10:00 \
        --output="lasertag-$EXPERIMENT-merge-%j.out" \
        --wrap="$(printf '%q ' "$LASERTAG" experiment merge "$OUT/parts" --out "$OUT")")
    merge=${merge%%;*}
    echo "submitted $SHARDS shards of $EXPERIMENT as job $array, and merge job $merge after them"
    echo "results: $OUT"
    exit 0
fi

# Task k of an array 0-(n-1): shard k/n.
count=${SLURM_ARRAY_TASK_COUNT:-$((SLURM_ARRAY_TASK_MAX - SLURM_ARRAY_TASK_MIN + 1))}
if [[ "$SLURM_ARRAY_TASK_MIN" != 0 || "$SLURM_ARRAY_TASK_MAX" != $((count - 1)) ]]; then
    echo "error: the array is $SLURM_ARRAY_TASK_MIN-$SLURM_ARRAY_TASK_MAX with $count tasks;" \
        "shards need --array=0-$((count - 1)), every index once" >&2
    exit 2
fi
read -r -a flags <<<"$FLAGS"
# `${flags[@]+…}`: an empty array is "unbound" to `set -u` in bash before 4.4.
exec "$LASERTAG" experiment "$EXPERIMENT" ${flags[@]+"${flags[@]}"} --maps "$MAPS" \
    --shard "$SLURM_ARRAY_TASK_ID/$count" --out "$OUT"
