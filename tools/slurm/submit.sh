#!/usr/bin/env bash
# Submits a sharded benchmark to Slurm: an array of N `macro bench run` shards
# (tools/slurm/bench.sbatch) and a merge + report job that starts when every shard succeeded
# (--dependency=afterok:<array job id>). docs/benchmark.md, "On a Slurm cluster".
#
#   tools/slurm/submit.sh --root /data/DL3DV-Closeup --out /scratch/bench --shards 8 \
#       [--cpus 16] [--macro /path/to/macro] [--sbatch-args "--partition=cpu --time=12:00:00"] \
#       -- --methods 3dgs,transfer --K 1,3
#
# Everything after `--` goes to `macro bench run`. Prints the two job ids.
set -euo pipefail

usage() {
  sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'
}
die() {
  echo "submit.sh: $*" >&2
  exit 2
}

root="" out="" shards="" cpus="" macro_bin="" sbatch_args=""
while [ $# -gt 0 ]; do
  case "$1" in
    --root) root=${2:?--root needs a value}; shift 2 ;;
    --out) out=${2:?--out needs a value}; shift 2 ;;
    --shards) shards=${2:?--shards needs a value}; shift 2 ;;
    --cpus) cpus=${2:?--cpus needs a value}; shift 2 ;;
    --macro) macro_bin=${2:?--macro needs a value}; shift 2 ;;
    --sbatch-args) sbatch_args=${2:?--sbatch-args needs a value}; shift 2 ;;
    -h | --help) usage; exit 0 ;;
    --) shift; break ;;
    *) die "unknown argument '$1' (--help for usage)" ;;
  esac
done
[ -n "$root" ] || die "--root: required"
[ -n "$out" ] || die "--out: required"
case "$shards" in
  '' | *[!0-9]* | 0) die "--shards: expected a positive integer, found '$shards'" ;;
esac
if [ -n "$cpus" ]; then
  case "$cpus" in '' | *[!0-9]* | 0) die "--cpus: expected a positive integer, found '$cpus'" ;; esac
fi
command -v sbatch >/dev/null || die "sbatch not found (run this on a Slurm login node)"
[ -d "$root" ] || die "--root $root: folder not found"
if [ -z "$macro_bin" ]; then macro_bin=$(command -v macro) || die "--macro: not given and no macro on PATH"; fi
[ -x "$macro_bin" ] || die "--macro $macro_bin: not an executable"

here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out/logs"
root=$(cd "$root" && pwd)
out=$(cd "$out" && pwd)
export MACRO_BIN=$macro_bin MACRO_BENCH_ROOT=$root MACRO_BENCH_OUT=$out MACRO_BENCH_ARGS="$*"

cpu_args=()
if [ -n "$cpus" ]; then cpu_args=(--cpus-per-task "$cpus"); fi
# shellcheck disable=SC2086  # sbatch_args is a list of flags
array_id=$(MACRO_BENCH_STEP=run sbatch --parsable --export=ALL --array="0-$((shards - 1))" \
  "${cpu_args[@]}" --output="$out/logs/shard-%a.out" $sbatch_args "$here/bench.sbatch")
array_id=${array_id%%;*}  # --parsable prints "id" or "id;cluster"
# shellcheck disable=SC2086
merge_id=$(MACRO_BENCH_STEP=merge sbatch --parsable --export=ALL \
  --dependency="afterok:$array_id" --job-name=macro-bench-merge --output="$out/logs/merge.out" \
  $sbatch_args "$here/bench.sbatch")
merge_id=${merge_id%%;*}
echo "shards: job $array_id (array 0-$((shards - 1))), merge + report: job $merge_id (afterok)"
echo "results: $out/results.jsonl, report: $out/report/"
