#!/usr/bin/env bash
# Installs what the tests need (idempotent; one line per step, pip's output in .venv/install.log)
# and runs lint + the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_env.sh
export RAY_AUTH_MODE=disabled
.venv/bin/ruff check .
.venv/bin/python -m pytest -q "$@"
