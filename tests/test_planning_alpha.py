"""Alpha schedules: both paper readings, the other kinds, validation and state."""

import pytest
import torch

from copilot_ray.planning import AlphaClock, AlphaSchedule

torch.set_num_threads(1)


def test_paper_warm_start_global_clock():
    s = AlphaSchedule.preset("paper_warm_start")
    assert s.clock == "global"
    # "start from 1 and reduce towards 0 during the first two episodes", then pure time cost
    vals = [s.value(episode=e, repetition=e % 5, repetitions=5) for e in range(8)]
    assert vals[:3] == pytest.approx([1.0, 0.5, 0.0])
    assert vals[3:] == pytest.approx([0.0] * 5)


def test_paper_per_task_clock_restarts_every_task_batch():
    s = AlphaSchedule.preset("paper_per_task")
    clock = AlphaClock(s, repetitions=5)
    seen = []
    for _ in range(10):  # two task mini-batches of b = 5 repetitions
        seen.append(clock.value)
        clock.advance()
    assert seen == pytest.approx([0.9, 0.7, 0.5, 0.3, 0.1] * 2)
    assert s.value(0, 0, 1) == pytest.approx(0.9)  # b = 1: the start value


def test_other_kinds():
    c = AlphaSchedule.from_dict({"kind": "constant", "alpha": 0.3})
    assert c.value(100) == 0.3
    e = AlphaSchedule.from_dict({"kind": "exponential", "start": 1.0, "end": 0.2, "decay": 0.5})
    assert [e.value(t) for t in range(3)] == pytest.approx([1.0, 0.6, 0.4])
    st = AlphaSchedule.from_dict({"kind": "step", "boundaries": [2, 5], "values": [1.0, 0.5, 0.0]})
    assert [st.value(t) for t in range(7)] == [1.0, 1.0, 0.5, 0.5, 0.5, 0.0, 0.0]
    lin = AlphaSchedule.from_dict({"kind": "linear", "start": 0.0, "end": 1.0, "duration": 4})
    assert lin.value(2) == pytest.approx(0.5) and lin.value(10) == 1.0
    per = AlphaSchedule.from_dict({"kind": "step", "clock": "per_task", "boundaries": [1], "values": [1, 0]})
    assert per.value(episode=7, repetition=0, repetitions=3) == 1.0
    assert per.value(episode=8, repetition=1, repetitions=3) == 0.0


@pytest.mark.parametrize(
    "spec, key",
    [
        ({"kind": "constant", "alpha": 1.5}, "alpha=1.5"),
        ({"kind": "linear", "start": -0.1, "end": 0.0, "duration": 2}, "start=-0.1"),
        ({"kind": "linear", "start": 1.0, "end": 0.0}, "duration=None"),
        ({"kind": "linear", "start": 1.0, "end": 0.0, "duration": 0}, "duration=0"),
        ({"kind": "exponential", "decay": 1.5}, "decay=1.5"),
        ({"kind": "step", "boundaries": [1], "values": [1.0]}, "boundaries"),
        ({"kind": "step", "boundaries": [1], "values": [1.0, 2.0]}, "values\\[1\\]=2.0"),
        ({"kind": "constant", "start": 0.5}, "'start'"),
        ({"kind": "cosine"}, "kind='cosine'"),
        ({"kind": "constant", "clock": "daily"}, "clock='daily'"),
        ({"kind": "constant", "alpah": 0.5}, "'alpah'"),
        ({"preset": "nope"}, "preset='nope'"),
    ],
)
def test_validation_names_key_and_value(spec, key):
    with pytest.raises(ValueError, match=key):
        AlphaSchedule.from_dict(spec)


@pytest.mark.parametrize("name", ["paper_warm_start", "paper_per_task", "euclidean", "time_cost"])
def test_dict_round_trip(name):
    s = AlphaSchedule.preset(name)
    assert AlphaSchedule.from_dict(s.to_dict()) == s
    step = AlphaSchedule.from_dict({"kind": "step", "boundaries": [3], "values": [0.8, 0.2]})
    assert AlphaSchedule.from_dict(step.to_dict()) == step


def test_preset_with_override():
    s = AlphaSchedule.from_dict({"preset": "paper_warm_start", "duration": 4})
    assert s.value(2) == pytest.approx(0.5)


def test_clock_state_dict_round_trip():
    clock = AlphaClock(AlphaSchedule.preset("paper_per_task"), repetitions=5)
    for _ in range(7):
        clock.advance()
    state = clock.state_dict()
    other = AlphaClock(AlphaSchedule.preset("euclidean"))
    other.load_state_dict(state)
    assert other.episode == 7 and other.repetition == 2 and other.schedule == clock.schedule
    assert other.value == pytest.approx(clock.value) == pytest.approx(0.5)
    assert AlphaClock({"preset": "paper_warm_start"}).value == 1.0
