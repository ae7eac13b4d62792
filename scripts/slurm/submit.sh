#!/usr/bin/env bash
# Submits a calibench study as a Slurm job array of N shards and a merge job that waits for all of them.
#   scripts/slurm/submit.sh [--cpus-per-task C] [--time T] [--partition P] [--mem M] \
#       SCENARIO.toml N RESULTS_DIR [CAMPAIGN_BINARY]
# The options are sbatch's own and go to every shard; --partition and --mem go to the merge job too (it needs one
# CPU and under half an hour whatever the study). Left out, the shards get the defaults of study.sbatch (2 CPUs,
# 2 hours), the merge those of merge.sbatch, and both the cluster's default partition and memory.
# CAMPAIGN_BINARY defaults to target/release/campaign of this checkout (build it first:
# `cargo build --release --bin campaign`). RESULTS_DIR must be on a file system every node sees.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
usage="usage: $0 [--cpus-per-task C] [--time T] [--partition P] [--mem M] SCENARIO.toml N RESULTS_DIR [CAMPAIGN_BINARY]"
shard_opts=()
merge_opts=()
while [[ $# -gt 0 && "$1" == --* ]]; do
    option="$1"
    case "$option" in
        --cpus-per-task | --time | --partition | --mem) ;;
        *) echo "unknown option $option; $usage" >&2; exit 1 ;;
    esac
    [[ $# -ge 2 && -n "$2" ]] || { echo "$option needs a value; $usage" >&2; exit 1; }
    shard_opts+=("$option=$2")
    case "$option" in
        --partition | --mem) merge_opts+=("$option=$2") ;;
    esac
    shift 2
done
if [[ $# -lt 3 || $# -gt 4 ]]; then
    echo "$usage" >&2
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
# does by default (a scenario's relative robot path is read from there); their logs go to RESULTS. Options on
# sbatch's command line override the scripts' #SBATCH lines.
array=$(sbatch --parsable --array="0-$((shards - 1))" --output="$results/slurm-%A_%a.out" \
    ${shard_opts[@]+"${shard_opts[@]}"} --export=ALL "$here/study.sbatch")
array="${array%%;*}"
merge=$(sbatch --parsable --dependency="afterok:$array" --output="$results/slurm-%j-merge.out" \
    ${merge_opts[@]+"${merge_opts[@]}"} --export=ALL "$here/merge.sbatch")
echo "submitted shards as array job $array (0-$((shards - 1))) and the merge as job $merge"
echo "watch: squeue -j $array,$merge    result: $results/merged"
