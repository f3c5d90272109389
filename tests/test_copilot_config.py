"""CoPilotConfig: the builder sets CO-PILOT's knobs and validate() names the bad key and value."""

import pytest

from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
from copilot_ray.algorithms.copilot.settings import SETTINGS
from copilot_ray.algorithms.sac.traversal_env import TRAVERSAL_ENV_ID


def config(**copilot):
    return CoPilotConfig().environment("maze-point", env_config={"layout": "u-maze"}).copilot(**copilot)


def test_builder_merges_dicts_and_resolves_presets():
    c = config(tree_depth=3, planner={"std": 0.1}, alpha_schedule="paper_warm_start")
    assert c.tree_depth == 3
    assert c.planner["std"] == 0.1 and c.planner["lr"] == 0.005  # other keys keep their defaults
    assert c.alpha_schedule == {
        "kind": "linear",
        "clock": "global",
        "start": 1.0,
        "end": 0.0,
        "duration": 2.0,
    }


def test_validate_swaps_in_the_traversal_env_and_the_fast_learner():
    c = config(tree_depth=2, tau_max=7)
    c.validate()
    assert c.env == TRAVERSAL_ENV_ID and c.goal_env == "maze-point"
    assert c.env_config["goal_env"] == "maze-point" and c.env_config["tau_max"] == 7
    assert c.env_config["goal_env_config"] == {"layout": "u-maze"}
    assert "gc_sac" in c.learner_config_dict
    c.validate()  # idempotent: validating twice keeps the goal env
    assert c.goal_env == "maze-point"


@pytest.mark.parametrize(
    ("knobs", "match"),
    [
        ({"tree_depth": 11}, r"tree_depth=11"),
        ({"tree_depth": -1}, r"tree_depth=-1"),
        ({"repetitions": 0}, r"repetitions=0"),
        ({"tau_max": 2.5}, r"tau_max=2.5"),
        ({"collision_penalty": -1}, r"collision_penalty=-1"),
        ({"updates_per_env_step": 0}, r"updates_per_env_step=0"),
        ({"collision_cost": "area"}, r"collision_cost='area'.*indicator"),
        ({"planner": {"max_grad_norm": 0}}, r"planner\.max_grad_norm=0"),
        ({"planner": {"target_kl": -1.0}}, r"planner\.target_kl=-1\.0"),
        ({"alpha_schedule": {"kind": "constant", "alpha": 1.5}}, r"alpha_schedule=.*1\.5"),
        ({"planner": {"stdd": 0.1}}, r"planner\.stdd=0\.1.*known keys"),
        ({"planner": {"std": 0}}, r"planner\.std=0"),
        ({"cost_model": {"fit_steps": 0}}, r"cost_model\.fit_steps=0"),
    ],
)
def test_bad_values_are_rejected_with_key_and_value(knobs, match):
    with pytest.raises(ValueError, match=match):
        config(**knobs).validate()


def test_vectorised_runners_are_rejected():
    c = config().env_runners(num_envs_per_env_runner=4)
    with pytest.raises(ValueError, match="num_envs_per_env_runner=4"):
        c.validate()


@pytest.mark.parametrize(
    ("updates_per_env_step", "training_intensity", "batch", "ratio"),
    [
        (None, None, 256, 1.0),  # SB3's one gradient step per env step
        (0.25, None, 256, 0.25),
        (None, 512.0, 256, 2.0),  # RLlib's meaning: 512 replayed timesteps per sampled one
        (None, 64.0, 128, 0.5),
    ],
)
def test_update_to_data_ratio_from_either_knob(updates_per_env_step, training_intensity, batch, ratio):
    c = config(updates_per_env_step=updates_per_env_step).training(
        training_intensity=training_intensity, train_batch_size_per_learner=batch
    )
    c.validate()
    assert c.utd_ratio() == pytest.approx(ratio)
    # The fast learner records the same ratio it was built with.
    assert c.learner_config_dict["gc_sac"]["updates_per_env_step"] == pytest.approx(ratio)


def test_both_update_to_data_knobs_at_once_are_rejected():
    c = config(updates_per_env_step=0.5).training(training_intensity=128.0)
    with pytest.raises(ValueError, match=r"updates_per_env_step=0\.5 and training_intensity=128\.0"):
        c.validate()
    with pytest.raises(ValueError, match=r"training_intensity=0"):
        config().training(training_intensity=0).validate()


def test_collision_penalty_defaults_follow_the_collision_cost():
    assert config().collision_penalty_value() == 10.0  # paper: per colliding segment
    assert config(collision_cost="length").collision_penalty_value() == 100.0  # reference: per unit length
    assert config(collision_cost="length", collision_penalty=30.0).collision_penalty_value() == 30.0


def test_paper_literal_preset_sets_every_reading_and_later_arguments_override_it():
    from copilot_ray.algorithms.copilot.settings import PRESETS

    c = config(preset="paper_literal")
    literal = PRESETS["paper_literal"]
    for key, value in literal.items():
        if key == "planner":
            assert all(c.planner[k] == v for k, v in value.items())
        else:
            assert getattr(c, key) == value, key
    assert c.preset == "paper_literal"
    assert c.planner["lr"] == 0.005  # planner keys the preset does not name keep their values
    # Arguments of the same call override the preset, whatever their order.
    c = config(tau_max=40, preset="paper_literal", planner={"std": 0.02})
    assert c.tau_max == 40 and c.planner["std"] == 0.02 and c.after_failure == "continue"
    c.validate()
    assert c.env_config["tau_max"] == 40 and c.env_config["after_failure"] == "continue"


def test_unknown_preset_is_rejected_naming_it():
    with pytest.raises(ValueError, match=r"preset='paper'.*paper_literal"):
        config(preset="paper")


def test_traversal_rules_reach_the_env_config():
    c = config(step_limit="scaled", after_failure="abort_layer", subtask_reward="uniform", reward_scale=2.0)
    c.validate()
    rules = {k: c.env_config[k] for k in ("step_limit", "after_failure", "subtask_reward", "reward_scale")}
    assert rules == {
        "step_limit": "scaled",
        "after_failure": "abort_layer",
        "subtask_reward": "uniform",
        "reward_scale": 2.0,
    }


@pytest.mark.parametrize(
    ("knobs", "match"),
    [
        ({"step_limit": "exp"}, r"step_limit='exp'"),
        ({"after_failure": "retry"}, r"after_failure='retry'"),
        ({"subtask_reward": "dense"}, r"subtask_reward='dense'"),
        ({"agent_collision": "stop"}, r"agent_collision='stop'"),
        ({"agent_collision_penalty": -0.5}, r"agent_collision_penalty=-0.5"),
        ({"reward_scale": 0}, r"reward_scale=0"),
        ({"traversal_tree": "best"}, r"traversal_tree='best'"),
        ({"eval_action": "greedy"}, r"eval_action='greedy'"),
        ({"planner_warm_start": -3}, r"planner_warm_start=-3"),
        ({"planner": {"noise": "gaussian"}}, r"planner\.noise='gaussian'"),
        ({"planner": {"clip": 1.5}}, r"planner\.clip=1\.5"),
        ({"planner": {"std_final": 0}}, r"planner\.std_final=0"),
        ({"planner": {"std_anneal_phases": 0}}, r"planner\.std_anneal_phases=0"),
    ],
)
def test_bad_reading_knobs_are_rejected_with_key_and_value(knobs, match):
    with pytest.raises(ValueError, match=match):
        config(**knobs).validate()


def test_copilot_and_agent_take_named_arguments_with_their_defaults():
    import inspect

    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig

    params = inspect.signature(CoPilotConfig().copilot).parameters
    undotted = {k for k, s in SETTINGS.items() if "." not in k and s.target != "training"}
    assert set(params) == undotted | {"planner", "cost_model"}
    assert params["tree_depth"].default == SETTINGS["tree_depth"].default
    assert params["tree_depth"].kind is inspect.Parameter.KEYWORD_ONLY
    assert params["planner"].default["std"] == SETTINGS["planner.std"].default
    assert f"tree_depth (int, default {SETTINGS['tree_depth'].default})" in CoPilotConfig.copilot.__doc__
    agent = inspect.signature(GoalSACConfig().agent).parameters
    assert "tau_max" in agent and "tree_depth" not in agent and "actor_lr" not in agent
    with pytest.raises(ValueError, match="unknown setting 'tree_depht'.*tree_depth"):
        CoPilotConfig().copilot(tree_depht=3)
