"""copilot_ray.planning.health: the finiteness check and the fault drill's hook."""

import math

import pytest
import torch

from copilot_ray.planning.health import (
    FAULT_ENV,
    NonFiniteStateError,
    check_finite,
    fill_nan,
    injected_fault,
    parse_fault,
)


def test_parse_fault_reads_component_and_iteration_and_names_the_variable_when_wrong():
    assert parse_fault("planner_nan@3") == ("planner", 3, None)
    assert parse_fault(" cost_model_nan@12:seed=1 ") == ("cost_model", 12, 1)
    assert parse_fault("") is None and parse_fault(None) is None
    for bad in ("planner@3", "agent_nan@3", "planner_nan@x", "planner_nan@3:seed"):
        with pytest.raises(ValueError, match=rf"{FAULT_ENV}='{bad}' is invalid"):
            parse_fault(bad)


def test_injected_fault_only_at_its_iteration(monkeypatch):
    monkeypatch.setenv(FAULT_ENV, "cost_model_nan@4")
    assert [injected_fault(i) for i in (3, 4, 5)] == [None, "cost_model", None]
    monkeypatch.setenv(FAULT_ENV, "planner_nan@4:seed=1")
    assert [injected_fault(4, s) for s in (0, 1)] == [None, "planner"]
    monkeypatch.delenv(FAULT_ENV)
    assert injected_fault(4) is None


def test_check_finite_names_every_broken_component():
    good, bad, inf = torch.nn.Linear(2, 2), torch.nn.Linear(2, 2), torch.nn.Linear(2, 2)
    check_finite({"planner": good.parameters()}, 1, "now")
    fill_nan(bad.parameters())
    assert math.isnan(float(bad.weight[0, 0]))
    with torch.no_grad():
        inf.bias[0] = math.inf
    with pytest.raises(
        NonFiniteStateError, match="iteration 7: .* in the planner and the cost_model at the end"
    ):
        check_finite(
            {
                "planner": list(bad.parameters()),
                "cost_model": list(inf.parameters()),
                "x": list(good.parameters()),
            },
            7,
            "at the end",
        )
