#!/usr/bin/env bash
# Installs everything (idempotent; one line per step, pip's output in .venv/install.log) and runs
# the main job on its embedded defaults: the demo sweep (sweeps/demo.yaml) on a local Ray, tracked in
# MLflow in results/demo/mlflow.db, then the analysis report of it. A second run continues (or just
# re-reports) the same sweep instead of starting over.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_env.sh
export RAY_AUTH_MODE=disabled
resume=()
if [ -d results/demo/tune ]; then
  resume=(--resume)
fi
.venv/bin/python -m copilot_ray.sweep sweeps/demo.yaml "${resume[@]}" "$@"
.venv/bin/python -m analysis.report demo --tracking-uri "sqlite:///$PWD/results/demo/mlflow.db" \
  --out results/demo/report
