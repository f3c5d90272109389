#!/usr/bin/env bash
# The planner warm start's validation probe: benchmarks/planner_collision.py once per (layout, variant,
# seed), as many processes at once as there are cores, then one table of all their logs.
#   layouts four-rooms and u-maze (where defaults are chosen), seeds 0-3, variants $VARIANTS (default d c k)
#     d: the annealed warm start (std 0.05 -> 0.015 over 1000 phases) with the free mean (the default
#        until planner.mean leaky; every variant but s and b keeps the free mean, as when first measured)
#     c: constant std 0.05   k: d with planner.max_kl 0.5   l: d with collision_cost length (SGT-PG's)
#     s: d with planner.mean squashed   b: d with planner.mean leaky (CO-PILOT's default)
#   spiral (transfer check only; nothing is chosen on it): seeds 0-1, variants $SPIRAL_VARIANTS (default d k)
# usage: [VARIANTS="d c k"] [SPIRAL_VARIANTS="d k"] \
#        bash benchmarks/planner_validation_probe.sh [PHASES=1000] [OUTDIR=results/planner_probe] [SECONDS=3600]
# Writes OUTDIR/probe.jsonl (one line per evaluation) and OUTDIR/probe_stdout.txt; prints the table.
set -u
PHASES=${1:-1000}; OUTDIR=${2:-results/planner_probe}; LIMIT=${3:-3600}
PYTHON=${PYTHON:-.venv/bin/python}
VARIANTS=${VARIANTS-d c k}; SPIRAL_VARIANTS=${SPIRAL_VARIANTS-d k}  # set and empty: none
mkdir -p "$OUTDIR"
LOGS=$(mktemp -d)
jobs() {
  for s in 0 1; do for v in $SPIRAL_VARIANTS; do echo "spiral $v $s"; done; done
  for lay in four-rooms u-maze; do for s in 0 1 2 3; do for v in $VARIANTS; do echo "$lay $v $s"; done; done; done
}
one() {
  lay=$1; v=$2; s=$3; a="--std-final 0.015 --anneal-phases 1000"; cost=indicator; mean=free
  [ "$v" = c ] && a=""
  [ "$v" = k ] && a="$a --max-kl 0.5"
  [ "$v" = l ] && cost=length
  [ "$v" = s ] && mean=squashed
  [ "$v" = b ] && mean=leaky
  a="$a --mean $mean"
  # shellcheck disable=SC2086  # $a is a list of flags
  PYTHONPATH=. OMP_NUM_THREADS=1 "$PYTHON" benchmarks/planner_collision.py --collision-costs "$cost" \
    --iterations "$PHASES" --eval-every $((PHASES / 10 > 0 ? PHASES / 10 : 1)) --layout "$lay" --seeds "$s" $a \
    --log "$LOGS/$lay-$v-$s.jsonl" > "$LOGS/$lay-$v-$s.txt" 2>&1
}
export -f one; export PHASES LOGS PYTHON
echo "cores: $(nproc)  python: $("$PYTHON" --version)  start: $(date +%T)"
jobs | timeout "$LIMIT" xargs -P "$(nproc)" -L 1 bash -c 'one $0 $1 $2'
echo "end: $(date +%T)"
cat "$LOGS"/*.jsonl > "$OUTDIR/probe.jsonl"
tail -n 4 "$LOGS"/*.txt > "$OUTDIR/probe_stdout.txt"
PYTHONPATH=. "$PYTHON" benchmarks/planner_collision.py --summarise "$OUTDIR/probe.jsonl"
