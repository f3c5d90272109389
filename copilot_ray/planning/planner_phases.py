"""pi_p's planner phase, the one CO-PILOT's curriculum and the SGT-PG baseline both run: the exploration
std annealed over the phases, then one top-down construction (Algorithm 1) with one PPO update per layer.

    phases = PlannerPhases(planner, settings)            # settings: the `planner.*` fields
    built = phases.run(starts, goals, depth, cost, rng)  # a ConstructionResult; `phases.count` += 1
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .construction import ConstructionResult, construct_trees
from .planner import SubgoalPlanner


class PlannerPhases:
    """Planner phases of one planner, counted (the std annealing's clock; checkpoint `count`).

    settings: `std`, `std_final` (None: a constant std), `std_anneal_phases`, `num_samples` (the
    `planner.*` settings' fields)."""

    def __init__(self, planner: SubgoalPlanner, settings: Mapping[str, Any]):
        self.planner = planner
        self.settings = dict(settings)
        self.count = 0

    def anneal(self) -> None:
        """The std of this phase: linear from `std` to `std_final` over `std_anneal_phases` phases."""
        p = self.settings
        if p["std_final"] is not None:
            frac = min(1.0, self.count / p["std_anneal_phases"])
            self.planner.set_std(p["std"] + frac * (p["std_final"] - p["std"]))

    def run(
        self, starts, goals, depth: int, cost, rng, *, train: bool = True, deterministic: bool = False
    ) -> ConstructionResult:
        """One phase on the tasks (starts, goals): the annealed std, then Algorithm 1 (`train`: one PPO
        update per layer on `num_samples` trees per task; the output tree a sample, or the mean with
        `deterministic`)."""
        self.anneal()
        self.count += 1
        return construct_trees(
            self.planner,
            starts,
            goals,
            depth,
            cost,
            num_samples=self.settings["num_samples"],
            train=train,
            deterministic=deterministic,
            rng=rng,
        )
