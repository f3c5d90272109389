"""RRTStarConfig: what one RRT* trial runs (no Ray): the run and every setting of rrt_star/settings.py
at its value (`copilot_ray.settings.record_class`)."""

from __future__ import annotations

from copilot_ray.algorithms.rrt_star.settings import SETTINGS
from copilot_ray.settings import record_class

RRTStarConfig = record_class("RRTStarConfig", SETTINGS)
