#!/usr/bin/env bash
# Installs everything (idempotent) and runs the main job on its embedded defaults: a short CO-PILOT
# run on local Ray, tracked in an embedded SQLite MLflow store under results/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_env.sh
export RAY_AUTH_MODE=disabled
mkdir -p results/demo
exec .venv/bin/python -m copilot_ray.train \
  --env maze-point --layout u-maze --tree-depth 3 --repetitions 2 --task-batch-size 10 \
  --stop-env-steps 30000 --eval-tasks 50 --seed 0 \
  --checkpoint-dir results/demo/checkpoint \
  --tracking-uri "sqlite:///$PWD/results/demo/mlflow.db" --experiment copilot-demo "$@"
