"""Adding an algorithm or an env is one module plus one registry line; specs, plans and configs follow."""

from __future__ import annotations

import pytest

from copilot_ray import registry
from copilot_ray.envs import registry as env_registry
from copilot_ray.sweep_spec import SpecError, build_algorithm_config, format_plan, parse_spec
from copilot_ray.trials.spec_trial import SpecTrial

TOY = ("tests.toy_algorithm", "tests.toy_algorithm:ToyPPOConfig", "tests.toy_algorithm:ToyPPOTrial")


@pytest.fixture
def toy(monkeypatch):
    # The one registry line a new algorithm adds (here undone after the test).
    monkeypatch.setitem(registry.ALGORITHMS, "toy-ppo", TOY)
    monkeypatch.setitem(
        env_registry.ENV_FACTORIES, "toy-cartpole", "gymnasium.envs.classic_control:CartPoleEnv"
    )


def toy_spec(**changes):
    spec = {
        "name": "toy",
        "env": {"id": "toy-cartpole"},
        "algorithm": "toy-ppo",
        "config": {"num_epochs": 3},
        "search": {"lr": {"grid": [1e-4, 1e-3]}},
        "searcher": {"type": "grid", "metric": "env_runners/episode_return_mean", "mode": "max"},
        "stop": {"iterations": 1},
    }
    spec.update(changes)
    return spec


def test_a_registered_toy_algorithm_runs_through_spec_plan_and_config(toy):
    spec = parse_spec(toy_spec())
    assert spec.trial_plan() == [{"lr": 1e-4, "seed": 0}, {"lr": 1e-3, "seed": 0}]
    assert "toy-ppo on toy-cartpole" in format_plan(spec)
    config = build_algorithm_config(spec.trial_plan()[1], spec)
    assert type(config).__name__ == "ToyPPOConfig"
    assert config.lr == 1e-3 and config.num_epochs == 3 and config.env == "toy-cartpole"
    trial = registry.get_algorithm("toy-ppo").trial_class()
    assert trial.__name__ == "ToyPPOTrial" and issubclass(trial, SpecTrial)


def test_the_toy_algorithms_own_rules_and_metrics_apply(toy):
    with pytest.raises(
        SpecError, match=r"config\.num_epochs: 0 is invalid: num_epochs must be an integer >= 1"
    ):
        parse_spec(toy_spec(config={"num_epochs": 0}))
    with pytest.raises(SpecError, match=r"config\.tree_depth: unknown key"):
        parse_spec(toy_spec(config={"tree_depth": 3}))  # CO-PILOT's settings are not the toy's
    bad_metric = {"type": "grid", "metric": "copilot/validation/success_planned", "mode": "max"}
    with pytest.raises(SpecError, match=r"toy-ppo does not log this metric"):
        parse_spec(toy_spec(searcher=bad_metric))


def test_unknown_algorithm_names_the_registered_ones():
    with pytest.raises(
        registry.UnknownAlgorithmError, match=r"unknown algorithm 'copilt' \(did you mean 'copilot'\?\)"
    ):
        registry.get_algorithm("copilt")
    with pytest.raises(
        SpecError,
        match=r"algorithm: 'nope' is invalid: unknown algorithm; known: \['copilot', 'her', 'hrl', 'next', 'ppo', 'rrt_curriculum', 'rrt_star', 'sac', 'sgt_pg', 'sorb', 'sorb_map'\]",
    ):
        parse_spec(toy_spec(algorithm="nope"))
