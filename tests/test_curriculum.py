"""CO-PILOT's curriculum as a plain object (no Ray): its iteration returns its metrics, and its state keeps
the layout checkpoints have had under "copilot" since before it was a component."""

import numpy as np
import pytest

from copilot_ray import keys
from copilot_ray.algorithms.copilot.settings import SETTINGS
from copilot_ray.envs import make
from copilot_ray.planning.curriculum import CoPilotCurriculum

# The keys CoPilot's checkpoints held under "copilot" before the curriculum was its own object.
OLD_STATE_KEYS = {"planner", "cost_model", "alpha_clock", "planner_phases", "planner_checks", "warm_started"}


def _settings(**over):
    values = {key: s.default for key, s in SETTINGS.items() if "." not in key}
    nested = {
        target: {s.field: s.default for s in SETTINGS.values() if s.target == target}
        for target in ("planner", "cost_model")
    }
    values.update(nested)
    values.update(
        tree_depth=2,
        repetitions=2,
        planner_warm_start=2,
        planner_task_batch_size=4,
        alpha_schedule={"kind": "constant", "alpha": 0.5},
        collision_penalty=10.0,
    )
    values["planner"] = {**values["planner"], "num_samples": 4}
    values["cost_model"] = {**values["cost_model"], "init_euclidean": 200, "fit_steps": 3}
    values.update(over)
    return values


def _curriculum(seed=0, **over):
    env = make("maze-point", layout="u-maze").unwrapped
    rng = np.random.default_rng(seed)
    train = env.tasks("train")
    return CoPilotCurriculum(
        env, _settings(**over), train, env.tasks("test")[0], lambda k: 0.1, rng, seed
    ), rng


def _subtasks(trees):
    """Finished sub-tasks as the traversal would report them: every finest segment reached."""
    starts, ends = trees[:, :-1].reshape(-1, 2), trees[:, 1:].reshape(-1, 2)
    n = len(starts)
    return {
        "start": starts,
        "end": ends,
        "goal": ends,
        "steps": np.full(n, 5),
        "layer": np.full(n, 2),
        "index": np.tile(np.arange(1, 5), len(trees)),
        "task": np.repeat(np.arange(len(trees)), 4),
        "reached": np.ones(n, bool),
        "collided": np.zeros(n, bool),
        "reset_to_state": np.zeros(n, bool),
        "map_queries": np.zeros(n, np.int64),
    }


def test_an_iteration_of_the_curriculum_returns_its_metrics_and_traverses_the_first_tasks():
    curriculum, rng = _curriculum()
    warm = curriculum.prepare(1, rng)
    assert set(warm) == {keys.PLANNER_PREFIX + "warm_start_s", keys.PLANNER_PREFIX + "warm_start_cost"}
    assert curriculum.prepare(2, rng) == {}  # once per run
    assert curriculum.tasks_to_draw(2) == 4  # the planner's batch; the agent traverses 2 of it
    starts, goals = (x[:4] for x in curriculum.env.tasks("train"))
    checks = curriculum.collision_checks
    trees, metrics = curriculum.trees(starts, goals, 2, rng)
    assert trees.shape == (2, 5, 2)
    np.testing.assert_allclose(trees[:, 0], starts[:2])
    assert metrics[keys.ALPHA] == 0.5 and keys.PLANNER_APPROX_KL_MAX in metrics
    assert curriculum.collision_checks > checks
    tracked = {keys.DIAG_TAU_HAT_ERROR, keys.DIAG_TAU_HAT_BIAS, keys.DIAG_EUCLIDEAN_ERROR}
    learned = curriculum.learn(_subtasks(trees), rng)
    assert set(learned) == {keys.COST_MODEL_LOSS, *tracked} and curriculum.alpha_clock.episode == 1
    assert curriculum.summary()[keys.DTAU_SIZE] == 200 + 8
    assert set(curriculum.learned_parts()) == {"planner", "cost_model"}


def test_its_state_has_the_layout_old_checkpoints_hold_and_restores_them():
    curriculum, rng = _curriculum()
    curriculum.prepare(1, rng)
    state = curriculum.state_dict()
    assert set(state) == OLD_STATE_KEYS
    fresh, _ = _curriculum(seed=1)
    fresh.load_state_dict(state)
    assert fresh.phases.count == curriculum.phases.count == 2
    assert fresh.collision_checks == curriculum.collision_checks and fresh.prepare(1, rng) == {}
    for a, b in zip(fresh.planner.parameters(), curriculum.planner.parameters(), strict=True):
        np.testing.assert_array_equal(a.detach().numpy(), b.detach().numpy())
    # A checkpoint from before the counters existed: the planner learned, the warm start done.
    oldest = {k: v for k, v in state.items() if k not in ("planner_phases", "planner_checks", "warm_started")}
    older, _ = _curriculum(seed=2)
    older.load_state_dict(oldest)
    assert (older.phases.count, older.collision_checks, older.prepare(1, rng)) == (0, 0, {})


def test_collision_cost_length_needs_the_envs_hook():
    class NoLengths:
        def __getattr__(self, name):
            if name == "collision_lengths":
                raise AttributeError(name)
            return getattr(make("maze-point").unwrapped, name)

    with pytest.raises(ValueError, match=r"collision_cost='length' is invalid for env NoLengths"):
        CoPilotCurriculum(NoLengths(), _settings(collision_cost="length"), None, None, None, None, 0)


def test_a_warm_start_paused_by_a_stop_and_resumed_from_its_state_ends_in_the_uninterrupted_planner():
    """6 phases in one go, against 3, a stop (train's Ctrl-C through the heartbeat), the state and the
    run's rng carried to a fresh curriculum (what a checkpoint and --resume do), and the other 3: the
    same planner, weight for weight, the same phase count and collision checks."""
    from copilot_ray.heartbeat import Heartbeat, StopRequested

    whole, rng = _curriculum(planner_warm_start=6)
    whole.prepare(1, rng, Heartbeat())

    class CtrlCInPhase3(Heartbeat):
        def beat(self, message):
            if message().endswith("phase 3 of 6"):
                self.request_stop("interrupted")  # phase 3 still runs: the stop waits for its end
            super().beat(message)

    paused, rng = _curriculum(planner_warm_start=6)
    with pytest.raises(StopRequested, match="planner warm start paused after 3 of 6 phases"):
        paused.prepare(1, rng, CtrlCInPhase3())
    assert paused.phases.count == 3
    state, rng_state = paused.state_dict(), rng.bit_generator.state

    resumed, _ = _curriculum(planner_warm_start=6)
    resumed.load_state_dict(state)
    rng = np.random.default_rng()
    rng.bit_generator.state = rng_state
    assert set(resumed.prepare(1, rng, Heartbeat())) == {
        keys.PLANNER_PREFIX + "warm_start_s",
        keys.PLANNER_PREFIX + "warm_start_cost",
    }
    assert (resumed.phases.count, resumed.collision_checks) == (6, whole.collision_checks)
    for a, b in zip(resumed.planner.parameters(), whole.planner.parameters(), strict=True):
        np.testing.assert_array_equal(a.detach().numpy(), b.detach().numpy())
    assert resumed.prepare(2, rng) == {}  # done: the next iteration has no warm start


def test_tau_hat_is_scored_on_the_new_tuples_before_it_is_refit_on_them():
    """The tracking diagnostic, by hand: two segments of length 3 and 4 at 2 distance units per step
    (1.5 and 2 steps as the crow flies), each taking the agent 5 steps; a tau_hat of 12 units (6 steps) is
    1 step off on average and over (bias +1), the Euclidean cost 3.25 under. In a curriculum it scores
    tau_hat as it was before the refit on those tuples."""
    from copilot_ray.planning.curriculum import tau_hat_tracking

    starts = np.zeros((2, 2))
    ends = np.array([[3.0, 0.0], [0.0, 4.0]])
    steps = np.array([5.0, 5.0])
    got = tau_hat_tracking(
        lambda a, b: np.full(len(a), 12.0),
        lambda a, b: np.linalg.norm(b - a, axis=-1),
        starts,
        ends,
        steps,
        2.0,
    )
    assert got == {
        keys.DIAG_TAU_HAT_ERROR: pytest.approx(1.0),
        keys.DIAG_TAU_HAT_BIAS: pytest.approx(1.0),
        keys.DIAG_EUCLIDEAN_ERROR: pytest.approx(3.25),
    }
    assert tau_hat_tracking(None, None, starts[:0], ends[:0], steps[:0], 2.0) == {}

    curriculum, rng = _curriculum()
    curriculum.prepare(1, rng)
    starts, goals = (x[:4] for x in curriculum.env.tasks("train"))
    trees, _ = curriculum.trees(starts, goals, 2, rng)
    subtasks = _subtasks(trees)
    before = curriculum.cost_model.predict(subtasks["start"], subtasks["end"])
    step = float(curriculum.env.nominal_step_distance)
    learned = curriculum.learn(subtasks, rng)
    assert learned[keys.DIAG_TAU_HAT_ERROR] == pytest.approx(float(np.mean(np.abs(before / step - 5))))
