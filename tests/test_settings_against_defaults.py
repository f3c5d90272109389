"""The report holds each configuration's logged settings against this checkout's defaults (analysis/defaults.py):
the defaults it reads without building a config must be exactly what a default run logs, and a row must
name what its runs changed and what they lacked."""

from __future__ import annotations

import pytest

from analysis.aggregate import ConfigSummary
from analysis.defaults import SAME, defaults_table, differences, short
from analysis.load import Trial
from copilot_ray.keys import ALGORITHM_TAG, GIT_COMMIT_TAG
from copilot_ray.registry import ALGORITHMS, RunContext, get_algorithm
from copilot_ray.settings import PARAM_LIMIT, logged_text

CASES = [(name, preset) for name in sorted(ALGORITHMS) for preset in [None, *get_algorithm(name).presets]]


@pytest.mark.parametrize(("algorithm", "preset"), CASES)
def test_the_defaults_read_without_a_config_are_what_a_default_run_logs(algorithm, preset):
    from copilot_ray.tracking import params_for_mlflow
    from copilot_ray.trials.description import effective_settings

    entry = get_algorithm(algorithm)
    config = entry.build_config({"preset": preset} if preset else {}, RunContext(env_id="maze-point"))
    logged = params_for_mlflow(effective_settings(config, entry.settings))
    if "preset" in entry.settings:
        logged["preset"] = preset or "default"  # the sweep's tracker logs the preset by name
    assert entry.defaults_as_logged(preset) == logged


def test_hrl_runs_log_their_hierarchy_settings():
    # hrl.c is the record's field hrl_c: before settings records were read whole, it was never logged.
    from copilot_ray.trials.description import effective_settings

    entry = get_algorithm("hrl")
    config = entry.build_config({"hrl.c": 5}, RunContext(env_id="maze-point"))
    assert effective_settings(config, entry.settings)["hrl.c"] == 5


def _config(params: dict[str, str], algorithm: str = "copilot", label: str = "row") -> ConfigSummary:
    tags = {ALGORITHM_TAG: algorithm, GIT_COMMIT_TAG: "580fa7894d52"}
    trial = Trial(
        "r", "r", "FINISHED", "default", "0", tags, params={**params, "seed": "0", "env.id": "maze-point"}
    )
    return ConfigSummary("default", label, [trial], [trial], {}, 1.0)


def test_a_row_names_the_values_its_runs_changed_and_the_settings_they_lacked():
    logged = get_algorithm("copilot").defaults_as_logged()
    logged["planner.lr"] = "0.0033798304921413393"  # stage 1's winner
    del logged["planner.mean"]  # a setting added after the runs' commit
    differ, missing = differences(_config(logged))
    default_lr = get_algorithm("copilot").settings["planner.lr"].default
    assert differ == [("planner.lr", "0.0033798304921413393", logged_text(default_lr))]
    assert missing == [
        ("planner.mean", logged_text(get_algorithm("copilot").settings["planner.mean"].default))
    ]
    row = defaults_table([_config(logged)]).rows[0]
    assert row[1] == "580fa78"
    assert row[2] == f"planner.lr = 0.00338 ({short(logged_text(default_lr))})"
    assert row[3].startswith("planner.mean (now ")


def test_a_run_at_this_checkouts_defaults_differs_in_nothing_and_a_preset_is_held_against_its_own():
    assert defaults_table([_config(get_algorithm("copilot").defaults_as_logged())]).rows[0][2:] == [
        SAME,
        SAME,
    ]
    literal = get_algorithm("copilot").defaults_as_logged("paper_literal")
    assert differences(_config(literal)) == ([], [])
    # The same values held against the default preset would differ.
    literal["preset"] = "default"
    assert differences(_config(literal))[0]


def test_what_cannot_be_compared_says_why():
    gone = defaults_table([_config({}, algorithm="dqn"), _config({"preset": "mine"}), _config({})]).rows
    assert gone[0][2] == "not compared: algorithm 'dqn' is not one of this checkout's"
    assert gone[1][2] == "not compared: preset 'mine' is not one of this checkout's copilot presets"
    assert gone[2][2] == "not compared: its runs logged no settings"  # not every setting "not logged"


def test_numbers_are_shortened_and_everything_else_kept():
    assert short("0.00027389695952347") == "0.0002739"
    assert [short(t) for t in ("10000", "[64, 64]", "None", "leaky", "0.98")] == [
        "10000",
        "[64, 64]",
        "None",
        "leaky",
        "0.98",
    ]


def test_a_value_is_logged_and_read_back_in_one_form_cut_to_mlflows_limit():
    from copilot_ray.tracking import params_for_mlflow

    long = "x" * (PARAM_LIMIT + 100)
    assert params_for_mlflow({"a": long, "b": {"c": [64, 64]}}) == {
        "a": long[:PARAM_LIMIT],
        "b.c": "[64, 64]",
    }
    assert logged_text(long) == long[:PARAM_LIMIT] and logged_text(None) == "None"
