"""SGTPGConfig: what one SGT-PG trial runs (no Ray): the run and every setting of sgt_pg/settings.py
at its value, pi_p's (`planner.*`) as the dict `planner` (`copilot_ray.settings.record_class`)."""

from __future__ import annotations

from copilot_ray.algorithms.sgt_pg.settings import SETTINGS
from copilot_ray.settings import record_class

SGTPGConfig = record_class("SGTPGConfig", SETTINGS, nested=("planner",))
