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
#   bash scripts/device_check.sh [OUT_DIR] [extra device_throughput.py flags]   (default OUT_DIR: $OUT or .)
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
commit="$(git rev-parse --short HEAD 2>/dev/null || echo "${COMMIT:-unknown}")"
command=(benchmarks/device_throughput.py --suite --log "$out/trials.jsonl" "$@")
{
  echo "# $(date -u '+%Y-%m-%d %H:%M UTC'), commit $commit, $(nproc) cores, $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 || echo 'no nvidia-smi')"
  echo "# PYTHONPATH=.:/tmp/site $python_bin ${command[*]}"
} >"$out/device_check.txt"
PYTHONPATH=.:/tmp/site RAY_AUTH_MODE=disabled "$python_bin" -u "${command[@]}" 2>&1 | tee -a "$out/device_check.txt"
stacked=(benchmarks/stacked_update.py --seeds 1 4 16 64 --seconds 3)
echo "# PYTHONPATH=.:/tmp/site $python_bin ${stacked[*]}" >>"$out/device_check.txt"
PYTHONPATH=.:/tmp/site RAY_AUTH_MODE=disabled "$python_bin" -u "${stacked[@]}" 2>&1 | tee -a "$out/device_check.txt"
stacked_trials=(benchmarks/stacked_trial.py --gpu --stacks 4 16 --iterations 3 --rounds 1)
echo "# PYTHONPATH=.:/tmp/site $python_bin ${stacked_trials[*]}" >>"$out/device_check.txt"
PYTHONPATH=.:/tmp/site RAY_AUTH_MODE=disabled "$python_bin" -u "${stacked_trials[@]}" 2>&1 | tee -a "$out/device_check.txt"
