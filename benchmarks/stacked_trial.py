"""Env steps/s of a stacked-seeds trial (`SeedStackTrial`, a spec's `seeds_per_trial`) against one seed's
own trial, both in this process, CO-PILOT on the u-maze (`--layout`) with one SAC update per env step.

    PYTHONPATH=. python benchmarks/stacked_trial.py [--stacks 2 4] [--iterations 4] [--rounds 2] [--gpu]
        [--layout u-maze]

Rows: one seed's own trial; then per stack size N, N seeds in one trial (one batched act per env step,
one stacked update per round, on every device). Each row builds its
trial (not timed), runs one iteration to warm up (the planner's warm start, SAC's
learning start), then times `--iterations` iterations; rows alternate over `--rounds` so that a machine
whose load drifts affects both alike. Printed per row: aggregate env steps/s (all its seeds), per seed,
and the host cost per seed env step: the traversals' wall time less their SAC updates', over the env
steps they took (acting, env stepping, episodes; the target is <= 0.1 ms at 16 seeds), and of it the
acting (the actor's forward pass and the noise: one batched pass for a stack) and, for a stack on the
maze, the moving (one `batch_step` for every seed's agent); the rest is each seed's env step and its
sub-task's bookkeeping.

What it answers on a CPU: a two-core machine runs either seeds as trials two at a time (two one-seed
processes side by side) or stacks side by side; a stack of N is not slower in aggregate when its row is
at least the one-seed row (each process then gets one core either way). On a GPU the stack's one update
for N seeds is the point (benchmarks/stacked_update.py measures the update alone); `--gpu` puts every
trial's learner, and so the stack, on the GPU (`resources.gpus_per_trial: 1`; refused without one).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
import yaml

from copilot_ray import keys

SPEC = {
    "name": "stacked_trial_benchmark",
    "env": {"id": "maze-point", "config": {"layout": "u-maze"}},
    "algorithm": "copilot",
    "config": {
        "tree_depth": 3,
        "repetitions": 1,
        "task_batch_size": 4,
        "tau_max": 12,
        "eval_interval": 1000,  # no evaluation inside the timed iterations
        "num_steps_sampled_before_learning_starts": 100,
        "updates_per_env_step": 1.0,
        "cost_model.init_euclidean": 500,
        "cost_model.fit_steps": 5,
        "planner_warm_start": 3,
        "planner_task_batch_size": 8,
    },
    "searcher": {"type": "grid"},
    "stop": {"iterations": 1000, "min_evaluations": 1},  # a benchmark: its evaluations do not matter
    "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
}


def _spec_file(directory: Path, seeds: list[int], gpu: bool, layout: str = "u-maze") -> str:
    data = {**SPEC, "seeds": seeds, "seeds_per_trial": len(seeds), "tracking": {"storage": str(directory)}}
    data["env"] = {**SPEC["env"], "config": {"layout": layout}}
    if gpu:  # the learner, and so the stack, on the GPU
        data["resources"] = {**SPEC["resources"], "gpus_per_trial": 1}
    path = directory / f"stack_{len(seeds)}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


def _one_seed_trial(spec_path: str):
    from copilot_ray.algorithms.copilot.trial import CoPilotTrial

    return CoPilotTrial(config={keys.SPEC_PATH_KEY: spec_path, keys.SEED_PARAM: 0})


def _stacked_trial(spec_path: str, seeds: list[int]):
    from copilot_ray.algorithms.sac.trial import SeedStackTrial

    return SeedStackTrial(config={keys.SPEC_PATH_KEY: spec_path, keys.SEEDS_KEY: seeds})


def _env_steps(result: dict) -> float:
    """Env steps of every seed in a result (a stacked trial's seeds, or the one trial's)."""
    per_seed = result.get(keys.SEED_RESULTS)
    if per_seed:
        return sum(m[keys.ENV_STEPS] for m in per_seed.values())
    return float(result["env_runners"]["num_env_steps_sampled_lifetime"])


class Clock:
    """Seconds spent inside the traversals and inside their SAC updates, for one-seed trials
    (`RunnerTraversal._traverse`, `FusedLearnerUpdater.update`) and stacks (`SeedStack._traverse`,
    `SeedStack._update`), and inside acting (a runner's exploring policy; `SeedStack._act`) and a
    stack's moving (`SeedStack._batch_move`): patched in once, read per row."""

    traverse_s = update_s = act_s = move_s = 0.0
    _inside: set[str] = set()  # the fields being timed now (a timed call inside another counts once)

    @classmethod
    def install(cls) -> None:
        from copilot_ray.algorithms.sac.agent_updates import FusedLearnerUpdater
        from copilot_ray.algorithms.sac.runner_traversal import RunnerTraversal
        from copilot_ray.algorithms.sac.seed_stack import SeedStack
        from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner

        for owner, name, field in (
            (RunnerTraversal, "_traverse", "traverse_s"),
            (SeedStack, "_traverse", "traverse_s"),
            (FusedLearnerUpdater, "update", "update_s"),
            (SeedStack, "_update", "update_s"),
            (SeedStack, "_act", "act_s"),
            (SeedStack, "_batch_move", "move_s"),
        ):
            setattr(owner, name, cls._timed(getattr(owner, name), field))
        policy = TraversalEnvRunner.policy  # a one-seed runner's act is the function it returns

        def timed_policy(self, explore):
            act = policy(self, explore)
            return cls._timed(act, "act_s") if explore else act

        TraversalEnvRunner.policy = timed_policy

    @classmethod
    def _timed(cls, fn, field: str):
        def timed(*args, **kwargs):
            if field in cls._inside:
                return fn(*args, **kwargs)
            cls._inside.add(field)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                cls._inside.discard(field)
                setattr(cls, field, getattr(cls, field) + time.perf_counter() - t0)

        return timed


def measure(trial, iterations: int) -> tuple[float, float, float, float]:
    """(env steps/s of all the trial's seeds, then host, acting and moving ms per seed env step) over
    `iterations` iterations after one to warm up; each iteration prints its running rate, so a run cut
    off (a lent machine's minutes) keeps a figure."""
    start = time.perf_counter()
    before = _env_steps(trial.train())
    print(f"   warm-up iteration: {before:.0f} env steps in {time.perf_counter() - start:.0f} s", flush=True)
    Clock.traverse_s = Clock.update_s = Clock.act_s = Clock.move_s = 0.0
    start = time.perf_counter()
    for i in range(iterations):
        after = _env_steps(trial.train())
        seconds = time.perf_counter() - start
        per_step = 1000 / max(after - before, 1)  # ms per seed env step, per second spent
        host, act, move = (
            (Clock.traverse_s - Clock.update_s) * per_step,
            Clock.act_s * per_step,
            Clock.move_s * per_step,
        )
        print(
            f"   iteration {i + 1}: {(after - before) / seconds:.1f} env steps/s so far, host "
            f"{host:.3f} ms per seed env step (acting {act:.3f}, moving {move:.3f})",
            flush=True,
        )
    trial.stop()
    return (after - before) / seconds, host, act, move


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stacks", type=int, nargs="+", default=[2, 4], help="seeds per stacked trial")
    parser.add_argument("--iterations", type=int, default=4, help="timed iterations per row")
    parser.add_argument("--rounds", type=int, default=2, help="times every row runs, alternating")
    parser.add_argument(
        "--threads", type=int, default=1, help="torch threads (a trial's process has one core)"
    )
    parser.add_argument("--gpu", action="store_true", help="every trial's learner on the GPU")
    parser.add_argument("--layout", default="u-maze", help="the maze-point layout (default u-maze)")
    args = parser.parse_args()
    if any(n < 2 for n in args.stacks):
        raise SystemExit(f"--stacks: every stack needs >= 2 seeds, got {args.stacks}")
    if args.gpu and not torch.cuda.is_available():
        raise SystemExit("--gpu: torch sees no CUDA device on this machine")
    torch.set_num_threads(args.threads)
    Clock.install()
    directory = Path(tempfile.mkdtemp(prefix="stacked_trial_"))
    rows: dict[str, list[tuple[float, float, float, float]]] = {}
    for round_ in range(args.rounds):
        name = "one seed, its own trial"
        rows.setdefault(name, []).append(
            measure(_one_seed_trial(_spec_file(directory, [0], args.gpu, args.layout)), args.iterations)
        )
        print(f"round {round_ + 1}: {name}: {rows[name][-1][0]:.1f} env steps/s", flush=True)
        for n in args.stacks:
            seeds = list(range(n))
            name = f"{n} seeds in one trial, one stacked update"
            spec = _spec_file(directory, seeds, args.gpu, args.layout)
            rows.setdefault(name, []).append(measure(_stacked_trial(spec, seeds), args.iterations))
            print(f"round {round_ + 1}: {name}: {rows[name][-1][0]:.1f} env steps/s", flush=True)
    print(
        "\n| trial | env steps/s, all its seeds (per round) | per seed | vs one seed's trial "
        "| host ms per seed env step (per round) | of it acting | moving |"
    )
    print("|---|---|---|---|---|---|---|")
    base = sum(row[0] for row in rows["one seed, its own trial"]) / args.rounds
    for name, values in rows.items():
        n = 1 if name.startswith("one") else int(name.split()[0])
        rate, host, act, move = (sum(column) / len(values) for column in zip(*values, strict=True))
        runs = ", ".join(f"{row[0]:.1f}" for row in values)
        hosts = ", ".join(f"{row[1]:.3f}" for row in values)
        moving = f"{move:.3f}" if n > 1 else "(in its env step)"
        print(
            f"| {name} | {rate:.1f} ({runs}) | {rate / n:.1f} | {rate / base:.2f}x | {host:.3f} ({hosts}) "
            f"| {act:.3f} | {moving} |"
        )


if __name__ == "__main__":
    main()
