#!/usr/bin/env bash
# Creates (or reuses) ./.venv with everything copilot_ray needs. Idempotent: a second run only
# re-installs when pyproject.toml changed.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON_BIN="${PYTHON:-python3.11}"
command -v "$PYTHON_BIN" >/dev/null 2>&1 || PYTHON_BIN=python3
if [ ! -x .venv/bin/python ]; then
  "$PYTHON_BIN" -m venv .venv
fi

stamp=.venv/.copilot_ray-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi

.venv/bin/python -m pip install -q --upgrade pip
# torch first, pinned: the CPU wheel of 2.13.0 is cached on these machines. If another package
# pulled in a plain `torch` requirement first, pip would download a multi-GB CUDA build instead.
.venv/bin/python -m pip install -q "torch==2.13.0"
.venv/bin/python -m pip install -q -e ".[test]"
echo "$want" > "$stamp"
