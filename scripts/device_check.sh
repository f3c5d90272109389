#!/usr/bin/env bash
# The GPU check in one call of a lent GPU machine (an H200, 16 cores, Python 3.12 with torch and no
# network; docs/throughput/device.md is the recipe): at most 8 minutes of command, every step capped by
# `timeout`, one line for every figure at the end (benchmarks/device_figures.py: measured, or why not).
#
#   bash scripts/device_check.sh [OUT]            (default OUT: $OUT, else ./device_check_out)
#
# The steps, in the order their figures matter (each one's cap in the STEPS table below; a step that
# fails or is cut says so, in its line of OUT/steps.jsonl, and the next one runs):
#   install         the carried wheels (device_wheels/, scripts/gather_device_wheels.sh) into /tmp/site
#   stacked_update  the stacked SAC update alone, N = 1, 16, 64, eager and captured (stacked_update.py)
#   trials          the update alone (no compiler) and its captured agreement, then two CO-PILOT trials
#                   sharing the GPU beside a CPU twin and a CPU trial on the old paths (device_throughput.py)
#   sweep           sweeps/device_stacked.yaml: 2 configurations x 16 seeds stacked per trial, tracked in
#                   MLflow, from /tmp/copilot_device_sweep (benchmarks/device_sweep.py); SIGTERM 45 s
#                   before its cap, so that Tune saves its state and stops the trials within it
#   pack            its store by `python -m copilot_ray.carry` into OUT/device_sweep.tar.gz (--report-only
#                   when the in-flight archive is over 15 MiB: a file back from OUT is at most 16 MiB)
#   stacked_trial   one seed's trial alone on the GPU, then 64 seeds stacked in one trial (stacked_trial.py)
#   compile         the compiled + captured update and its agreement (minutes of compiling: last)
#   figures         every figure's line, OUT/device_figures.json, and where a GPU trial measured a rate
#                   the GPU section of measured_throughput.json (copied to OUT) and depth_k's GPU plan
#
# Where torch sees no CUDA device (a rehearsal, docs/throughput/device_rehearsal.txt) the same steps
# run: nothing is installed, every import is limited to what the GPU machine will have
# (scripts/device_image/sitecustomize.py, enforce), the GPU rows say `skipped: no CUDA device`, the sweep
# is its 2-seed CPU cut from /tmp/copilot_device_sweep_cpu, and trials take 1 CPU each on a small machine.
# OUT gets at most 8 files (what a call brings back): device_check.txt (everything printed),
# steps.jsonl, figures.jsonl, trials.jsonl, device_sweep.tar.gz, device_figures.json and, with a GPU
# rate, measured_throughput.json. Exit 0 once the steps ran (their failures are lines); 2 when the wheels
# cannot be installed.
set -uo pipefail
cd "$(dirname "$0")/.."
repo="$PWD"
out="${1:-${OUT:-$repo/device_check_out}}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
python_bin="$(command -v "${PYTHON:-python3}")" || { echo "error: no ${PYTHON:-python3} here" >&2; exit 2; }
case "$python_bin" in /*) ;; *) python_bin="$repo/$python_bin" ;; esac # steps run from other folders
TOTAL=480 # seconds: the whole command (a call's 10 minutes less the machine's start and the transfers)

# STEPS: name and cap in seconds; their sum is at most TOTAL (tests/test_device_check.py checks).
STEPS=(
  "install 40"
  "stacked_update 40"
  "trials 110"
  "sweep 165"
  "pack 30"
  "stacked_trial 35"
  "compile 35"
  "figures 20"
)
declare -A CAP
for entry in "${STEPS[@]}"; do CAP[${entry% *}]=${entry#* }; done

log="$out/device_check.txt"
steps="$out/steps.jsonl"
: >"$steps"
: >"$out/figures.jsonl"
: >"$out/trials.jsonl"
rm -f "$out/device_sweep.tar.gz" "$out/device_figures.json" "$out/measured_throughput.json"
started=$SECONDS
export RAY_AUTH_MODE=disabled PYTHONUNBUFFERED=1

say() { echo "$*" | tee -a "$log"; }
record() { echo "$1" >>"$steps"; }

# step NAME COMMAND...: runs COMMAND (a shell string) under its cap, its output into the log, and records
# its exit status (124 or 137: cut at the cap) and seconds.
step() {
  local name="$1" command="$2" cap="${CAP[$1]}" t0=$SECONDS rc
  say "# step $name (cap $cap s, $((SECONDS - started)) s so far): $command"
  timeout --signal INT --kill-after 10 "$((cap - 10))" bash -c "$command" 2>&1 | tee -a "$log"
  rc=${PIPESTATUS[0]}
  [ "$rc" = 0 ] || say "# step $name: exit status $rc$([ "$rc" = 124 ] || [ "$rc" = 137 ] && echo " (cut at $cap s)")"
  record "{\"step\": \"$name\", \"cap_s\": $cap, \"rc\": $rc, \"seconds\": $((SECONDS - t0))}"
  return 0
}
skip() { # skip NAME WHY
  say "# step $1: skipped: $2"
  record "{\"step\": \"$1\", \"cap_s\": ${CAP[$1]}, \"skipped\": \"$2\"}"
}

echo "# $(date -u '+%Y-%m-%d %H:%M UTC'), commit ${COMMIT:-$(git rev-parse --short HEAD 2>/dev/null || echo unknown)}, $(nproc) cores, $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 || echo 'no nvidia-smi')" >"$log"
cuda=$("$python_bin" -c "import torch; print(int(torch.cuda.is_available()))" 2>/dev/null || echo 0)
cpus=$(nproc)
if [ "$cuda" = 1 ]; then
  say "# cuda: yes ($("$python_bin" -c 'import torch; print(torch.cuda.get_device_name(0), "torch", torch.__version__)'))"
  pythonpath="$repo:/tmp/site"
  sweep_root=/tmp/copilot_device_sweep
  prepare=""
else
  say "# cuda: no: a rehearsal (GPU rows skipped; imports limited to the GPU image's packages and the carried wheels)"
  pythonpath="$repo/scripts/device_image:$repo"
  export DEVICE_IMPORT_GUARD=enforce DEVICE_IMPORT_LOG=/tmp/device_check_imports.$$.log
  sweep_root=/tmp/copilot_device_sweep_cpu
  prepare="--cpu"
fi
record "{\"step\": \"machine\", \"cuda\": $([ "$cuda" = 1 ] && echo true || echo false), \"cores\": $cpus}"
export PYTHONPATH="$pythonpath"
per_trial=2
[ "$cpus" -ge 8 ] || per_trial=1 # two CPU trials side by side on a two-core machine
py="$python_bin -u"

# ---------------------------------------------------------------------------------------------- install
if [ "$cuda" = 1 ]; then
  if ! "$python_bin" -c "import lzma" 2>/dev/null; then
    say "error: this Python has no lzma module: the carried wheels' large members are LZMA (gather_device_wheels.sh)"
    exit 2
  fi
  ls device_wheels/*.whl >/dev/null 2>&1 || {
    say "error: no device_wheels/*.whl here: run scripts/gather_device_wheels.sh and carry device_wheels"
    exit 2
  }
  step install "$python_bin -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site device_wheels/*.whl && $python_bin -c 'import ray, mlflow, gymnasium; print(\"installed: ray\", ray.__version__, \"mlflow\", mlflow.__version__)'"
  if ! "$python_bin" -c "import ray, mlflow" 2>/dev/null; then
    say "error: the wheels did not install (see above)"
    exit 2
  fi
else
  skip install "no CUDA device (a rehearsal uses this checkout's environment)"
fi

# ------------------------------------------------------------------------------------- stacked update
step stacked_update "$py benchmarks/stacked_update.py --seeds 1 16 64 --seconds 2 --threads $per_trial"

# --------------------------------------------------------------------------------------------- trials
step trials "$py benchmarks/device_throughput.py --update-paths plain --updates-seconds 3 --trials 2 \
  --gpus-per-trial 0.5 --cpu-baseline --batches-baseline --cpus-per-trial $per_trial --seconds 40 \
  --warm-start 5 --set tree_depth=3 --log $out/trials.jsonl --figures $out/figures.jsonl"
if [ -s "$out/trials.jsonl" ]; then # the trials' iterations as logged: the figures of a step cut off
  say "# the trial step's log, summarised: $py benchmarks/device_throughput.py --summarise $out/trials.jsonl"
  $py benchmarks/device_throughput.py --summarise "$out/trials.jsonl" 2>&1 | tee -a "$log"
else
  say "# the trial step logged no iteration"
fi

# ---------------------------------------------------------------------------------------------- sweep
rm -rf "$sweep_root"
$py benchmarks/device_sweep.py prepare "$sweep_root" $prepare >>"$log" 2>&1
step sweep "cd $sweep_root && timeout --signal TERM --kill-after 25 $((CAP[sweep] - 45)) $py -m copilot_ray.sweep device_stacked.yaml"

# ----------------------------------------------------------------------------------------------- pack
step pack "$py benchmarks/device_sweep.py pack $sweep_root $out/device_sweep.tar.gz --figures $out/figures.jsonl"

# -------------------------------------------------------------------------------------- stacked trial
if [ "$cuda" = 1 ]; then
  step stacked_trial "$py benchmarks/stacked_trial.py --gpu --stacks 64 --iterations 1 --rounds 1 --layout four-rooms"
else
  skip stacked_trial "no CUDA device"
fi

# -------------------------------------------------------------------------------------------- compile
if [ "$cuda" = 1 ]; then
  step compile "$py benchmarks/device_throughput.py --updates-only --update-paths compiled --updates-seconds 3 --figures $out/figures.jsonl"
else
  skip compile "no CUDA device"
fi

# -------------------------------------------------------------------------------------------- figures
step figures "$py benchmarks/device_figures.py $out --write"
if [ "$cuda" != 1 ] && [ -s "${DEVICE_IMPORT_LOG:-/nonexistent}" ]; then
  say "# imports the GPU machine would refuse (processes, distribution, module, as the guard saw them; each one's caller went on without it):"
  cut -f2,3 "$DEVICE_IMPORT_LOG" | sort | uniq -c | tee -a "$log"
  rm -f "$DEVICE_IMPORT_LOG"
fi
say "# done in $((SECONDS - started)) s of at most $TOTAL; OUT: $out ($(ls "$out" | tr '\n' ' '))"
exit 0
