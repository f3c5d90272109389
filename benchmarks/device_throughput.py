"""Env steps/s of trials on a CPU or a GPU share, side by side, without Tune or MLflow; and the SAC update
alone on each device and path.

    PYTHONPATH=. python benchmarks/device_throughput.py --suite [--log FILE.jsonl]

is the one-command GPU check (at most 8 minutes on a 16-core one-GPU machine, about 6): the update alone
(`--updates-seconds` 8 per row), then a lone CO-PILOT trial with its learner on the GPU beside its CPU
twin and a CPU trial on the paths before this checkout's (`--seconds` 120, `--warm-start` 20). On a
machine without a GPU it runs the CPU rows and says, one line each, which GPU rows it skipped (on two
cores: `--suite --cpus-per-trial 1`, the two CPU trials side by side).

    PYTHONPATH=. python benchmarks/device_throughput.py [--algorithm copilot] [--trials 1]
        [--gpus-per-trial 1] [--cpus-per-trial 2] [--cpu-baseline] [--batches-baseline] [--seconds 180]
        [--eval-every 3200] [--updates-seconds 0] [--log FILE.jsonl]
    PYTHONPATH=. python benchmarks/device_throughput.py --summarise FILE.jsonl

The update alone (`--updates-seconds` > 0): SAC gradient steps of the trial's learner (256x256 networks,
batch 256, random four-rooms-sized transitions: obs 4, action 2) in this process, per device and path:
"batches" (RLlib's `update(batch=...)` from the replay sampled on the host, the finite check on the host: the path before
the fused update), "fused eager" (`update_from_replay`: the step and its replay sampling on the device,
no host sync), and on a GPU "fused captured" (one CUDA graph replay per step) and "fused compiled +
captured" (torch.compile'd first). Each row warms up (capture, compilation: its seconds printed), then
runs calls of 64 steps for the given seconds; a row that fails prints its error and the rest go on. On
a GPU two more lines say whether the captured and the compiled + captured update agree with the eager
one over 8 steps from the same parameters, replay and seed.

Each trial is a Ray actor holding `--cpus-per-trial` CPUs (torch's threads follow them) and
`--gpus-per-trial` of a GPU (0: the CPU; fractions share one card, as Tune's trials would), that builds
the algorithm from the registry at its defaults on maze-point `--layout` with
`resources.gpus_per_trial`'s learner placement, and trains until `--seconds` have passed and it has done
at least 3 iterations. `--cpu-baseline` adds one trial on `--cpus-per-trial` CPUs and no GPU, run beside
the others, so a GPU's multiple is measured on the same machine at the same moment; `--batches-baseline`
one more CPU trial on the paths before the fused update and the lean traversal loop ("cpu before":
`fused_update=False`, `lean_traversal=False`: RLlib's batches and env runner). The first iteration
(the algorithm starting, CO-PILOT's planner warm start) is left out of the rates.

Prints, per trial kind: env steps/s per trial and in aggregate, SAC updates/s, the shares of wall time
per phase and what each costs per env step in ms (the algorithm's own `copilot/time/*` timers: "agent"
is the traversal less its SAC updates, i.e. env steps, the policy's forward passes, the replay's adds
and the weight sync; "other" is the rest: Ray and result building),
trials per hour at `--budget` env steps, and the learner's device as the trial saw it. What this leaves
out against `benchmarks/throughput.py`: Tune's and MLflow's per-iteration costs (under 1 % there), and
it needs neither installed beyond Ray's own Tune imports.

`--log` appends every iteration of every trial to a JSON-lines file as it ends, so a run cut off (a
machine lent for minutes) keeps what it measured: `--summarise FILE` prints the same summary from it,
from each trial's iterations so far (a trial needs 2 to have a rate).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from throughput import PHASES, phase_shares  # noqa: E402  (the same phases and shares as the Tune benchmark)


def _config(
    algorithm: str,
    layout: str,
    eval_every: int,
    warm_start,
    seed: int,
    cpus: int,
    gpus: float,
    current=True,
    settings: dict | None = None,
):
    from copilot_ray.registry import RunContext, get_algorithm

    run = RunContext(
        env_id="maze-point",
        env_config={"layout": layout},
        seed=seed,
        num_cpus_for_main_process=cpus,
        num_gpus=gpus,
    )
    values = {"eval_every_env_steps": eval_every, "eval_num_tasks": 100}
    if algorithm == "copilot":
        values["eval_tree_tasks"] = 0  # no tree snapshots written to disk per evaluation
        if warm_start is not None:
            values["planner_warm_start"] = warm_start
    if not current:
        # The paths before the fused update and the lean loop: RLlib's batches and env runner.
        values.update(fused_update=False, lean_traversal=False)
    values.update(settings or {})
    return get_algorithm(algorithm).build_config(values, run)


class Trial:
    """One algorithm in one actor: builds it, trains it for a while, returns per-iteration records."""

    def __init__(
        self,
        algorithm,
        layout,
        eval_every,
        warm_start,
        seed,
        cpus,
        gpus,
        kind,
        log,
        current=True,
        settings=None,
    ):
        self.algo = _config(
            algorithm, layout, eval_every, warm_start, seed, cpus, gpus, current, settings
        ).build_algo()
        self.label = {"kind": kind, "trial": seed}
        self.log = log

    def device(self) -> str:
        import torch

        learner = self.algo.learner_group._learner
        module = next(iter(learner.module._rl_modules.values()))
        return f"{next(module.parameters()).device} (torch threads {torch.get_num_threads()})"

    def train_for(self, seconds: float, min_iterations: int = 3) -> list[dict]:
        from copilot_ray import keys

        records, started = [], time.perf_counter()
        while time.perf_counter() - started < seconds or len(records) < min_iterations:
            t0 = time.perf_counter()
            result = self.algo.train()
            wall = time.perf_counter() - t0
            record = {
                "env_steps": float(keys.result_value(result, keys.ENV_STEPS) or 0.0),
                "wall_s": wall,
                "updates": float(keys.result_value(result, keys.AGENT_SAC_UPDATES) or 0.0),
            }
            for p in PHASES:
                record[p] = float(keys.result_value(result, keys.TIME_PREFIX + p) or 0.0)
            records.append(record)
            if self.log:
                with open(self.log, "a") as f:  # one short line per write: appends do not interleave
                    f.write(json.dumps({**self.label, "device": self.device(), **record}) + "\n")
        return records


def rates(records: list[dict]) -> dict | None:
    """Env steps/s (with and without the evaluation phase), updates/s and phase shares over the iterations
    after the first (None: fewer than 2)."""
    if len(records) < 2:
        return None
    later = records[1:]
    wall = sum(r["wall_s"] for r in later)
    steps = records[-1]["env_steps"] - records[0]["env_steps"]
    spent = {p: sum(r[p] for r in later) for p in PHASES}
    evaluation = spent["eval_s"]
    return {
        "env_steps_per_s": steps / wall,
        # the same iterations less their evaluation phase: the rate a trial evaluating less often tends to
        "env_steps_per_s_without_eval": steps / (wall - evaluation) if wall > evaluation else None,
        "updates_per_s": sum(r["updates"] for r in later) / wall,
        "shares": phase_shares(spent, wall),
        "iterations": len(later),
        "first_iteration_s": records[0]["wall_s"],
    }


UPDATE_BATCH = 256
UPDATE_STEPS_PER_CALL = 64


# `--update-paths`: "plain" rows need no compiler (seconds to warm up); "compiled" ones compile first
# (a minute or more on a GPU), so a check runs them after the trials.
UPDATE_PATHS = {
    "plain": [
        ("cpu", "batches"),
        ("cpu", "fused eager"),
        ("cuda", "batches"),
        ("cuda", "fused eager"),
        ("cuda", "fused captured"),
    ],
    "compiled": [("cuda", "fused compiled + captured")],
}
UPDATE_PATHS["all"] = UPDATE_PATHS["plain"] + UPDATE_PATHS["compiled"]
AGREEMENT_PATHS = {"plain": ["fused captured"], "compiled": ["fused compiled + captured"]}
AGREEMENT_PATHS["all"] = AGREEMENT_PATHS["plain"] + AGREEMENT_PATHS["compiled"]


def _figure(figures: str | None, **record) -> None:
    """One JSON line per figure as it is measured (`--figures`): what benchmarks/device_figures.py reads,
    so a run cut off keeps every row it finished."""
    if figures:
        with open(figures, "a") as f:
            f.write(json.dumps({"source": "device_throughput", **record}) + "\n")


def _first_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"


def update_rows(seconds: float, threads: int, paths: str = "all", figures: str | None = None) -> list[str]:
    """The SAC update alone, per device and path (module docstring): one printed line per row."""
    import torch

    rows = [(d, p) for d, p in UPDATE_PATHS[paths] if d == "cpu" or torch.cuda.is_available()]
    lines = []
    if not torch.cuda.is_available() and any(d == "cuda" for d, _ in UPDATE_PATHS[paths]):
        lines.append("update alone on the GPU: skipped: no CUDA device (torch sees none on this machine)")
        print(lines[-1], flush=True)
    for device, path in rows:
        try:
            line, rate, warm = _update_row(device, path, seconds, threads)
            _figure(figures, figure="update alone", device=device, path=path, updates_per_s=rate, warm_s=warm)
        except Exception as exc:  # one failing row (e.g. a compiler missing) must not lose the others
            line = f"update alone, {device}, {path}: failed: {_first_line(exc)}"
            _figure(figures, figure="update alone", device=device, path=path, error=_first_line(exc))
        lines.append(line)
        print(line, flush=True)
    return lines


def agreement_rows(threads: int, paths: str = "all", figures: str | None = None) -> list[str]:
    """On a GPU: the captured (and compiled + captured) fused update against the eager one, from the same
    parameters, replay and seed, over 8 steps (3 eager warm-up calls, the capture, 4 replays): the largest
    parameter difference, which float noise keeps far below 1e-3."""
    import torch

    if not torch.cuda.is_available():
        return []
    lines = []
    for path in AGREEMENT_PATHS[paths]:
        try:
            diff = _largest_difference("fused eager", path, threads)
            verdict = "agrees" if diff < 1e-3 else "DISAGREES"
            line = f"{path} against fused eager on the GPU, 8 steps: {verdict} (largest parameter difference {diff:.2e})"
            _figure(figures, figure="agreement", path=path, largest_difference=diff, agrees=diff < 1e-3)
        except Exception as exc:
            line = f"{path} against fused eager on the GPU: failed: {_first_line(exc)}"
            _figure(figures, figure="agreement", path=path, error=_first_line(exc))
        lines.append(line)
        print(line, flush=True)
    return lines


def _largest_difference(reference: str, path: str, threads: int) -> float:
    import torch
    import torch._inductor.config

    # Compiled random ops draw their own numbers unless told to call eager's: same noise, same result.
    torch._inductor.config.fallback_random = True
    params = {}
    state = None
    for name in (reference, path):
        learner_group, replay = _update_setup("cuda", name, threads)
        learner = learner_group._learner
        if state is None:
            state = learner_group.get_state()
        else:
            learner_group.set_state(state)
        torch.manual_seed(0)
        learner.update_from_replay(replay, 8, UPDATE_BATCH, {})
        module = next(iter(learner.module._rl_modules.values()))
        params[name] = [p.detach().clone() for p in module.state_dict().values()]
    return max(float((a - b).abs().max()) for a, b in zip(params[reference], params[path], strict=True))


def _update_setup(device: str, path: str, threads: int):
    """A learner group of the trial's learner on `device` for `path`, and its replay filled with random
    four-rooms-sized transitions (on the host for "batches", else on the learner's device)."""
    import numpy as np
    from gymnasium import spaces
    from ray.rllib.algorithms.sac import SACConfig

    from copilot_ray.algorithms.gc_sac import FlatTransitionBuffer, use_fast_learner

    config = use_fast_learner(
        SACConfig()
        .environment(
            observation_space=spaces.Box(0.0, 1.0, (4,), np.float32),
            action_space=spaces.Box(-1.0, 1.0, (2,), np.float32),
        )
        .learners(num_gpus_per_learner=1 if device == "cuda" else 0)
        .debugging(seed=0),
        torch_threads=threads,
        fused_update=path != "batches",
        cuda_graph="captured" in path,
        compile_update="compiled" in path,
    )
    learner_group = config.build_learner_group()
    rng = np.random.default_rng(0)
    n = 100_000
    obs = rng.uniform(0, 1, (n, 4)).astype(np.float32)
    columns = {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.02, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        "rewards": -(rng.random(n) > 0.05).astype(np.float32),
        "terminateds": rng.random(n) < 0.05,
    }
    replay = FlatTransitionBuffer(n, device="cpu" if path == "batches" else learner_group._learner.device)
    replay.add(columns)
    return learner_group, replay


def _update_row(device: str, path: str, seconds: float, threads: int) -> tuple[str, float, float]:
    import torch

    from copilot_ray.algorithms.gc_sac import host_sampler, update_from_buffer

    learner_group, replay = _update_setup(device, path, threads)
    learner = learner_group._learner
    sample = host_sampler(replay)
    if path == "batches":

        def call() -> None:
            update_from_buffer(learner_group, sample, UPDATE_STEPS_PER_CALL, UPDATE_BATCH, len(replay))
    else:

        def call() -> None:
            learner.update_from_replay(replay, UPDATE_STEPS_PER_CALL, UPDATE_BATCH, {})

    def synchronised() -> float:
        if learner.device.type == "cuda":
            torch.cuda.synchronize(learner.device)
        return time.perf_counter()

    t0 = synchronised()
    for _ in range(2):  # warm-up: RLlib's lazy state, the capture, the compilation
        call()
    warm = synchronised() - t0
    steps, t0 = 0, synchronised()
    while synchronised() - t0 < seconds:
        call()
        steps += UPDATE_STEPS_PER_CALL
    rate = steps / (synchronised() - t0)
    name = (
        torch.cuda.get_device_name(learner.device) if learner.device.type == "cuda" else f"{threads} threads"
    )
    line = (
        f"update alone, {device} ({name}), {path}: {rate:.0f} updates/s ({1000 / rate:.2f} ms each; "
        f"{steps} steps in {seconds:.0f} s, warm-up {warm:.1f} s)"
    )
    return line, rate, warm


def _cuda_available() -> bool:
    import torch

    return torch.cuda.is_available()


# What --suite sets (unless the command line sets it too).
SUITE = {
    "updates_seconds": 8.0,
    "trials": 1,
    "gpus_per_trial": 1.0,
    "cpu_baseline": True,
    "batches_baseline": True,
    "seconds": 120.0,
    "warm_start": 20,
}


def _setting(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE")
    import yaml

    return key, yaml.safe_load(value)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algorithm", default="copilot", help="a registered RLlib algorithm (default copilot)")
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--trials", type=int, default=1, help="trials on --gpus-per-trial (default 1)")
    p.add_argument("--gpus-per-trial", type=float, default=0.0, help="0: the CPU (default 0)")
    p.add_argument("--cpus-per-trial", type=int, default=2)
    p.add_argument("--cpu-baseline", action="store_true", help="one more trial on the CPU, beside them")
    p.add_argument(
        "--batches-baseline",
        action="store_true",
        help="one more CPU trial on the paths before the fused update and the lean traversal loop, beside them",
    )
    p.add_argument(
        "--updates-seconds", type=float, default=0.0, help="time the update alone, per row (0: not at all)"
    )
    p.add_argument(
        "--update-paths",
        choices=sorted(UPDATE_PATHS),
        default="all",
        help="the update-alone rows: plain (no compiler), compiled (torch.compile first), or all (default)",
    )
    p.add_argument("--updates-only", action="store_true", help="the update-alone rows only: no trials")
    p.add_argument(
        "--suite",
        action="store_true",
        help="the one-command GPU check: --updates-seconds 8 --trials 1 --gpus-per-trial 1 --cpu-baseline "
        "--batches-baseline --seconds 120 --warm-start 20 (flags given after it still count)",
    )
    p.add_argument("--seconds", type=float, default=180.0, help="train each trial at least this long")
    p.add_argument("--eval-every", type=int, default=3200, help="env steps between evaluations")
    p.add_argument(
        "--warm-start",
        type=int,
        default=None,
        help="CO-PILOT's planner_warm_start (phases before the first env step, in the first iteration only, "
        "which the rates leave out; default: the setting's own, 1000, ~100 s)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        type=_setting,
        metavar="KEY=VALUE",
        help="an algorithm setting for every trial (repeatable; e.g. tree_depth=3: shorter iterations, so a "
        "trial cut off after a minute still has a rate)",
    )
    p.add_argument("--budget", type=int, default=200_000, help="env steps per trial for trials/hour")
    p.add_argument("--log", default=None, help="append every trial's iterations to this JSON-lines file")
    p.add_argument(
        "--figures",
        default=None,
        metavar="FILE",
        help="append every update-alone row as a JSON line (benchmarks/device_figures.py reads it)",
    )
    p.add_argument(
        "--summarise", default=None, metavar="FILE", help="print the summary of a --log file; run nothing"
    )
    args = p.parse_args(argv)
    if args.suite:
        given = set(argv if argv is not None else sys.argv[1:])
        for flag, value in SUITE.items():
            if f"--{flag.replace('_', '-')}" not in given:
                setattr(args, flag, value)
    if args.summarise is not None and not os.path.isfile(args.summarise):
        print(f"error: --summarise {args.summarise!r} is invalid: no such file", file=sys.stderr)
        raise SystemExit(2)
    bad = [
        (f"--{k.replace('_', '-')}", v, need)
        for k, v, ok, need in (
            ("trials", args.trials, args.trials >= 1, "an integer >= 1"),
            ("gpus_per_trial", args.gpus_per_trial, args.gpus_per_trial >= 0, "a number >= 0"),
            ("cpus_per_trial", args.cpus_per_trial, args.cpus_per_trial >= 1, "an integer >= 1"),
            ("seconds", args.seconds, args.seconds > 0, "a number > 0"),
            ("updates_seconds", args.updates_seconds, args.updates_seconds >= 0, "a number >= 0"),
            ("eval_every", args.eval_every, args.eval_every >= 1, "an integer >= 1"),
            ("budget", args.budget, args.budget >= 1, "an integer >= 1"),
        )
        if not ok
    ]
    # GPU trials only count where they run (without a GPU they are skipped, saying so).
    trials = args.trials if args.gpus_per_trial == 0 or _cuda_available() else 0
    cpus = args.cpus_per_trial * (trials + int(args.cpu_baseline) + int(args.batches_baseline))
    if args.updates_only:
        cpus = 0
    if args.cpus_per_trial >= 1 and cpus > (os.cpu_count() or 1):
        bad.append(
            ("--cpus-per-trial", args.cpus_per_trial, f"trials x CPUs ({cpus}) over {os.cpu_count()} cores")
        )
    if args.gpus_per_trial * args.trials > 1 + 1e-9:
        bad.append(("--gpus-per-trial", args.gpus_per_trial, "over one GPU in all (this runs on one card)"))
    for flag, value, need in bad:
        print(f"error: {flag} {value!r} is invalid: must be {need}", file=sys.stderr)
    if bad:
        raise SystemExit(2)
    return args


def summary_lines(
    by_trial: dict[tuple[str, int], list[dict]], devices: dict, budget: int, errors: dict | None = None
) -> list[str]:
    """Per trial kind (in the order met): the rates of its trials that have one, and those that do not;
    a trial that raised is named with its error, and its kind's other trials keep their figures."""
    errors = errors or {}
    lines = []
    for kind in dict.fromkeys(k for k, _ in [*by_trial, *errors]):
        trials = {t: r for (k, t), r in by_trial.items() if k == kind}
        rows = [x for x in (rates(r) for r in trials.values()) if x is not None]
        short = sorted(t for t, r in trials.items() if len(r) < 2)
        seen = sorted({devices[(kind, t)] for t in trials if (kind, t) in devices})
        head = f"{kind}: {len(trials)} trial(s), learner on {', '.join(seen) or '?'}"
        for (k, t), error in sorted(errors.items()):
            if k == kind:
                lines.append(f"{kind}: trial {t} failed: {error}")
        if not rows:
            lines.append(f"{head}: no rate (no trial finished 2 iterations)")
            continue
        without = [r["env_steps_per_s_without_eval"] for r in rows if r["env_steps_per_s_without_eval"]]
        per_trial = statistics.mean(r["env_steps_per_s"] for r in rows)
        aggregate = per_trial * len(trials)  # the trials without a rate ran too: count them at the mean
        shares = {p: statistics.mean(r["shares"][p] for r in rows) for p in rows[0]["shares"]}
        lines.append(
            f"{head}: {per_trial:.0f} env steps/s per trial (min {min(r['env_steps_per_s'] for r in rows):.0f}"
            + (f"; without evaluation {statistics.mean(without):.0f}" if without else "")
            + f"), {aggregate:.0f} in aggregate, "
            f"{statistics.mean(r['updates_per_s'] for r in rows):.0f} SAC updates/s per trial, "
            f"{aggregate * 3600 / budget:.2f} trials/hour at {budget} env steps; "
            f"iterations measured {min(r['iterations'] for r in rows)}-{max(r['iterations'] for r in rows)}, "
            f"first iteration {statistics.mean(r['first_iteration_s'] for r in rows):.0f} s"
            + (f"; {len(short)} trial(s) without 2 iterations, counted at the mean" if short else "")
        )
        ms = 1000.0 / statistics.mean(r["env_steps_per_s"] for r in rows)  # wall time per env step
        lines.append(
            "   shares: "
            + ", ".join(f"{p.removesuffix('_s')} {v:.0%}" for p, v in shares.items())
            + f"; per env step {ms:.2f} ms: "
            + ", ".join(f"{p.removesuffix('_s')} {v * ms:.2f}" for p, v in shares.items())
        )
    return lines


def read_log(path: str) -> tuple[dict[tuple[str, int], list[dict]], dict, dict]:
    """A --log file back as {(kind, trial): records in order}, {(kind, trial): device} and
    {(kind, trial): error} for the trials that raised."""
    by_trial: dict[tuple[str, int], list[dict]] = {}
    devices, errors = {}, {}
    with open(path) as f:
        for line in f:
            if not line.strip():
                continue
            row = json.loads(line)
            key = (row.pop("kind"), int(row.pop("trial")))
            if "error" in row:  # the trial raised: its iterations so far stay, the error is said
                errors[key] = row["error"]
                by_trial.setdefault(key, [])
                continue
            devices[key] = row.pop("device")
            by_trial.setdefault(key, []).append(row)
    return by_trial, devices, errors


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.summarise is not None:
        by_trial, devices, errors = read_log(args.summarise)
        print("\n".join(summary_lines(by_trial, devices, args.budget, errors)))
        return 0
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    import ray
    import torch

    started = time.perf_counter()
    has_gpu = torch.cuda.is_available()
    print(
        f"machine: {os.cpu_count()} CPU cores, "
        + (f"GPU {torch.cuda.get_device_name(0)}" if has_gpu else "no GPU visible to torch")
        + f"; torch {torch.__version__}, ray {ray.__version__}",
        flush=True,
    )
    if args.updates_seconds > 0:
        update_rows(args.updates_seconds, args.cpus_per_trial, args.update_paths, args.figures)
        agreement_rows(args.cpus_per_trial, args.update_paths, args.figures)
        print(f"({time.perf_counter() - started:.0f} s so far)", flush=True)
    if args.updates_only:
        return 0
    gpus = args.gpus_per_trial if has_gpu else 0.0
    kinds = []
    if args.gpus_per_trial > 0 and not has_gpu:
        print(f"gpu trial(s): skipped: no CUDA device (torch sees none on this machine; {args.trials} asked)")
    else:
        kinds.append(("gpu" if gpus > 0 else "cpu", gpus, args.trials, True))
    if args.cpu_baseline:
        kinds.append(("cpu baseline", 0.0, 1, True))
    if args.batches_baseline:
        kinds.append(("cpu before", 0.0, 1, False))
    if not kinds:
        return 0
    ray.init(
        num_cpus=os.cpu_count(),
        num_gpus=1 if gpus > 0 else None,
        include_dashboard=False,
        log_to_driver=False,
    )
    try:
        by_trial, devices, errors, wall = run_trials(args, kinds)
    finally:
        ray.shutdown()
    print(
        f"{args.algorithm} on maze-point {args.layout}, evaluation every {args.eval_every} env steps "
        f"(100 validation + 100 test tasks), {args.cpus_per_trial} CPUs per trial"
        + "".join(f", {k}={v}" for k, v in args.set)
        + f"; {wall:.0f} s of training, "
        f"{time.perf_counter() - started:.0f} s in all"
    )
    print("\n".join(summary_lines(by_trial, devices, args.budget, errors)))
    return 0


def run_trials(args, kinds) -> tuple[dict, dict, dict, float]:
    """Every kind's trials as actors, side by side, each until `--seconds` have passed: (records by
    trial, devices, errors, wall seconds). A trial that raises (its actor lost, a CUDA error) is an error
    of its own, said as it happens and written to the log; the others' figures stay."""
    import ray

    log = args.log and os.path.abspath(args.log)
    actors = []
    for kind, kind_gpus, n, current in kinds:
        remote = ray.remote(num_cpus=args.cpus_per_trial, num_gpus=kind_gpus)(Trial)
        for i in range(n):
            actor = remote.remote(
                args.algorithm,
                args.layout,
                args.eval_every,
                args.warm_start,
                i,
                args.cpus_per_trial,
                kind_gpus,
                kind,
                log,
                current,
                dict(args.set),
            )
            actors.append(((kind, i), actor))
    devices, errors, records = {}, {}, {}

    def failed(key, exc) -> None:
        errors[key] = _first_line(exc)
        records[key] = []
        print(f"{key[0]}: trial {key[1]} failed: {errors[key]}", flush=True)
        if log:
            with open(log, "a") as f:
                f.write(json.dumps({"kind": key[0], "trial": key[1], "error": errors[key]}) + "\n")

    for key, actor in actors:  # one at a time: an actor that failed to build fails alone
        try:
            devices[key] = ray.get(actor.device.remote())
        except Exception as exc:  # noqa: BLE001 - any failure of one trial is that trial's
            failed(key, exc)
    t0 = time.perf_counter()
    pending = {actor.train_for.remote(args.seconds): key for key, actor in actors if key not in errors}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        key = pending.pop(ready[0])
        try:
            records[key] = ray.get(ready[0])
        except Exception as exc:  # noqa: BLE001
            failed(key, exc)
    by_trial = {key: records[key] for key, _ in actors}
    return by_trial, devices, errors, time.perf_counter() - t0


if __name__ == "__main__":
    raise SystemExit(main())
