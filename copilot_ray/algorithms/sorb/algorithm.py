"""SoRB (Search on the Replay Buffer; Eysenbach, Salakhutdinov and Levine, 2019) on CO-PILOT's agent:
`SoRBConfig` and `SoRB`.

Training is the HER baseline's goal-conditioned SAC (copilot_ray.algorithms.sac). At each evaluation,
once `sorb.pretrain_env_steps` env steps are done (before that it is evaluated as its agent alone),
SoRB builds a graph over `sorb.graph_size` states
drawn from its replay buffer (graph.py): the weight of edge i -> j is the agent's estimated number of
steps from state i to state j's achieved goal, read off its critic, and edges longer than
`sorb.max_edge_steps` are dropped. Each test task is routed start -> graph -> goal by shortest path and
the agent follows the waypoints (`sorb.waypoint_steps` each, `tau_max` steps in all, the budget every
method gets); a task the graph cannot route (or whose goal is within one edge) is one hop with the whole
`tau_max` budget, as the agent alone gets.

Distance from the critic. The reward is sparse (R = goal_reward x reward_scale on arrival, the episode
ending there), so a policy that arrives in d steps has Q = R * gamma^(d - 1) and
d = 1 + log(Q / R) / log(gamma). SoRB's own critic predicts distances directly (reward -1 per step,
gamma 1, optionally distributional and an ensemble); here the project's SAC critic is reused
unchanged, its twin-Q minimum at the actor's mean action is turned into steps, and Q is clipped to
[R * 1e-6, R] (an entropy bonus can push it outside). Left out: the distributional critic and the
critic ensemble (the twin minimum is the only pessimism), and SoRB's graph cleaning.

With `sorb.edge_check: map` (`algorithm: sorb_map`) every edge the critic keeps is also checked against
the map, and dropped where its straight segment crosses a wall: the graph gets the map access CO-PILOT's
planner has, and its checks are counted like the planner's (`copilot/privileges/collision_checks`).

Logged at each evaluation after pre-training: `copilot/eval/success` and `success_planned` = following
the graph's waypoints, `success_direct` = the agent alone; `sorb/graph_edges`, `sorb/waypoints_mean`,
`sorb/graph_s`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

from copilot_ray import keys
from copilot_ray.algorithms.sac.algorithm import GoalSAC, HERConfig
from copilot_ray.algorithms.sorb import settings as sorb_settings
from copilot_ray.algorithms.sorb.graph import ReplayGraph, pad_front
from copilot_ray.algorithms.sorb_map import settings as sorb_map_settings
from copilot_ray.planning.path_metrics import CountedChecks
from copilot_ray.settings import Setting

_STATE_KEY = "sorb"
# Rows per critic call when building the graph (memory: rows x hidden floats per layer).
_CRITIC_CHUNK = 32_768


class SoRBConfig(HERConfig):
    """The HER baseline's config plus SoRB's search settings (`.search(...)`, `sorb.*` in specs)."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = sorb_settings.SETTINGS
    NESTED: ClassVar[tuple[str, ...]] = ("her", "sorb")

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or SoRB)

    def search(self, **settings: Any) -> SoRBConfig:
        """SoRB's settings: pretrain_env_steps, graph_size, max_edge_steps, waypoint_steps."""
        self._refuse_unknown({f"sorb.{k}" for k in settings}, "search")
        self.sorb = {**self.sorb, **settings}
        return self

    @override(HERConfig)
    def validate(self) -> None:
        if self.num_learners != 0:
            raise ValueError(
                f"SoRBConfig: num_learners={self.num_learners!r} is invalid: the search reads the critic of "
                "the local learner; use 0"
            )
        super().validate()

    def uses_hindsight_buffer(self) -> bool:
        return True  # the graph's states come from it, relabelling or not


class SoRBMapConfig(SoRBConfig):
    """SoRB with the map (`algorithm: sorb_map`): `sorb.edge_check` is "map" unless set otherwise."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = sorb_map_settings.SETTINGS


class SoRB(GoalSAC):
    """Goal-conditioned SAC whose evaluation searches a graph over its replay buffer (module docstring)."""

    @classmethod
    @override(GoalSAC)
    def get_default_config(cls):
        return SoRBConfig()

    @override(GoalSAC)
    def setup(self, config) -> None:
        super().setup(config)
        # Every map check of the graph's edges (sorb.edge_check: map); checkpointed.
        self._edge_checks = CountedChecks(self.goal_env.unwrapped.segments_collide)

    def _segment_free(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return ~np.asarray(self._edge_checks(a, b), bool)

    @override(GoalSAC)
    def _collision_checks(self) -> int:
        return super()._collision_checks() + self._edge_checks.count

    @override(GoalSAC)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict[str, Any]:
        """GoalSAC's state plus the graph's map checks so far ("sorb")."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        state[_STATE_KEY] = {"edge_checks": self._edge_checks.count}
        return state

    @override(GoalSAC)
    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        self._edge_checks.count = int(state.get(_STATE_KEY, {}).get("edge_checks", 0))

    @torch.no_grad()
    def critic_distance(
        self, observations: np.ndarray, achieved: np.ndarray, goals: np.ndarray
    ) -> np.ndarray:
        """Estimated agent steps from each (observation, achieved goal) to each goal: see the module
        docstring. Batched, in chunks."""
        module = self.learner_group._learner.module[DEFAULT_MODULE_ID]
        device = next(module.parameters()).device  # the learner's: a GPU with resources.gpus_per_trial
        layout = self.goal_layout()
        reward = float(self.goal_env.unwrapped.goal_reward) * self.rules.reward_factor(0)
        log_gamma = np.log(self.config.gamma)
        out = np.empty(len(goals))
        for lo in range(0, len(goals), _CRITIC_CHUNK):
            hi = lo + _CRITIC_CHUNK
            obs = torch.as_tensor(
                layout.compose(observations[lo:hi], goals[lo:hi], achieved[lo:hi]), device=device
            )
            mean, _ = module.pi(module.pi_encoder({Columns.OBS: obs})["encoder_out"]).chunk(2, dim=-1)
            q = module.compute_q_values({Columns.OBS: obs, Columns.ACTIONS: torch.tanh(mean)})
            ratio = np.clip(q.cpu().numpy().astype(np.float64) / reward, 1e-6, 1.0)
            out[lo:hi] = 1.0 + np.log(ratio) / log_gamma
        return out

    @override(GoalSAC)
    def _evaluation_plan(self, n: int) -> dict[str, Any] | None:
        cfg = self.config
        steps = self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
        if steps < cfg.sorb["pretrain_env_steps"] or self.agent_updater.replay_size() == 0:
            # Before its search starts, SoRB is its agent alone: evaluated as such, on the cadence
            # every method shares (no gap at the start of its curve).
            return super()._evaluation_plan(n)
        t0 = time.perf_counter()
        observations, achieved = self.agent_updater.replay_states(cfg.sorb["graph_size"], self._rng)
        graph = ReplayGraph.build(
            observations,
            achieved,
            self.critic_distance,
            cfg.sorb["max_edge_steps"],
            segment_free=self._segment_free if cfg.sorb["edge_check"] == "map" else None,
        )
        search = _GraphWaypoints(graph, self.goal_env, cfg.sorb["waypoint_steps"], cfg.tau_max)
        self.metrics.log_value(keys.metric_path(keys.SORB_GRAPH_EDGES), graph.num_edges, window=1)
        self.metrics.log_value(keys.metric_path(keys.SORB_GRAPH_S), time.perf_counter() - t0, window=1)
        self._search = search
        return {
            "planner": search,
            "step_limit_of": lambda k: cfg.sorb["waypoint_steps"],
            "hop_limits": search.hop_limits,
            "planned_total_steps": cfg.tau_max,
        }

    @override(GoalSAC)
    def _evaluate(self) -> None:
        self._search = None
        super()._evaluate()
        if self._search is not None:
            self.metrics.log_value(
                keys.metric_path(keys.SORB_WAYPOINTS), self._search.mean_waypoints, window=1
            )


class _GraphWaypoints:
    """A SoRB graph behind the planner interface evaluation takes: `sample(starts, goals)` ->
    [N, P, d] waypoints (front-padded with the start where a route is shorter than the longest), and
    `hop_limits(waypoints)`: `waypoint_steps` per hop, except that a task routed straight to its goal
    (the goal within one edge, or no route through the graph) gets the task's whole budget `total_steps`
    for that one hop, as the agent alone would."""

    def __init__(self, graph: ReplayGraph, goal_env, waypoint_steps: int, total_steps: int):
        self.graph = graph
        self.goal_env = goal_env
        self.waypoint_steps = int(waypoint_steps)
        self.total_steps = int(total_steps)
        self.mean_waypoints = float("nan")
        self._straight: np.ndarray | None = None  # [N] of the last `sample`: routed straight to g

    def sample(self, starts: np.ndarray, goals: np.ndarray, deterministic: bool = True) -> np.ndarray:
        # The agent's observation at each start (the goal env's own, whatever its observation is).
        observations = np.stack(
            [
                self.goal_env.reset(options={"start": s, "goal": g})[0]["observation"]
                for s, g in zip(starts, goals, strict=True)
            ]
        )
        paths = self.graph.waypoints(observations, starts.astype(np.float32), goals.astype(np.float32))
        self.mean_waypoints = float(np.mean([len(p) for p in paths]))
        self._straight = np.array([len(p) == 2 for p in paths])
        return pad_front(paths)

    def hop_limits(self, waypoints: np.ndarray) -> np.ndarray:
        """int [N, P - 1]: the steps each hop of the last `sample`'s routes may take."""
        if self._straight is None or len(self._straight) != len(waypoints):
            raise ValueError("hop_limits needs the waypoints of the last sample() call")
        limits = np.full((len(waypoints), waypoints.shape[1] - 1), self.waypoint_steps, np.int64)
        limits[self._straight, -1] = self.total_steps
        return limits
