#!/usr/bin/env bash
# Creates (or reuses) ./.venv with everything copilot_ray needs. Idempotent: a second run only
# re-installs when pyproject.toml changed.
#
# Quiet: one line per step on the terminal; pip's own output (warnings included) is appended to
# .venv/install.log under a header per step. A failing step prints its name, the log's path and the
# log's last 30 lines, and the script exits with that command's status.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON_BIN="${PYTHON:-python3.11}"
command -v "$PYTHON_BIN" >/dev/null 2>&1 || PYTHON_BIN=python3
LOG=.venv/install.log

# step "what it does" command...: one line on the terminal, the command's output into $LOG.
step() {
  local what="$1" rc=0
  shift
  echo "$what..."
  printf '\n===== %s  %s\n$ %s\n' "$(date '+%Y-%m-%d %H:%M:%S')" "$what" "$*" >>"$LOG"
  "$@" >>"$LOG" 2>&1 || rc=$?
  if [ "$rc" -ne 0 ]; then
    {
      echo "FAILED (exit $rc): $what"
      echo "full output: $PWD/$LOG; its last 30 lines:"
      tail -n 30 "$LOG" | sed 's/^/    /'
    } >&2
    exit "$rc"
  fi
}

mkdir -p .venv
if [ ! -x .venv/bin/python ]; then
  step "creating ./.venv with $PYTHON_BIN" "$PYTHON_BIN" -m venv .venv
fi

stamp=.venv/.copilot_ray-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  echo "./.venv is up to date with pyproject.toml; nothing to install"
  exit 0
fi

pip=(.venv/bin/python -m pip --disable-pip-version-check)
step "upgrading pip" "${pip[@]}" install --progress-bar off --upgrade pip
# torch first, pinned: the CPU wheel of 2.13.0 is cached on these machines. If another package
# pulled in a plain `torch` requirement first, pip would download a multi-GB CUDA build instead.
step "installing torch 2.13.0 (CPU)" "${pip[@]}" install --progress-bar off "torch==2.13.0"
step "installing copilot_ray (editable, with test extras)" "${pip[@]}" install --progress-bar off -e ".[test]"
echo "$want" >"$stamp"
echo "./.venv ready (install log: $LOG)"
