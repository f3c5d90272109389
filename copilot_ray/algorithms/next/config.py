"""NEXTConfig: what one NEXT trial runs (no Ray)."""

from __future__ import annotations

from copilot_ray.algorithms.next.settings import SETTINGS
from copilot_ray.settings import record_class

_SEARCH_FIELDS = {  # SearchSettings field -> setting key
    "step": "step_length",
    "max_iterations": "max_iterations",
    "max_checks": "max_checks",
    "improve_iterations": "improve_iterations",
    "exploration": "exploration",
    "uniform_share": "uniform_share",
    "goal_bias": "goal_bias",
    "candidates": "candidates",
    "policy_std": "policy_std",
    "rewire_factor": "rewire_factor",
}


class NEXTConfig(record_class("NEXTConfig", SETTINGS)):
    """The run and every NEXT setting at its value (`copilot_ray.settings.record_class`), plus the
    planner's own settings objects."""

    def search_settings(self):
        """The planner's SearchSettings (copilot_ray.planning.next_planner)."""
        from copilot_ray.planning.next_planner import SearchSettings

        return SearchSettings(**{name: getattr(self, key) for name, key in _SEARCH_FIELDS.items()})

    def train_settings(self):
        """The planner's TrainSettings (copilot_ray.planning.next_planner)."""
        from copilot_ray.planning.next_planner import TrainSettings

        return TrainSettings(
            hidden=tuple(int(h) for h in self.hidden),
            lr=float(self.lr),
            batch_size=int(self.batch_size),
            hindsight=bool(self.hindsight),
        )
