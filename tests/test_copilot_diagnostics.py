"""The diagnostics count what they claim on hand-made trees and sub-task records."""

import numpy as np
import pytest

from copilot_ray import keys
from copilot_ray.algorithms.sac.traversal_diagnostics import traversal_diagnostics
from copilot_ray.envs import make
from copilot_ray.planning.plan_diagnostics import (
    plan_diagnostics,
    tau_hat_profile,
)


def euclid(a, b):
    return np.linalg.norm(np.asarray(b) - np.asarray(a), axis=-1)


def test_plan_diagnostics_on_a_hand_made_tree():
    env = make("maze-point", layout="u-maze").unwrapped
    wall = np.array([0.5, 0.5])  # inside u-maze's middle wall
    assert not env.is_free(wall)
    # depth 2: nodes 0..4; layer 1 adds node 2, layer 2 adds nodes 1 and 3.
    tree = np.array([[[0.1, 0.1], [0.1, 0.2], wall, [0.1, 0.3], [0.1, 0.7]]], np.float32)
    diag = plan_diagnostics(
        tree,
        2,
        point_collides=lambda p: env.segments_collide(p, p),
        distance=euclid,
        reachable_length=lambda k: 0.45 if k == 1 else 0.15,
    )
    assert diag[keys.DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "1"] == 1.0  # node 2
    assert diag[keys.DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "2"] == 0.0  # nodes 1 and 3
    seg1 = [euclid([0.1, 0.1], wall), euclid(wall, [0.1, 0.7])]
    assert diag[keys.DIAG_SEGMENT_LENGTH_LAYER + "1"] == pytest.approx(np.mean(seg1), rel=1e-5)
    assert diag[keys.DIAG_SEGMENT_UNREACHABLE_LAYER + "1"] == pytest.approx(0.5)  # 0.566 > 0.45, 0.447 < 0.45
    seg2 = [0.1, euclid([0.1, 0.2], wall), euclid(wall, [0.1, 0.3]), 0.4]
    assert diag[keys.DIAG_SEGMENT_LENGTH_LAYER + "2"] == pytest.approx(np.mean(seg2), rel=1e-5)
    assert diag[keys.DIAG_SEGMENT_UNREACHABLE_LAYER + "2"] == pytest.approx(0.75)  # all but the first
    assert diag[keys.DIAG_REACHABLE_LENGTH_LAYER + "2"] == 0.15


def records(rows):
    """rows: (task, layer, index, reached, start, end)"""
    task, layer, index, reached, start, end = zip(*rows, strict=True)
    return {
        "task": np.array(task),
        "layer": np.array(layer),
        "index": np.array(index),
        "reached": np.array(reached),
        "start": np.array(start, float),
        "end": np.array(end, float),
        "collided": np.array([False] * (len(rows) - 1) + [True]),
    }


def test_traversal_diagnostics_splits_success_by_the_previous_subtask():
    o = [0.0, 0.0]
    rows = [
        # task 0, layer 1: reached, failed, failed, reached  -> pairs (R->F), (F->F), (F->R)
        (0, 1, 1, True, o, [0.1, 0.0]),
        (0, 1, 2, False, o, [0.2, 0.0]),
        (0, 1, 3, False, o, o),
        (0, 1, 4, True, o, [0.0, 0.3]),
        # task 0, layer 0: one sub-task, no pair
        (0, 0, 1, False, o, o),
        # task 1, layer 1: reached, reached -> (R->R); shuffled order must not matter
        (1, 1, 2, True, o, o),
        (1, 1, 1, True, o, o),
    ]
    shuffled = records(rows)
    diag = traversal_diagnostics(shuffled, distance=euclid, success_radius=0.05)
    assert diag[keys.DIAG_SUCCESS_AFTER_REACHED] == pytest.approx(1 / 2)  # R->F, R->R
    assert diag[keys.DIAG_SUCCESS_AFTER_FAILED] == pytest.approx(1 / 2)  # F->F, F->R
    assert diag[keys.DIAG_DTAU_TUPLE_LENGTH_MAX] == pytest.approx(0.3)
    assert diag[keys.DIAG_DTAU_TUPLE_LENGTH_MEAN] == pytest.approx(0.6 / 7)
    assert diag[keys.DIAG_SUBTASK_COLLIDED] == pytest.approx(1 / 7)
    goals = np.array([[0.01, 0.0]] * 7)  # every first sub-goal within 0.05 of its start
    goals[4] = [0.5, 0.5]  # ... but task 0's layer-0 one
    diag = traversal_diagnostics({**shuffled, "goal": goals}, distance=euclid, success_radius=0.05)
    assert diag[keys.DIAG_FIRST_SUBTASK_TRIVIAL] == pytest.approx(2 / 3)


def test_tau_hat_profile_measures_the_segments_it_was_given():
    starts = np.array([[0.5, 0.5], [0.2, 0.2]])
    directions = np.array([[1.0, 0.0], [0.0, 1.0]])
    dist, tau = tau_hat_profile(
        lambda a, b: 2 * euclid(a, b), euclid, starts, directions, np.array([0.1, 0.6]), 0, 1
    )
    np.testing.assert_allclose(dist, [0.1, (0.5 + 0.6) / 2])  # 0.5 + 0.6 clipped at the border to 0.5
    np.testing.assert_allclose(tau, 2 * dist)


def test_dtau_tuples_of_failed_subtasks_end_state_or_lower_bound():
    from copilot_ray.planning.curriculum import dtau_tuples

    subtasks = {
        "start": np.array([[0.0, 0.0], [0.5, 0.5]]),
        "end": np.array([[0.1, 0.0], [0.5, 0.55]]),
        "goal": np.array([[0.11, 0.0], [0.5, 0.75]]),
        "steps": np.array([9, 25]),
        "reached": np.array([True, False]),
    }
    starts, ends, steps = dtau_tuples(subtasks, "end_state", euclid, 0.01)
    np.testing.assert_allclose(ends, subtasks["end"])
    np.testing.assert_allclose(steps, [9, 25])
    starts, ends, steps = dtau_tuples(subtasks, "lower_bound", euclid, 0.01)
    np.testing.assert_allclose(starts, subtasks["start"])
    # the reached sub-task keeps its tuple; the failed one is charged to its sub-goal: 25 steps taken
    # + 0.2 left at 0.01 per step
    np.testing.assert_allclose(ends, [[0.1, 0.0], [0.5, 0.75]])
    np.testing.assert_allclose(steps, [9, 45])
