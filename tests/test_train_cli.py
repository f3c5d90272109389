"""`python -m copilot_ray.train`: flags generated from the settings, presets and bad input, without Ray."""

import subprocess
import sys

import pytest

from copilot_ray import train
from copilot_ray.algorithms.copilot.settings import SETTINGS


def test_preset_flag_sets_the_readings_and_explicit_flags_override_it():
    config = train.build_config(train.parse_args(["--preset", "paper_literal", "--tau-max", "40"]))
    assert config.preset == "paper_literal" and config.after_failure == "continue"
    assert config.tau_max == 40 and config.subtask_reward == "halving"
    default = train.build_config(train.parse_args([]))
    assert default.preset is None and default.subtask_reward == "uniform" and default.tau_max == 25


def test_every_setting_but_the_schedule_fields_is_a_flag_with_its_rule_in_the_help():
    parser_help = subprocess.run(
        [sys.executable, "-m", "copilot_ray.train", "--help"], capture_output=True, text=True, check=True
    ).stdout
    flags = [s.flag for s in SETTINGS.values() if s.on_cli]
    assert len(flags) > 40 and "--planner-std-final" in flags and "--initial-alpha" in flags
    for s in SETTINGS.values():
        if s.on_cli:
            assert s.flag in parser_help, s.flag
    assert "--alpha-schedule-kind" not in parser_help  # schedule fields are for sweep specs


def test_flag_values_are_read_as_in_a_spec_and_reach_the_config():
    args = train.parse_args(
        [
            "--planner-std-final",
            "null",
            "--planner-hidden",
            "[8, 8]",
            "--actor-lr",
            "1e-3",
            "--fast-learner",
            "false",
            "--eval-tasks",
            "7",  # the old name of --eval-num-tasks still works
            "--after-failure",
            "abort_layer",
        ]
    )
    config = train.build_config(args)
    assert config.planner["std_final"] is None and config.planner["hidden"] == [8, 8]
    assert config.actor_lr == 1e-3 and config.fast_learner is False
    assert config.eval_num_tasks == 7 and config.after_failure == "abort_layer"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--preset", "paper"], "--preset 'paper' is invalid: must be one of"),
        (["--planner-clip", "1.5"], "--planner-clip 1.5 is invalid: must be a number in (0, 1)"),
        (["--tree-depth", "11"], "--tree-depth 11 is invalid: must be an integer in [0, 10]"),
        (
            ["--collision-cost", "area"],
            "--collision-cost 'area' is invalid: must be one of ['indicator', 'length']",
        ),
        (
            ["--updates-per-env-step", "0.5", "--training-intensity", "64"],
            "both set the update-to-data ratio",
        ),
    ],
)
def test_bad_values_exit_2_naming_flag_and_value(argv, message, capsys):
    assert train.main([*argv, "--stop-iters", "1"]) == 2
    assert message in capsys.readouterr().err


def test_bad_input_is_refused_before_ray_is_imported():
    code = (
        "import sys; from copilot_ray import train; "
        "rc = train.main(['--planner-clip', '1.5']); print(rc, 'ray' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["2", "False"]
