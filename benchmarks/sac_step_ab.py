"""One seed's SAC update time: the agent's `SACStep` at N = 1 against the steps it replaced, interleaved.

    PYTHONPATH=. python benchmarks/sac_step_ab.py [--base fce44f3] [--rounds 8] [--steps 40] [--threads 1]
        [--stack 4]

At this project's sizes (actor and twin critics [256, 256], batch 256, obs 4, action 2), on the CPU.
The replaced steps are read from git revision `--base` (the one before `SACStep`):

* "fused (base)": `fused_step.FusedSACStep`, the one-seed fused update (the RLModule's forward pass,
  torch's fused Adam, noise from torch's default generator);
* "stacked MLP (base)": `seed_stack.StackedSACStep` at N = 1, the stack's own batched MLP
  (`baddbmm` over stacked weights), its own Adam: what holding one stacked module would cost;
* "SACStep": this tree's step (the RLModule's networks by `functional_call` under `vmap`, Philox noise).

With `--stack N` (N > 1) two more rows compare the two ways of holding N seeds' networks: "stacked MLP
(base) xN" (the stack's own batched layers) and "SACStep xN" (the RLModule's networks under `vmap`);
their ms are per stacked step (N seed-updates).

Each round times `--steps` steps of every row in turn (A, B, C, then the next round), on one fixed
batch, after 5 warm-up steps each; the order rotates every round so a load change on a shared machine
hits every row alike. Prints each row's median and best ms per step over the rounds, and the median
of SACStep's per-round ratio to "fused (base)".
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray.algorithms.gc_sac import use_fast_learner
from copilot_ray.algorithms.gc_sac.sac_step import with_seed_axis

OBS, ACT, BATCH = 4, 2, 256
ROOT = Path(__file__).resolve().parents[1]


def _module_at(rev: str, path: str, name: str) -> types.ModuleType:
    """The module at `path` as of git revision `rev`, imported under `name`."""
    source = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True, text=True)
    if source.returncode != 0:
        # a shallow clone lacks the revision: say so instead of git's traceback
        why = source.stderr.strip()
        print(
            f"error: --base {rev}: {path} is not readable there ({why}); fetch it (git fetch --unshallow)",
            file=sys.stderr,
        )
        sys.exit(2)
    spec = importlib.util.spec_from_loader(name, loader=None)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    exec(compile(source.stdout, f"{rev}:{path}", "exec"), module.__dict__)  # noqa: S102 - our own history
    return module


def _learner():
    space = gym.spaces.Box(0.0, 1.0, (OBS,), np.float32)
    cfg = SACConfig().environment(
        observation_space=space, action_space=gym.spaces.Box(-1.0, 1.0, (ACT,), np.float32)
    )
    return (
        use_fast_learner(cfg.debugging(seed=0), hidden=(256, 256), torch_threads=None)
        .build_learner_group()
        ._learner
    )


def _batch() -> dict[str, torch.Tensor]:
    rng = np.random.default_rng(0)
    obs = rng.uniform(0, 1, (BATCH, OBS)).astype(np.float32)
    cols = {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.01, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (BATCH, ACT)).astype(np.float32),
        "rewards": np.full(BATCH, -1.0, np.float32),
        "terminateds": rng.random(BATCH) < 0.05,
    }
    return {k: torch.as_tensor(v) for k, v in cols.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="fce44f3", help="git revision of the replaced steps")
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--stack", type=int, default=0, help="also time N stacked seeds both ways")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    old_fused = _module_at(args.base, "copilot_ray/algorithms/gc_sac/fused_step.py", "base_fused_step")
    sys.modules["copilot_ray.algorithms.gc_sac.fused_step"] = old_fused  # what the base stack imports
    old_stack = _module_at(args.base, "copilot_ray/algorithms/gc_sac/seed_stack.py", "base_seed_stack")

    batch = _batch()
    base = _learner()  # the base steps train their own copies: every row starts from the same weights
    module_id = DEFAULT_MODULE_ID
    base_module = base.module[module_id].unwrapped()
    config = base.config.get_config_for_module(module_id)
    fused = old_fused.FusedSACStep(
        base_module,
        base.curr_log_alpha[module_id],
        [o for _, o in base.get_optimizers_for_module(module_id)],
        base.target_entropy[module_id],
        gamma=config.gamma,
        tau=config.tau,
        critic_loss="huber",
        twin_q=True,
    )
    agents = old_stack.StackedSAC.from_modules([base_module], [base.curr_log_alpha[module_id]])
    stacked = old_stack.StackedSACStep(
        agents,
        {"qf": config.critic_lr, "policy": config.actor_lr, "alpha": config.alpha_lr},
        base.target_entropy[module_id],
        gamma=config.gamma,
        tau=config.tau,
        critic_loss="huber",
    )
    step = _learner().fused_step()
    one_seed, seed_axis = batch, with_seed_axis(batch)
    rows = {
        "fused (base)": lambda: fused.step(one_seed),
        "stacked MLP (base)": lambda: stacked.step(seed_axis),
        "SACStep": lambda: step.step(seed_axis),
    }
    if args.stack > 1:
        n = args.stack
        learners = [_learner() for _ in range(n)]
        many = _learner().fused_step()  # only its settings are read
        stacked_n = old_stack.StackedSACStep(
            old_stack.StackedSAC.from_modules(
                [lr.module[module_id].unwrapped() for lr in learners],
                [lr.curr_log_alpha[module_id] for lr in learners],
            ),
            {"qf": config.critic_lr, "policy": config.actor_lr, "alpha": config.alpha_lr},
            base.target_entropy[module_id],
            gamma=config.gamma,
            tau=config.tau,
            critic_loss="huber",
        )
        step_n = type(many)(
            [lr.module[module_id].unwrapped() for lr in learners],
            [lr.curr_log_alpha[module_id] for lr in learners],
            [lr._sac_optimizers(module_id) for lr in learners],
            base.target_entropy[module_id],
            gamma=config.gamma,
            tau=config.tau,
            critic_loss="huber",
            seeds=range(n),
        )
        stacked_batch = {k: v.expand(n, *v.shape[1:]).contiguous() for k, v in seed_axis.items()}
        rows[f"stacked MLP (base) x{n}"] = lambda: stacked_n.step(stacked_batch)
        rows[f"SACStep x{n}"] = lambda: step_n.step(stacked_batch)
    for run in rows.values():
        for _ in range(5):
            run()
    times: dict[str, list[float]] = {name: [] for name in rows}
    order = list(rows)
    for r in range(args.rounds):
        for name in order[r % len(order) :] + order[: r % len(order)]:
            start = time.perf_counter()
            for _ in range(args.steps):
                rows[name]()
            times[name].append(1e3 * (time.perf_counter() - start) / args.steps)
    print(
        f"# cpu, {args.threads} thread(s), torch {torch.__version__}, batch {BATCH}, networks [256, 256], "
        f"{args.rounds} rounds x {args.steps} steps, base {args.base}"
    )
    for name, ms in times.items():
        print(f"{name:20s} median {statistics.median(ms):6.2f} ms/step   best {min(ms):6.2f} ms/step")
    ratios = [new / old for new, old in zip(times["SACStep"], times["fused (base)"], strict=True)]
    print(f"SACStep / fused (base): median of per-round ratios {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
