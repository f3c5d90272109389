"""`python -m copilot_ray.train`: presets and bad input, without starting Ray."""

from copilot_ray import train


def test_preset_flag_sets_the_readings_and_explicit_flags_override_it():
    config = train.build_config(train.parse_args(["--preset", "paper_literal", "--tau-max", "40"]))
    assert config.preset == "paper_literal" and config.after_failure == "continue"
    assert config.tau_max == 40 and config.initial_alpha == 1.0
    default = train.build_config(train.parse_args([]))
    assert default.preset is None and default.after_failure == "restart" and default.tau_max == 25


def test_bad_preset_exits_2_naming_it_before_ray_starts(capsys):
    assert train.main(["--preset", "paper", "--stop-iters", "1"]) == 2
    assert "preset='paper' is invalid" in capsys.readouterr().err
