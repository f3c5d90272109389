#!/usr/bin/env bash
# The GPU check in one go, on a lent GPU machine (its image: Python 3.12 with torch and numpy, no
# network): installs the wheels `scripts/gather_device_wheels.sh` put in device_wheels/ into /tmp/site,
# then runs `benchmarks/device_throughput.py --suite` (the update alone per device and path, a lone
# CO-PILOT trial with its learner on the GPU beside its CPU twin and a CPU trial on the paths before
# the fused update and the lean traversal loop; about 6 minutes), then `benchmarks/stacked_update.py`
# (N = 1, 4, 16, 64 seeds stacked in one update, eager and captured; under a minute), then
# `benchmarks/stacked_trial.py --gpu` (one seed's trial against 4 and 16 seeds stacked in one trial, the
# learner on the GPU; a few minutes), writing its
# output, with the machine, commit and command, to OUT_DIR/device_check.txt and every trial iteration
# to OUT_DIR/trials.jsonl.
#
#   [QUICK=1] bash scripts/device_check.sh [OUT_DIR] [extra device_throughput.py flags]   (default OUT_DIR: $OUT or .)
#
# A run cut off keeps what it printed (lines are flushed as rows finish) and the trials' iterations so
# far: `python benchmarks/device_throughput.py --summarise OUT_DIR/trials.jsonl`.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-${OUT:-.}}"
shift || true
mkdir -p "$out"
python_bin="${PYTHON:-python3}"
if ! PYTHONPATH=/tmp/site "$python_bin" -c "import ray, gymnasium" 2>/dev/null; then
  ls device_wheels/*.whl >/dev/null 2>&1 || {
    echo "error: no device_wheels/*.whl here: run scripts/gather_device_wheels.sh where PyPI is reachable" >&2
    exit 2
  }
  "$python_bin" -m pip install --disable-pip-version-check --quiet --no-index --no-deps --target /tmp/site \
    device_wheels/*.whl
fi
commit="${COMMIT:-$(git rev-parse --short HEAD 2>/dev/null || echo unknown)}"
# QUICK=1: the same three measurements cut to fit a lent machine's 15 minutes with its start (about 7
# minutes of running, each step capped by `timeout` so one that hangs leaves time for the rest): the stacked
# update first (N = 1, 4, 16, 64), then the update alone and a lone GPU trial beside its CPU twins, then
# 16 seeds stacked in one CO-PILOT trial on four-rooms (the benchmark's small trees, K = 3, b = 1: at
# K = 5, b = 5 an iteration of 16 seeds outlasts the lease; env steps/s hardly depend on K and b, the
# planner being about 1 % of a trial).
if [ "${QUICK:-0}" = 1 ]; then
  steps=(
    "90|benchmarks/stacked_update.py --seeds 1 4 16 64 --seconds 2"
    "200|benchmarks/device_throughput.py --suite --updates-seconds 3 --seconds 75 --warm-start 5 --log $out/trials.jsonl $*"
    "120|benchmarks/stacked_trial.py --gpu --stacks 16 --iterations 2 --rounds 1 --updates stacked --layout four-rooms"
  )
else
  steps=(
    "0|benchmarks/device_throughput.py --suite --log $out/trials.jsonl $*"
    "0|benchmarks/stacked_update.py --seeds 1 4 16 64 --seconds 3"
    "0|benchmarks/stacked_trial.py --gpu --stacks 4 16 --iterations 3 --rounds 1"
  )
fi
echo "# $(date -u '+%Y-%m-%d %H:%M UTC'), commit $commit, $(nproc) cores, $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 || echo 'no nvidia-smi')" >"$out/device_check.txt"
for step in "${steps[@]}"; do
  limit="${step%%|*}"
  command="${step#*|}"
  cut=""
  [ "$limit" = 0 ] || cut=" (cut at $limit s)"  # timeout 0: no limit
  echo "# PYTHONPATH=.:/tmp/site $python_bin $command$cut" >>"$out/device_check.txt"
  # A step that fails or is cut off says so and the next one still runs.
  # shellcheck disable=SC2086  # the command's words are split on purpose
  PYTHONPATH=.:/tmp/site RAY_AUTH_MODE=disabled timeout --signal INT --kill-after 10 "$limit" \
    "$python_bin" -u $command 2>&1 | tee -a "$out/device_check.txt" ||
    echo "# exit status ${PIPESTATUS[0]}" | tee -a "$out/device_check.txt"
done
# The trials' iterations as logged, summarised: the figures of a trial step that was cut off.
if [ -s "$out/trials.jsonl" ]; then
  echo "# PYTHONPATH=.:/tmp/site $python_bin benchmarks/device_throughput.py --summarise $out/trials.jsonl" >>"$out/device_check.txt"
  PYTHONPATH=.:/tmp/site "$python_bin" benchmarks/device_throughput.py --summarise "$out/trials.jsonl" 2>&1 | tee -a "$out/device_check.txt"
fi
