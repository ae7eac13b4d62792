#!/usr/bin/env bash
# Submits a calibench study as a Slurm job array of N shards and a merge job that waits for all of them.
#   scripts/slurm/submit.sh SCENARIO.toml N RESULTS_DIR [CAMPAIGN_BINARY]
# CAMPAIGN_BINARY defaults to target/release/campaign of this checkout (build it first:
# `cargo build --release --bin campaign`). RESULTS_DIR must be on a file system every node sees.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
if [[ $# -lt 3 ]]; then
    echo "usage: $0 SCENARIO.toml N RESULTS_DIR [CAMPAIGN_BINARY]" >&2
    exit 1
fi
scenario="$(realpath "$1")"
shards="$2"
results="$(realpath -m "$3")"
campaign="$(realpath "${4:-$here/../../target/release/campaign}")"
[[ "$shards" =~ ^[1-9][0-9]*$ ]] || { echo "N must be a positive integer, not '$shards'" >&2; exit 1; }
[[ -f "$scenario" ]] || { echo "no scenario file $scenario" >&2; exit 1; }
[[ -x "$campaign" ]] || { echo "no campaign binary at $campaign (cargo build --release --bin campaign)" >&2; exit 1; }
mkdir -p "$results"
export SCENARIO="$scenario" RESULTS="$results" SHARDS="$shards" CAMPAIGN="$campaign"
# --parsable prints the job id alone. The jobs run in the directory this script was called from, as sbatch
# does by default (a scenario's relative robot path is read from there); their logs go to RESULTS.
array=$(sbatch --parsable --array="0-$((shards - 1))" --output="$results/slurm-%A_%a.out" \
    --export=ALL "$here/study.sbatch")
array="${array%%;*}"
merge=$(sbatch --parsable --dependency="afterok:$array" --output="$results/slurm-%j-merge.out" \
    --export=ALL "$here/merge.sbatch")
echo "submitted shards as array job $array (0-$((shards - 1))) and the merge as job $merge"
echo "watch: squeue -j $array,$merge    result: $results/merged"
