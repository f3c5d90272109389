"""The SAC updates of N seeds' agents (one `GoalSAC` each, in one process) as one stacked update.

`StackedAgentUpdates(algos)` stacks the seeds' learner modules into one `gc_sac.sac_step.SACStep` (their
parameters and Adam state become views of its rows: a seed's learner always holds its current agent) and
their replay (one device buffer with a ring per seed: flat transitions, `gc_sac.FlatTransitionBuffer`,
or HER's relabelling buffer for her, sorb and sorb_map, `gc_sac.HindsightReplayBuffer`, relabelled on
the device as the one-seed fused path relabels), and gives each algorithm a `FusedLearnerUpdater`
over its ring of the stacked replay in place of its own: adding episodes writes the seed's rows of the
stacked replay. `update({seed: (n, timesteps)})` (a `seed_stack.SeedStack` round, for
every seed that owes steps) runs max(n) stacked steps, seed i active in its first n_i (its learner's
module is its row: the env runners sync from there, as after any update), and logs each seed's figures
on its own learner. The seeds' actions come from `self.step.act`, one batched forward pass.

Random streams: each seed's SAC noise and its replay's rows (and HER's goals) come from its own Philox
streams (`gc_sac.philox`, keyed by its seed: the streams its one-seed fused update and one-seed device
buffer draw from), through the stacked buffer's one sampler; an inactive seed draws nothing. So seed i's
updates in a stack of any size are its updates in a stack of one (tested), drawn from the streams its
one-seed trial's fused update draws from.

What the stacked path refuses (named, before anything runs): the numpy or stock update paths
(`fused_update=False`, `fast_learner=False`), learning-rate schedules,
gradient clipping, and algorithms whose configurations differ in anything but the seed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray.algorithms.gc_sac.sac_step import FINITE, SACStep, replay_step_call
from copilot_ray.algorithms.sac.agent_updates import FusedLearnerUpdater, fused_update, local_learner


def stacking_problems(algos: Sequence[Any]) -> list[str]:
    """Why these algorithms' agents cannot share one stacked update ([] when they can)."""
    problems = []
    first = algos[0].config
    for name, ok in (
        ("fast_learner", bool(first.fast_learner)),
        ("learner_config_dict['gc_sac']['fused_update']", fused_update(first)),
        ("grad_clip", first.grad_clip is None),
        ("twin_q", bool(first.twin_q)),
    ):
        if not ok:
            problems.append(f"{name}: the stacked update needs the default (got a value it cannot stack)")
    for lr_name in ("actor_lr", "critic_lr", "alpha_lr"):
        if not isinstance(getattr(first, lr_name), int | float):
            problems.append(f"{lr_name}={getattr(first, lr_name)!r}: the stacked update takes constant rates")
    base = first.setting_values()
    for algo in algos[1:]:
        other = algo.config.setting_values()
        differ = sorted(k for k in base if repr(base[k]) != repr(other.get(k)))
        if differ:
            problems.append(f"seed {algo.config.seed}: its configuration differs in {differ[:5]}")
    return problems


class StackedAgentUpdates:
    """N seeds' agent updates as one (module docstring). `algos`: built `GoalSAC`s, one per seed."""

    def __init__(self, algos: Sequence[Any]):
        problems = stacking_problems(algos)
        if problems:
            raise ValueError("these seeds' agents cannot be stacked: " + "; ".join(problems))
        self.algos = list(algos)
        self.seeds = [int(a.config.seed or 0) for a in algos]
        self.learners = [local_learner(a.config, a.learner_group) for a in algos]
        self.device = self.learners[0].device
        modules = [learner.module[DEFAULT_MODULE_ID].unwrapped() for learner in self.learners]
        cfg = algos[0].config
        module_cfg = self.learners[0].config.get_config_for_module(DEFAULT_MODULE_ID)
        self.step = SACStep(
            modules,
            [learner.curr_log_alpha[DEFAULT_MODULE_ID] for learner in self.learners],
            [learner._sac_optimizers(DEFAULT_MODULE_ID) for learner in self.learners],
            self.learners[0].target_entropy[DEFAULT_MODULE_ID],
            gamma=module_cfg.gamma,
            tau=module_cfg.tau,
            critic_loss=self.learners[0]._gc_settings["critic_loss"],
            seeds=self.seeds,
        )
        space = modules[0].observation_space, modules[0].action_space
        dims = (int(np.prod(space[0].shape)), int(np.prod(space[1].shape)))
        self.replay = algos[0].device_replay(self.device, self.seeds, dims)  # a ring per seed
        self.batch_size = int(cfg.train_batch_size_per_learner)
        self._active = torch.zeros(len(self.algos), dtype=torch.bool, device=self.device)
        self._cached: tuple[int, Any] | None = None  # (replay storage version, its step call)
        self._skipped_logged = [0] * len(self.algos)  # each seed's non-finite steps its learner has logged

    def view(self, index: int) -> FusedLearnerUpdater:
        """Seed `index`'s updater (what its algorithm's `agent_updater` becomes): its ring of the
        stacked replay; its updates are this stack's."""
        algo = self.algos[index]
        return FusedLearnerUpdater(algo.config, algo.learner_group, self.replay, ring=index)

    # ------------------------------------------------------------------ one round
    def update(self, requests: Mapping[int, tuple[int, dict[str, Any]]]) -> dict[int, list[dict[str, Any]]]:
        """{seed index: (gradient steps, timesteps)} -> {seed index: [its learner's results]}."""
        owed = [int(requests[i][0]) if i in requests else 0 for i in range(len(self.algos))]
        owed_on_device = torch.as_tensor(owed, device=self.device)  # once a round: steps compare to it
        run = self._run()
        last: dict[int, dict[str, torch.Tensor]] = {}
        for t in range(max(owed)):
            torch.gt(owed_on_device, t, out=self._active)  # in place: what the captured step reads
            stats = run()
            for i, n in enumerate(owed):
                if n == t + 1:  # seed i's last step of this round: its figures
                    last[i] = {k: v[i].detach().clone() for k, v in stats.items() if k != FINITE}
        skipped = self.step.skipped.cpu().tolist()  # every seed's non-finite steps so far
        out = {}
        for i, (n, timesteps) in requests.items():
            figures = {k: float(v) for k, v in last[i].items()} if i in last else {}
            new_skips, self._skipped_logged[i] = skipped[i] - self._skipped_logged[i], skipped[i]
            results = self.learners[i].record_steps(figures, new_skips, n, self.batch_size, timesteps)
            out[i] = [results] if figures else []
        return out

    def _run(self):
        """The stacked step on the stacked replay through the one capture site (`replay_step_call`),
        built again when the replay's storage moved (a graph holds it fixed)."""
        key = self.replay.storage_version
        if self._cached is None or self._cached[0] != key:
            settings = self.learners[0]._gc_settings
            run = replay_step_call(
                self.step,
                self.replay,
                self.batch_size,
                capture=self.device.type == "cuda" and settings["cuda_graph"],
                compile_update=settings["compile_update"],
                active=self._active,
            )
            self._cached = (key, run)
        return self._cached[1]

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, Any]:
        """Every seed's parameters, optimizer state and noise stream (each seed's replay rows and
        sampling stream are in its algorithm's checkpoint, through its updater's ring)."""
        return {"step": self.step.get_state()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores `get_state`'s snapshot (in place: the learners' modules, views of the step's rows,
        hold it too)."""
        self.step.set_state(state["step"])
        # The seeds' skipped-step counts come back with the step; each was logged before the checkpoint.
        self._skipped_logged = self.step.skipped.cpu().tolist()
