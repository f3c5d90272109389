"""Every CO-PILOT setting is declared once (settings.py): the config, the spec, the CLI and the README agree.

Each case of settings drift found before the table existed has a test here: `tree_depth: 0` refused by
a spec, `planner.clip: 1.5` accepted until a trial ran, `null` refused by a spec for optional planner
settings, alpha-schedule kinds copied by hand, the CLI's choices typed out again.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest

from copilot_ray import train
from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
from copilot_ray.algorithms.copilot.settings import (
    PRESETS,
    SETTINGS,
    defaults,
    render_readme,
)
from copilot_ray.planning.alpha_schedule import CLOCKS, KINDS, AlphaSchedule
from copilot_ray.registry import RunContext
from copilot_ray.sweep_spec import SpecError, build_algorithm_config, parse_spec

ROOT = Path(__file__).resolve().parents[1]


def spec_with(config: dict) -> dict:
    return {
        "name": "t",
        "env": {"id": "maze-point", "config": {"layout": "empty"}},
        "config": config,
        "stop": {"env_steps": 100, "min_evaluations": 0},
    }


def config_with(key: str, value) -> CoPilotConfig:
    run = RunContext("maze-point", {"layout": "empty"})
    return CoPilotConfig.from_settings({key: value}, run)


# A value each setting must refuse, and one (not its default) it must take; None: no such value.
def bad_value(s):
    if s.kind == "int":
        return -1
    if s.kind == "float":
        return -1.0 if s.key != "target_entropy" else "low"
    if s.kind == "bool":
        return "yes"
    if s.kind == "str":
        return "no-such-choice"
    if s.kind == "list":
        return ["x"]
    return 42  # schedule


CONFIG_SETTINGS = [s for s in SETTINGS.values() if s.target != "alpha_schedule" or s.key == "alpha_schedule"]


def test_every_default_obeys_its_own_rule_and_is_what_a_fresh_config_holds():
    fresh = CoPilotConfig()
    values = fresh.setting_values()
    for s in CONFIG_SETTINGS:
        if s.key == "alpha_schedule":
            assert AlphaSchedule.from_dict(values[s.key]) == AlphaSchedule.from_dict(s.default)
            continue
        assert s.problem(s.default) is None, s.key
        assert values[s.key] == s.default, s.key


def test_the_default_is_one_configuration_from_python_the_train_cli_and_a_spec():
    # A user who builds the default from Python once got 30 tasks per iteration where the CLI and the
    # specs (and so the evidence) used 2: every entry point must hold the same settings, preset included.
    python = CoPilotConfig().setting_values()
    cli = train.build_config(train.parse_args([])).setting_values()
    spec = parse_spec({"name": "t", "env": {"id": "maze-point"}, "stop": {"env_steps": 200_000}})
    (point,) = spec.trial_plan()
    from_spec = build_algorithm_config(point, spec).setting_values()
    assert set(python) == {s.key for s in CONFIG_SETTINGS}
    assert cli == python
    assert from_spec == python


@pytest.mark.parametrize("setting", CONFIG_SETTINGS, ids=lambda s: s.key)
def test_spec_and_config_refuse_the_same_bad_value_naming_the_key(setting):
    value = bad_value(setting)
    with pytest.raises(SpecError, match=rf"config\.{setting.key}: "):
        parse_spec(spec_with({setting.key: value}))
    with pytest.raises(ValueError, match=rf"CoPilotConfig: {setting.key}="):
        config_with(setting.key, value).validate()


def test_tree_depth_zero_is_refused_in_both_the_agent_alone_is_algorithm_sac():
    with pytest.raises(SpecError, match=r"config\.tree_depth: 0 is invalid"):
        parse_spec(spec_with({"tree_depth": 0}))
    with pytest.raises(ValueError, match=r"CoPilotConfig: tree_depth=0 is invalid"):
        config_with("tree_depth", 0).validate()


@pytest.mark.parametrize("clip", [1.5, 1.0, 0.0])
def test_planner_clip_outside_0_1_fails_at_the_spec_not_inside_a_trial(clip):
    with pytest.raises(SpecError, match=r"config\.planner\.clip: .* must be a number in \(0, 1\)"):
        parse_spec(spec_with({"planner.clip": clip}))
    with pytest.raises(ValueError, match=r"planner\.clip="):
        config_with("planner.clip", clip).validate()


@pytest.mark.parametrize(
    "key", ["planner.max_grad_norm", "planner.target_kl", "planner.max_kl", "planner.std_final"]
)
def test_null_switches_an_optional_planner_setting_off_in_both(key):
    parse_spec(spec_with({key: None}))
    config = config_with(key, None)
    config.validate()
    assert config.planner[key.split(".")[1]] is None


def test_alpha_schedule_fields_and_choices_come_from_the_schedule_module():
    dotted = {k.split(".", 1)[1] for k in SETTINGS if k.startswith("alpha_schedule.")}
    assert dotted == {f.name for f in fields(AlphaSchedule)}
    assert SETTINGS["alpha_schedule.kind"].choices == KINDS
    assert SETTINGS["alpha_schedule.clock"].choices == CLOCKS


def test_nested_defaults_are_the_dicts_the_config_starts_with():
    fresh = CoPilotConfig()
    assert fresh.planner == defaults("planner") and fresh.cost_model == defaults("cost_model")
    assert "std_final" in fresh.planner and fresh.planner["std_final"] == 0.015


def test_presets_name_only_settings_and_paper_literal_differs_where_the_readme_says():
    for name, values in PRESETS.items():
        for key, value in values.items():
            if key in ("planner", "cost_model"):
                for field_name, v in value.items():
                    assert SETTINGS[f"{key}.{field_name}"].problem(v) is None, (name, key, field_name)
            else:
                assert SETTINGS[key].problem(value) is None, (name, key)
    paper = config_with("preset", "paper_literal")
    assert paper.after_failure == "continue" and paper.subtask_reward == "halving"
    assert paper.planner["std_final"] is None
    # paper_literal isolates CO-PILOT's readings: the agent's SAC settings stay the baselines'.
    assert paper.initial_alpha == CoPilotConfig().initial_alpha == 0.02
    assert paper.agent_input == CoPilotConfig().agent_input == "state_goal_delta"


def test_unknown_copilot_argument_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"unknown setting 'tree_deph' \(did you mean 'tree_depth'\?\)"):
        CoPilotConfig().copilot(tree_deph=3)
    with pytest.raises(ValueError, match=r"actor_lr is SAC's: set it with \.training"):
        CoPilotConfig().copilot(actor_lr=1e-3)


def test_the_settings_pages_tables_are_current():
    page = (ROOT / "docs" / "settings.md").read_text()
    assert render_readme(page) == page, (
        "docs/settings.md's settings tables are stale: run "
        "`.venv/bin/python -m copilot_ray.algorithms.copilot.settings --write docs/settings.md`"
    )
