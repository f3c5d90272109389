#!/usr/bin/env bash
# Runs a sweep from a git worktree pinned at one commit, in the background, so that edits to this
# checkout while it runs (hours) cannot leak into its trials, and every trial's MLflow run names that
# commit (tag git_commit). The worktree and its own .venv live beside this checkout:
#
#   bash scripts/run_at_commit.sh [--commit REV] [--spec-from REV2] [--carry STORE.tar.gz|.tar.xz] SPEC.yaml [sweep flags]
#
# --carry: a results archive from another machine or session (made in the old worktree with `python -m
# copilot_ray.carry SPEC.yaml STORE.tar.gz`: the MLflow store, its artifacts and the unfinished parts' Tune
# folders) is unpacked into a new worktree first; with --resume the sweep skips the parts the store
# records finished and continues the unfinished one from its trials' checkpoints. The archive must come
# from the same commit and the same worktree path (checked before anything is made). A second archive
# (another sweep file of the same worktree, with its own store) is unpacked beside the first; one that
# would overwrite a file already there is refused.
#
# --spec-from: SPEC comes from commit REV2 of this checkout, the code from REV. For a part added to an
# experiment whose code must stay at one commit (seeds its seed rule asks for once a part has run):
# SPEC, as committed in REV2, is copied into the worktree (untracked), and a copy there that differs is
# refused, so a resumed part runs the spec it began with. A SPEC that REV holds already is run from REV.
#
# REV defaults to HEAD (which must hold no uncommitted change to copilot_ray/, analysis/ or sweeps/).
# The sweep's output goes to <worktree>/results/<spec name>.log; the results stay in the worktree's
# results/ (resume with the same command plus --resume). Prints the worktree, the log and the PID.
set -euo pipefail
cd "$(dirname "$0")/.."
rev=HEAD
spec_rev=""
carry=""
while [ $# -gt 0 ]; do
  case "$1" in
    --commit) rev="$2"; shift 2 ;;
    --spec-from) spec_rev="$2"; shift 2 ;;
    --carry)
      carry="$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"
      [ -f "$carry" ] || { echo "error: --carry $2 is not a file" >&2; exit 2; }
      shift 2 ;;
    *) break ;;
  esac
done
if [ $# -lt 1 ]; then
  echo "usage: bash scripts/run_at_commit.sh [--commit REV] [--spec-from REV2] [--carry STORE.tar.gz|.tar.xz] SPEC.yaml [sweep flags]" >&2
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
spec_sha="$sha"
if [ -n "$spec_rev" ]; then
  spec_sha="$(git rev-parse --verify --quiet "$spec_rev^{commit}")" || {
    echo "error: --spec-from $spec_rev is not a commit of this repository" >&2
    exit 2
  }
fi
if [ -n "$spec_rev" ] && [ "$spec_sha" = "$(git rev-parse HEAD)" ] && [ -n "$(git status --porcelain -- "$spec")" ]; then
  echo "error: --spec-from $spec_rev: $spec has uncommitted changes; commit them first" >&2
  exit 2
fi
git cat-file -e "$spec_sha:$spec" 2>/dev/null || {
  echo "error: $spec is not in commit ${spec_sha:0:7}" >&2
  exit 2
}
if [ "$spec_sha" != "$sha" ] && git cat-file -e "$sha:$spec" 2>/dev/null; then
  if [ "$(git rev-parse "$sha:$spec")" != "$(git rev-parse "$spec_sha:$spec")" ]; then
    echo "error: --spec-from ${spec_sha:0:7}: commit ${sha:0:7} holds another $spec; name the new part's spec differently" >&2
    exit 2
  fi
  spec_sha="$sha"
fi
tree="$(cd .. && pwd)/$(basename "$PWD")-at-${sha:0:7}"
if [ -n "$carry" ]; then
  # An archive from `python -m copilot_ray.carry` says where and at which commit it was packed: its store
  # continues only at that commit (one experiment, one commit) and at that path (Tune's state and the
  # trials' configs name absolute paths). An archive without that manifest is a store alone.
  manifest="$(tar -tf "$carry" | grep -m1 -E '(^|/)carry\.json$' || true)"
  if [ -n "$manifest" ]; then
    read -r packed_root packed_commit < <(tar -xOf "$carry" "$manifest" |
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
if [ -n "$carry" ] && [ -d "$tree" ]; then
  # Every archive has a manifest (checked above: same commit, same folder); any other file it would
  # overwrite is another sweep's, or this one's newer copy.
  clash="$(tar -tf "$carry" | grep -v '/$' | grep -v -E '(^|/)carry\.json$' |
    while IFS= read -r member; do
      if [ -e "$tree/$member" ]; then echo "$member"; break; fi
    done || true)"
  if [ -n "$clash" ]; then
    echo "error: --carry $carry would overwrite $tree/$clash" >&2
    exit 2
  fi
fi
if [ "$spec_sha" != "$sha" ] && [ -e "$tree/$spec" ]; then
  if ! git show "$spec_sha:$spec" | cmp -s - "$tree/$spec"; then
    # Name the commit whose spec the part began with (a later commit may only have edited a comment).
    began="$(git hash-object "$tree/$spec")"
    hint=""
    for rev in $(git log --format=%H -- "$spec"); do
      if [ "$(git rev-parse -q --verify "$rev:$spec" 2>/dev/null)" = "$began" ]; then
        hint="; it is $spec as committed in ${rev:0:7}: resume with --spec-from ${rev:0:7}"
        break
      fi
    done
    echo "error: --spec-from ${spec_sha:0:7}: $tree/$spec differs from $spec in ${spec_sha:0:7}; a part resumes with the spec it began with$hint" >&2
    exit 2
  fi
fi
if [ ! -d "$tree" ]; then
  git worktree add --detach "$tree" "$sha" >/dev/null
fi
if [ "$spec_sha" != "$sha" ] && [ ! -e "$tree/$spec" ]; then
  mkdir -p "$(dirname "$tree/$spec")"
  git show "$spec_sha:$spec" >"$tree/$spec"
fi
(cd "$tree" && bash scripts/setup_env.sh)
if [ -n "$carry" ]; then
  tar -xf "$carry" -C "$tree"  # gzip or xz: tar reads either
  echo "carried:  $carry -> $tree/results"
fi
log="$tree/results/$(basename "$spec" .yaml).log"
mkdir -p "$tree/results"
cd "$tree"
RAY_AUTH_MODE=disabled nohup .venv/bin/python -m copilot_ray.sweep "$spec" "$@" >>"$log" 2>&1 &
echo "worktree: $tree (commit ${sha:0:7}${spec_rev:+; $spec from ${spec_sha:0:7}})"
echo "log:      $log"
echo "pid:      $!"
