#!/usr/bin/env bash
# Runs a sweep from a git worktree pinned at one commit, in the background, so that edits to this
# checkout while it runs (hours) cannot leak into its trials, and every trial's MLflow run names that
# commit (tag git_commit). The worktree and its own .venv live beside this checkout:
#
#   bash scripts/run_at_commit.sh [--commit REV] SPEC.yaml [sweep flags, e.g. --resume]
#
# REV defaults to HEAD (which must hold no uncommitted change to copilot_ray/, analysis/ or sweeps/).
# The sweep's output goes to <worktree>/results/<spec name>.log; the results stay in the worktree's
# results/ (resume with the same command plus --resume). Prints the worktree, the log and the PID.
set -euo pipefail
cd "$(dirname "$0")/.."
rev=HEAD
if [ "${1:-}" = "--commit" ]; then
  rev="$2"
  shift 2
fi
if [ $# -lt 1 ]; then
  echo "usage: bash scripts/run_at_commit.sh [--commit REV] SPEC.yaml [sweep flags]" >&2
  exit 2
fi
spec="$1"
shift
sha="$(git rev-parse --verify --quiet "$rev^{commit}")" || {
  echo "error: --commit $rev is not a commit of this repository" >&2
  exit 2
}
if [ "$rev" = HEAD ] && [ -n "$(git status --porcelain -- copilot_ray analysis sweeps)" ]; then
  echo "error: uncommitted changes under copilot_ray/, analysis/ or sweeps/: commit them first" >&2
  exit 2
fi
git cat-file -e "$sha:$spec" 2>/dev/null || {
  echo "error: $spec is not in commit ${sha:0:7}" >&2
  exit 2
}
tree="$(cd .. && pwd)/$(basename "$PWD")-at-${sha:0:7}"
if [ ! -d "$tree" ]; then
  git worktree add --detach "$tree" "$sha" >/dev/null
fi
(cd "$tree" && bash scripts/setup_env.sh)
log="$tree/results/$(basename "$spec" .yaml).log"
mkdir -p "$tree/results"
cd "$tree"
RAY_AUTH_MODE=disabled nohup .venv/bin/python -m copilot_ray.sweep "$spec" "$@" >>"$log" 2>&1 &
echo "worktree: $tree (commit ${sha:0:7})"
echo "log:      $log"
echo "pid:      $!"
