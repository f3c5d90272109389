#!/usr/bin/env bash
# Runs a sweep from a git worktree pinned at one commit, in the background, so that edits to this
# checkout while it runs (hours) cannot leak into its trials, and every trial's MLflow run names that
# commit (tag git_commit). The worktree and its own .venv live beside this checkout:
#
#   bash scripts/run_at_commit.sh [--commit REV] [--carry STORE.tar.gz] SPEC.yaml [sweep flags, e.g. --resume]
#
# --carry: a results archive from another machine or session (made in the old worktree with `python -m
# copilot_ray.carry SPEC.yaml STORE.tar.gz`: the MLflow store, its artifacts and the unfinished parts' Tune
# folders) is unpacked into a new worktree first; with --resume the sweep skips the parts the store
# records finished and continues the unfinished one from its trials' checkpoints. The archive must come
# from the same commit and the same worktree path (checked before anything is made).
#
# REV defaults to HEAD (which must hold no uncommitted change to copilot_ray/, analysis/ or sweeps/).
# The sweep's output goes to <worktree>/results/<spec name>.log; the results stay in the worktree's
# results/ (resume with the same command plus --resume). Prints the worktree, the log and the PID.
set -euo pipefail
cd "$(dirname "$0")/.."
rev=HEAD
carry=""
while [ $# -gt 0 ]; do
  case "$1" in
    --commit) rev="$2"; shift 2 ;;
    --carry)
      carry="$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"
      [ -f "$carry" ] || { echo "error: --carry $2 is not a file" >&2; exit 2; }
      shift 2 ;;
    *) break ;;
  esac
done
if [ $# -lt 1 ]; then
  echo "usage: bash scripts/run_at_commit.sh [--commit REV] [--carry STORE.tar.gz] SPEC.yaml [sweep flags]" >&2
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
if [ -n "$carry" ]; then
  # An archive from `python -m copilot_ray.carry` says where and at which commit it was packed: its store
  # continues only at that commit (one experiment, one commit) and at that path (Tune's state and the
  # trials' configs name absolute paths). An archive without that manifest is a store alone.
  manifest="$(tar -tzf "$carry" | grep -m1 -E '(^|/)carry\.json$' || true)"
  if [ -n "$manifest" ]; then
    read -r packed_root packed_commit < <(tar -xzOf "$carry" "$manifest" |
      python3 -c 'import json, sys; m = json.load(sys.stdin); print(m["root"], m["commit"])')
    if [ "$packed_commit" != "$sha" ]; then
      echo "error: --carry $carry was packed at commit ${packed_commit:0:7}, not ${sha:0:7}: a store continues only at the commit that began it" >&2
      exit 2
    fi
    if [ "$packed_root" != "$tree" ]; then
      echo "error: --carry $carry was packed in $packed_root; its Tune state resumes only there, and this checkout would put it in $tree" >&2
      exit 2
    fi
  fi
fi
if [ ! -d "$tree" ]; then
  git worktree add --detach "$tree" "$sha" >/dev/null
fi
(cd "$tree" && bash scripts/setup_env.sh)
if [ -n "$carry" ]; then
  if [ -d "$tree/results" ] && [ -n "$(ls -A "$tree/results" 2>/dev/null)" ]; then
    echo "error: --carry: $tree/results is not empty; the carried store would overwrite it" >&2
    exit 2
  fi
  tar -xzf "$carry" -C "$tree"
  echo "carried:  $carry -> $tree/results"
fi
log="$tree/results/$(basename "$spec" .yaml).log"
mkdir -p "$tree/results"
cd "$tree"
RAY_AUTH_MODE=disabled nohup .venv/bin/python -m copilot_ray.sweep "$spec" "$@" >>"$log" 2>&1 &
echo "worktree: $tree (commit ${sha:0:7})"
echo "log:      $log"
echo "pid:      $!"
