"""The sweep spec: loading, every rejection (with its key path), trial plans, Optuna define-by-run.

No Ray is started; only `test_build_algorithm_config_*` and `test_tune_search_space` import RLlib/Tune.
"""

from __future__ import annotations

import copy
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from copilot_ray import keys
from copilot_ray.sweep_spec import (
    SpecError,
    SweepSpec,
    build_algorithm_config,
    format_plan,
    load_spec,
    load_specs,
    optuna_define_by_run,
    parse_spec,
    to_tune_search_space,
    tune_stop,
)
from copilot_ray.trials.description import config_key

ROOT = Path(__file__).resolve().parents[1]
SWEEPS = sorted((ROOT / "sweeps").glob("*.yaml"))

BASE = {
    "name": "t",
    "env": {"id": "maze-point", "config": {"layout": "empty"}},
    "config": {"tree_depth": 2},
    "search": {"repetitions": {"grid": [1, 2]}},
    "seeds": [0, 1],
    "stop": {"env_steps": 10000},
}


def spec_with(**changes) -> dict:
    data = copy.deepcopy(BASE)
    for dotted, value in changes.items():
        node = data
        *parents, last = dotted.split("__")
        for p in parents:
            node = node.setdefault(p, {})
        if value is _DELETE:
            node.pop(last)
        else:
            node[last] = value
    return data


_DELETE = object()


def rejected(data: dict) -> str:
    with pytest.raises(SpecError) as err:
        parse_spec(data, "x.yaml")
    assert isinstance(err.value, ValueError)
    return str(err.value)


# ------------------------------------------------------------------------------------------ shipped specs
@pytest.mark.parametrize("path", SWEEPS, ids=[p.name for p in SWEEPS])
def test_every_shipped_spec_loads(path):
    specs = load_specs(path)
    # one spec named after its file, or parts named <file>_<part>
    assert [s.name for s in specs] == [path.stem] or all(s.name.startswith(path.stem + "_") for s in specs)
    for spec in specs:
        assert spec.trial_plan()
        assert "trial(s)" in format_plan(spec)
        if spec.searcher.type == "grid":
            for point in spec.trial_plan():
                build_algorithm_config(point, spec)  # every trial of every part builds its config


def test_shipped_specs_exist():
    names = {p.stem for p in SWEEPS}
    assert {"smoke", "depth_k", "repetitions_b", "alpha_schedule", "hpo", "demo"} <= names


def test_trial_plans_of_shipped_specs():
    depth = load_spec(ROOT / "sweeps/depth_k.yaml").trial_plan()
    assert len(depth) == 30
    assert sorted({t["tree_depth"] for t in depth}) == [1, 2, 3, 4, 5, 6]
    assert depth[:5] == [{"tree_depth": 1, "seed": s} for s in (1, 2, 3, 4, 5)]  # seed 0 tuned
    assert len(load_spec(ROOT / "sweeps/repetitions_b.yaml").trial_plan()) == 4 * 3
    smoke = load_spec(ROOT / "sweeps/smoke.yaml")
    assert smoke.trial_plan() == [{"tree_depth": 1, "seed": 0}, {"tree_depth": 2, "seed": 0}]
    assert smoke.resources.max_concurrent_trials == 1 and smoke.resources.num_env_runners == 0
    alpha = load_spec(ROOT / "sweeps/alpha_schedule.yaml").trial_plan()
    assert {"paper_warm_start", "paper_per_task"} <= {
        t["alpha_schedule"] for t in alpha if isinstance(t["alpha_schedule"], str)
    }
    hpo = load_spec(ROOT / "sweeps/hpo.yaml")
    assert hpo.searcher.type == "optuna" and hpo.searcher.sampler == "tpe"
    assert len(hpo.trial_plan()) == hpo.searcher.num_samples * len(hpo.seeds)
    assert hpo.has_conditional_params


def test_format_plan_shows_table_and_budget():
    text = format_plan(load_spec(ROOT / "sweeps/depth_k.yaml"))
    assert "6 configuration(s) x 5 seed(s)" in text
    assert "30 trial(s)" in text and "6,000,000 env steps" in text
    assert "tree_depth" in text


def test_defaults_experiment_tracking_and_cpus(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    spec = parse_spec(spec_with(resources={"num_env_runners": 2}))
    assert spec.experiment == "t"
    assert spec.tracking.uri == f"sqlite:///{tmp_path / 'results' / 't' / 'mlflow.db'}"
    assert spec.tracking.uri.startswith("sqlite:////")  # absolute path
    assert spec.resources.cpus_per_trial == 3
    assert spec.searcher.type == "grid"
    assert tune_stop(spec) == {keys.ENV_STEPS: 10000}


def test_yaml_floats_in_exponent_form_are_numbers(tmp_path):
    path = tmp_path / "s.yaml"
    data = spec_with(config={"tree_depth": 2, "planner.lr": "PLACEHOLDER"})
    path.write_text(yaml.safe_dump(data).replace("PLACEHOLDER", "1e-3"))
    assert load_spec(path).config["planner.lr"] == 1e-3


# ------------------------------------------------------------------------------------------ rejections
@pytest.mark.parametrize(
    "changes, expected",
    [
        (
            {"config__tree_depth": -1},
            "config.tree_depth: -1 is invalid: tree_depth must be an integer in [1, 10]",
        ),
        ({"config__tree_depth": 11}, "too deep for memory"),
        ({"config__tree_depth": "5"}, "config.tree_depth: '5' is invalid"),
        ({"config__tree_depth": 5.0}, "config.tree_depth: 5.0 is invalid"),
        ({"config__tree_depth": True}, "config.tree_depth: True is invalid"),
        (
            {"search__repetitions__grid": [1, 0]},
            "search.repetitions.grid[1]: 0 is invalid: repetitions must be",
        ),
        ({"config__alpha_schedule.alpha": 1.5}, "config.alpha_schedule.alpha: 1.5 is invalid"),
        ({"config__alpha_schedule.values": [1.0, -0.1]}, "config.alpha_schedule.values"),
        (
            {"config__alpha_schedule": {"kind": "constant", "alpha": 2.0}},
            "config.alpha_schedule: {'kind': 'constant', 'alpha': 2.0} is invalid",
        ),
        ({"config__alpha_schedule": "paper_per_taks"}, "config.alpha_schedule: 'paper_per_taks' is invalid"),
        ({"search__repetitions__grid": []}, "search.repetitions.grid: [] is invalid: an empty grid"),
        ({"search__repetitions__grid": [1, 1]}, "duplicate value 1"),
        (
            {"search": {"tree_depth": {"grid": [1, 2, -1]}}, "config": {}},
            "search.tree_depth.grid[2]: -1 is invalid: tree_depth must be an integer in [1, 10]",
        ),
        ({"config": {"tree_depth": 2, "planner.std": 0.0}}, "config.planner.std: 0.0 is invalid"),
        ({"config__tree_deph": 3}, "config.tree_deph: unknown key; did you mean 'tree_depth'?"),
        ({"config__planner.sdt": 3}, "did you mean 'planner.std'?"),
        (
            {"search": {"tree_deph": {"grid": [1]}}},
            "search.tree_deph: unknown key; did you mean 'tree_depth'?",
        ),
        (
            {"search__repetitions": {"gird": [1]}},
            "search.repetitions.gird: unknown key; did you mean 'grid'?",
        ),
        ({"search__repetitions": {"grid": [1], "int": [1, 2]}}, "search.repetitions: give exactly one of"),
        ({"envv": {}}, "envv: unknown key; did you mean 'env'?"),
        (
            {"env__id": "maze-pont"},
            "env.id: 'maze-pont' is invalid: unknown env id; did you mean 'maze-point'?",
        ),
        ({"env__config__layot": "empty"}, "env.config.layot"),
        ({"env__config__layout": "no-such-layout"}, "env.config.layout: 'no-such-layout' is invalid"),
        ({"env__config__speed": -1.0}, "env.config.speed: -1.0 is invalid"),
        ({"seeds": [0, 1, 0]}, "seeds: [0, 1, 0] is invalid: duplicate seed 0"),
        ({"seeds": []}, "seeds: [] is invalid"),
        ({"seeds": ["0"]}, "seeds[0]: '0' is invalid"),
        ({"stop": {}}, "stop: give env_steps and/or iterations"),
        ({"stop": {"env_steps": 0}}, "stop.env_steps: 0 is invalid"),
        ({"name": _DELETE}, "name: required key is missing"),
        ({"name": "a b/c"}, "name: 'a b/c' is invalid"),
        (
            {"resources": {"num_env_runners": 2, "cpus_per_trial": 2}},
            "resources.cpus_per_trial: 2 is invalid",
        ),
        ({"resources": {"max_concurrent_trials": 0}}, "resources.max_concurrent_trials: 0 is invalid"),
        ({"resources": {"num_env_runners": -1}}, "resources.num_env_runners: -1 is invalid"),
        ({"resources": {"gpus_per_trial": -0.5}}, "resources.gpus_per_trial: -0.5 is invalid"),
        (
            {"resources": {"gpus_per_trial": 1.5}},
            "resources.gpus_per_trial: 1.5 is invalid: must be >= 0, and a whole",
        ),
        (
            {"algorithm": "rrt_star", "config": {}, "search": {}, "resources": {"gpus_per_trial": 1}},
            "resources.gpus_per_trial: 1 is invalid: 'rrt_star' has no learner that runs on a GPU",
        ),
        (
            {"algorithm": "copliot"},
            "algorithm: 'copliot' is invalid: unknown algorithm; did you mean 'copilot'?",
        ),
        ({"config__seed": 3}, "config.seed"),
        (
            {"search": {"tree_depth": {"grid": [1, 2]}}},
            "search.tree_depth: tree_depth is also fixed in config",
        ),
        (
            {"searcher": {"type": "grid", "metric": "copilot/validation/sucess_planned", "mode": "max"}},
            "searcher.metric: 'copilot/validation/sucess_planned' is invalid: copilot does not log this metric; did you mean 'copilot/validation/success_planned'?",
        ),
        ({"searcher": {"type": "bayes"}}, "searcher.type: 'bayes' is invalid"),
    ],
)
def test_rejections_name_key_path_and_value(changes, expected):
    message = rejected(spec_with(**changes))
    assert message.startswith("x.yaml: ")
    assert expected in message, message


@pytest.mark.parametrize(
    "domain, expected",
    [
        ({"int": [5, 1]}, "search.p.int: [5, 1] is invalid: low 5 > high 1"),
        ({"float": [0.5, 0.1]}, "low 0.5 > high 0.1"),
        ({"float": [0.0, 0.1], "log": True}, "a log range needs low > 0"),
        ({"int": [0, 4], "log": True}, "a log range needs low > 0"),
        ({"float": [0.1]}, "float takes [low, high]"),
        ({"float": ["a", "b"]}, "search.p.float[0]: 'a' is invalid"),
        ({"int": [1, 4], "step": 0}, "search.p.step: 0 is invalid"),
        ({"categorical": []}, "an empty categorical"),
        ({"grid": [1, 2], "log": True}, "log and step apply to int and float ranges only"),
    ],
)
def test_range_rejections(domain, expected):
    key = "planner.num_samples" if "int" in domain else "planner.std"
    data = spec_with(search={key: domain}, searcher=_optuna())
    message = rejected(data).replace(f"search.{key}", "search.p")
    assert expected in message, message


def _optuna(**kw):
    return {
        "type": "optuna",
        "metric": "copilot/validation/success_planned",
        "mode": "max",
        "num_samples": 4,
        **kw,
    }


def test_range_ends_follow_the_keys_rule():
    message = rejected(spec_with(search={"alpha_schedule.alpha": {"float": [0.0, 1.5]}}, searcher=_optuna()))
    assert (
        "search.alpha_schedule.alpha.float[1]: 1.5 is invalid: alpha_schedule.alpha must be a number in [0, 1]"
        in message
    )
    message = rejected(spec_with(search={"repetitions": {"float": [1.0, 3.0]}}, searcher=_optuna()))
    assert "search.repetitions.float: [1.0, 3.0] is invalid: repetitions is an integer: use int" in message


def test_searcher_and_domain_must_agree():
    message = rejected(spec_with(search={"planner.std": {"float": [0.01, 0.1]}}))
    assert "search.planner.std: 'float' is invalid: a grid searcher needs every domain to be grid" in message
    message = rejected(spec_with(searcher=_optuna()))
    assert "search.repetitions: 'grid' is invalid: an optuna searcher samples; use categorical" in message


def test_searcher_and_scheduler_rules():
    assert "searcher.metric" in rejected(
        spec_with(searcher={"type": "optuna", "mode": "max", "num_samples": 2})
    )
    assert "searcher.num_samples: 0 is invalid" in rejected(
        spec_with(search={"planner.std": {"float": [0.01, 0.1]}}, searcher=_optuna(num_samples=0))
    )
    assert "searcher.sampler: 'grid' is invalid" in rejected(
        spec_with(search={"planner.std": {"float": [0.01, 0.1]}}, searcher=_optuna(sampler="grid"))
    )
    assert "scheduler: 'asha' is invalid: a scheduler needs searcher.metric" in rejected(
        spec_with(scheduler={"type": "asha", "max_t": 1000})
    )
    searcher = {"type": "grid", "metric": "copilot/planner/cost_layer_3", "mode": "min"}
    message = rejected(
        spec_with(searcher=searcher, scheduler={"type": "asha", "max_t": 100, "grace_period": 200})
    )
    assert "scheduler.grace_period: 200 is invalid: must be <= max_t (100)" in message
    message = rejected(spec_with(searcher=searcher, scheduler={"type": "median_stopping", "max_t": 100}))
    assert "scheduler.max_t: 100 is invalid: does not apply to type median_stopping" in message
    assert "searcher.metric: 'copilot/planner/cost_layer_11'" in rejected(
        spec_with(searcher={**searcher, "metric": "copilot/planner/cost_layer_11"})
    )
    ok = parse_spec(
        spec_with(searcher=searcher, scheduler={"type": "asha", "max_t": 1000, "grace_period": 100})
    )
    assert ok.scheduler.reduction_factor == 3.0


def test_several_problems_are_reported_together():
    message = rejected(spec_with(config={"tree_depth": -1, "repetitions": 0}, seeds=[1, 1]))
    lines = message.splitlines()
    assert any("config.tree_depth: -1" in line for line in lines)
    assert any("config.repetitions: 0" in line for line in lines)
    assert any("duplicate seed 1" in line for line in lines)


def test_alpha_schedule_keys_must_form_a_schedule():
    # linear on the global clock needs a duration
    data = spec_with(
        config={"tree_depth": 2, "alpha_schedule.kind": "linear", "alpha_schedule.clock": "global"}
    )
    assert "config: " in rejected(data) and "duration is required" in rejected(data)
    # a field the kind does not use
    data = spec_with(config={"tree_depth": 2, "alpha_schedule.kind": "constant", "alpha_schedule.start": 0.5})
    assert "does not apply to kind='constant'" in rejected(data)
    data = spec_with(config={"tree_depth": 2, "alpha_schedule": "euclidean", "alpha_schedule.kind": "linear"})
    assert "config.alpha_schedule.kind" in rejected(data)
    # conditional branch missing a needed field: exponential on the per-task clock is fine without one,
    # but a kind that does not use a sampled field is caught
    search = {
        "alpha_schedule.kind": {
            "categorical": ["constant", "linear"],
            "when": {"constant": {"alpha_schedule.start": {"float": [0.1, 0.2]}}},
        }
    }
    data = spec_with(search=search, searcher=_optuna(), config={"alpha_schedule.clock": "per_task"})
    assert "search: " in rejected(data) and "does not apply to kind='constant'" in rejected(data)


def test_update_to_data_ratio_set_twice_is_rejected():
    data = spec_with(config={"tree_depth": 2, "updates_per_env_step": 0.5, "training_intensity": 128.0})
    msg = rejected(data)
    assert "config: " in msg and "training_intensity" in msg and "updates_per_env_step" in msg
    data = spec_with(config={"tree_depth": 2, "updates_per_env_step": 0.5})
    data["search"] = {"training_intensity": {"grid": [64.0, 256.0]}}
    assert "search: " in rejected(data)
    # One of them alone is fine.
    parse_spec(spec_with(config={"tree_depth": 2, "training_intensity": 128.0}), "x.yaml")


def test_when_needs_known_choices_and_categorical():
    search = {"alpha_schedule.kind": {"categorical": ["constant"], "when": {"constnt": {}}}}
    message = rejected(spec_with(search=search, searcher=_optuna()))
    assert (
        "search.alpha_schedule.kind.when.constnt: 'constnt' is invalid: not one of the categorical values"
        in message
    )
    search = {"alpha_schedule.kind": {"grid": ["constant"], "when": {"constant": {}}}}
    assert "search.alpha_schedule.kind.when: conditional parameters need a categorical domain" in rejected(
        spec_with(search=search)
    )
    search = {
        "alpha_schedule.kind": {
            "categorical": ["constant"],
            "when": {"constant": {"alpha_schedule.alpha": {"float": [0.0, 2.0]}}},
        }
    }
    message = rejected(spec_with(search=search, searcher=_optuna()))
    assert "search.alpha_schedule.kind.when.constant.alpha_schedule.alpha.float[1]: 2.0 is invalid" in message


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\nenv: {id: maze-point\nstop: {env_steps: 5}\n")
    with pytest.raises(SpecError) as err:
        load_spec(path)
    assert str(err.value).startswith(f"{path}:3:") and "YAML syntax error" in str(err.value)


def test_yaml_duplicate_key_is_an_error(tmp_path):
    path = tmp_path / "dup.yaml"
    path.write_text("name: x\nseeds: [0]\nseeds: [1]\n")
    with pytest.raises(SpecError) as err:
        load_spec(path)
    assert f"{path}:3:" in str(err.value) and "duplicate key 'seeds'" in str(err.value)


def test_missing_file_and_non_mapping(tmp_path):
    with pytest.raises(SpecError, match="cannot read"):
        load_spec(tmp_path / "nope.yaml")
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(SpecError, match="must be a mapping"):
        load_spec(path)


def test_bad_layout_file_names_file_line_column(tmp_path):
    layout = tmp_path / "maze.txt"
    layout.write_text("....\n..x.\n")
    message = rejected(spec_with(env__config={"layout": str(layout)}))
    assert "env.config.layout" in message and f"{layout}:2:3" in message


def test_rejected_spec_imports_no_ray(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(spec_with(config__tree_depth=-1)))
    code = (
        "import sys\n"
        "from copilot_ray.sweep_spec import load_spec, SpecError\n"
        f"try:\n    load_spec({str(path)!r})\nexcept SpecError as e:\n    print('REJECTED', e)\n"
        f"load_spec({str(ROOT / 'sweeps/hpo.yaml')!r})\n"
        "assert 'ray' not in sys.modules, 'ray was imported'\n"
        "print('NO RAY')\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert out.returncode == 0, out.stderr
    assert "REJECTED" in out.stdout and "config.tree_depth: -1 is invalid" in out.stdout
    assert "NO RAY" in out.stdout


# ------------------------------------------------------------------------------------------ optuna
def test_define_by_run_suggests_only_the_chosen_kinds_parameters():
    optuna = pytest.importorskip("optuna")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    spec = load_spec(ROOT / "sweeps/hpo.yaml")
    fn = optuna_define_by_run(spec)
    study = optuna.create_study(direction="maximize", sampler=optuna.samplers.RandomSampler(seed=0))
    expected = {
        "constant": {"alpha_schedule.alpha"},
        "linear": {"alpha_schedule.start", "alpha_schedule.end"},
        "exponential": {"alpha_schedule.start", "alpha_schedule.end", "alpha_schedule.decay"},
    }
    seen = set()
    for _ in range(30):
        trial = study.ask()
        flat = fn(trial)
        kind = flat["alpha_schedule.kind"]
        seen.add(kind)
        schedule_keys = {k for k in flat if k.startswith("alpha_schedule.") and k != "alpha_schedule.kind"}
        assert schedule_keys == expected[kind]
        assert set(trial.params) == set(flat)
        assert 0.01 <= flat["planner.std"] <= 0.2 and 4 <= flat["planner.num_samples"] <= 32
        study.tell(trial, 0.0)
    assert seen == set(expected)


def test_define_by_run_decodes_non_scalar_categoricals():
    optuna = pytest.importorskip("optuna")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    choices = ["paper_per_task", {"kind": "constant", "alpha": 0.5}]
    spec = parse_spec(spec_with(search={"alpha_schedule": {"categorical": choices}}, searcher=_optuna()))
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=1))
    drawn = [optuna_define_by_run(spec)(study.ask())["alpha_schedule"] for _ in range(20)]
    assert all(d in choices for d in drawn) and {str(d) for d in drawn} == {str(c) for c in choices}


# ------------------------------------------------------------------------------------------ Tune / RLlib
def _has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


@pytest.mark.skipif(not _has("ray"), reason="ray is not installed")
def test_tune_search_space():
    from ray.tune.search.sample import Categorical, Float, Integer

    space = to_tune_search_space(load_spec(ROOT / "sweeps/depth_k.yaml"))
    assert space["tree_depth"] == {"grid_search": [1, 2, 3, 4, 5, 6]}
    assert space["seed"] == {"grid_search": [1, 2, 3, 4, 5]}
    spec = parse_spec(
        spec_with(
            search={
                "planner.std": {"float": [0.01, 0.1], "log": True},
                "planner.num_samples": {"int": [4, 8]},
                "planner.epochs": {"int": [2, 8], "step": 2},
                "updates_per_env_step": {"categorical": [0.5, 1.0]},
            },
            searcher=_optuna(),
        )
    )
    space = to_tune_search_space(spec)
    assert "seed" not in space
    assert isinstance(space["planner.std"], Float) and isinstance(space["updates_per_env_step"], Categorical)
    ints = space["planner.num_samples"]
    assert isinstance(ints, Integer) and (ints.lower, ints.upper) == (4, 9)  # high inclusive in the spec
    with pytest.raises(ValueError, match="optuna_define_by_run"):
        to_tune_search_space(load_spec(ROOT / "sweeps/hpo.yaml"))


def _copilot_importable() -> str | None:
    try:
        import copilot_ray.algorithms.copilot  # noqa: F401
    except Exception as err:  # noqa: BLE001
        return f"copilot_ray.algorithms.copilot does not import: {type(err).__name__}: {err}"
    return None


def test_build_algorithm_config_applies_dotted_keys():
    reason = _copilot_importable()
    if reason:
        pytest.skip(reason)
    spec = load_spec(ROOT / "sweeps/hpo.yaml")
    flat = {
        "planner.std": 0.1,
        "planner.num_samples": 8,
        "cost_model.lr": 0.002,
        "actor_lr": 1e-3,
        "critic_lr": 2e-3,
        "updates_per_env_step": 0.5,
        "alpha_schedule.kind": "exponential",
        "alpha_schedule.start": 0.8,
        "alpha_schedule.end": 0.1,
        "alpha_schedule.decay": 0.5,
        "seed": 7,
    }
    config = build_algorithm_config(flat, spec)
    assert config.tree_depth == 5 and config.repetitions == 5  # fixed config
    assert config.planner["std"] == 0.1 and config.planner["num_samples"] == 8
    assert config.planner["lr"] == 0.005  # untouched default survives the merge
    assert config.cost_model["lr"] == 0.002
    assert config.actor_lr == 1e-3 and config.critic_lr == 2e-3 and config.updates_per_env_step == 0.5
    assert config.alpha_schedule == {
        "kind": "exponential",
        "clock": "per_task",
        "start": 0.8,
        "end": 0.1,
        "decay": 0.5,
    }
    assert config.seed == 7 and config.env == "maze-point" and config.env_config == {"layout": "four-rooms"}
    config.copy(copy_frozen=False).validate()
    smoke = load_spec(ROOT / "sweeps/smoke.yaml")
    for trial in smoke.trial_plan():
        cfg = build_algorithm_config(trial, smoke)
        assert cfg.tree_depth == trial["tree_depth"] and cfg.task_batch_size == 4 and cfg.tau_max == 10
        assert cfg.cost_model["init_euclidean"] == 5000 and cfg.num_env_runners == 0
    # dotted fields without a kind override the preset
    alpha = load_spec(ROOT / "sweeps/alpha_schedule.yaml")
    cfg = build_algorithm_config({"alpha_schedule": "paper_warm_start", "seed": 0}, alpha)
    assert cfg.alpha_schedule["clock"] == "global" and cfg.alpha_schedule["duration"] == 2
    with pytest.raises(SpecError, match=r"trial.tree_deph: .*did you mean 'tree_depth'"):
        build_algorithm_config({"tree_deph": 3}, smoke)
    with pytest.raises(SpecError, match=r"trial.tree_depth: -1 is invalid"):
        build_algorithm_config({"tree_depth": -1}, smoke)


def test_preset_in_a_spec_is_applied_first_and_other_keys_override_it():
    reason = _copilot_importable()
    if reason:
        pytest.skip(reason)
    spec = parse_spec(
        spec_with(
            config={"tree_depth": 2, "preset": "paper_literal", "tau_max": 30, "initial_alpha": 0.01},
            search={"after_failure": {"grid": ["continue", "restart"]}},
        )
    )
    configs = [build_algorithm_config(trial, spec) for trial in spec.trial_plan()]
    assert {c.after_failure for c in configs} == {"continue", "restart"}
    for c in configs:
        assert c.preset == "paper_literal" and c.traversal_tree == "sampled" and c.planner_warm_start == 0
        assert c.tau_max == 30 and c.initial_alpha == 0.01  # the spec's own keys win over the preset
    with pytest.raises(SpecError, match=r"config.preset: 'paper' is invalid.*paper_literal"):
        parse_spec(spec_with(config={"preset": "paper"}))
    with pytest.raises(SpecError, match=r"config.target_entropy: 'low' is invalid"):
        parse_spec(spec_with(config={"target_entropy": "low"}))


def test_spec_is_a_pydantic_model():
    spec = load_spec(ROOT / "sweeps/smoke.yaml")
    assert isinstance(spec, SweepSpec)
    again = parse_spec(spec.model_dump(by_alias=True, exclude_none=True))
    assert again.trial_plan() == spec.trial_plan()


# ------------------------------------------------------------------------------------------ variants
def _variants_spec(**changes):
    return spec_with(
        config={"tree_depth": 2, "tau_max": 20},
        variants={"base": {}, "paper": {"preset": "paper_literal"}, "short": {"tau_max": 5}},
        **changes,
    )


def test_variants_are_a_grid_axis_over_every_point_and_seed():
    spec = parse_spec(_variants_spec())
    plan = spec.trial_plan()
    assert len(plan) == 3 * 2 * 2  # variants x repetitions grid x seeds
    assert plan[0] == {"variant": "base", "repetitions": 1, "seed": 0}
    assert {p["variant"] for p in plan} == {"base", "paper", "short"}
    assert spec.num_configurations() == 6
    assert spec.merged({"variant": "short", "repetitions": 2, "seed": 0}) == {
        "tree_depth": 2,
        "tau_max": 5,  # the variant overrides config
        "repetitions": 2,
    }
    text = format_plan(spec)
    assert "variant short: tau_max=5" in text and "variant base: (config as it is)" in text
    from ray.tune.search.sample import Categorical  # noqa: F401 - Tune importable

    space = to_tune_search_space(spec)
    assert space["variant"] == {"grid_search": ["base", "paper", "short"]}


def test_variants_build_their_configs():
    reason = _copilot_importable()
    if reason:
        pytest.skip(reason)
    spec = parse_spec(_variants_spec())
    short = build_algorithm_config({"variant": "short", "repetitions": 1, "seed": 0}, spec)
    paper = build_algorithm_config({"variant": "paper", "repetitions": 1, "seed": 0}, spec)
    base = build_algorithm_config({"variant": "base", "repetitions": 1, "seed": 0}, spec)
    assert short.tau_max == 5 and base.tau_max == 20 and paper.tau_max == 20  # config wins over the preset
    assert paper.preset == "paper_literal" and paper.subtask_reward == "halving"
    assert base.subtask_reward == "uniform"
    with pytest.raises(SpecError, match=r"trial.variant: 'nope' is invalid"):
        build_algorithm_config({"variant": "nope", "seed": 0}, spec)


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"variants": {"a": {"tau_mx": 3}}}, "variants.a.tau_mx: unknown key; did you mean 'tau_max'?"),
        ({"variants": {"a": {"tau_max": 0}}}, "variants.a.tau_max: 0 is invalid"),
        ({"variants": {"a b": {}}}, "variants.a b: 'a b' is invalid"),
        (
            {"variants": {"a": {"repetitions": 2}}},
            "variants.a.repetitions: 2 is invalid: repetitions is also searched",
        ),
        (
            {
                "variants": {"a": {}},
                "searcher": _optuna(),
                "search": {"repetitions": {"categorical": [1, 2]}},
            },
            "variants: ['a'] is invalid: variants need searcher type: grid",
        ),
    ],
)
def test_bad_variants_are_rejected_naming_the_key(changes, expected):
    assert expected in rejected(spec_with(**changes))


def test_optional_knobs_take_null():
    spec = parse_spec(
        spec_with(config={"tree_depth": 2, "planner.std_final": None, "planner.max_grad_norm": None})
    )
    assert spec.config["planner.std_final"] is None
    assert "config.planner.std: None is invalid" in rejected(spec_with(config={"planner.std": None}))


def test_shipped_ablation_spec_has_the_paper_reading_and_one_revert_per_variant():
    spec = load_spec(ROOT / "sweeps/readings_ablation.yaml")
    assert spec.variants["paper_literal"] == {"preset": "paper_literal"}
    assert spec.variants["default"] == {}
    assert all(len(v) == 1 for name, v in spec.variants.items() if name != "default")
    from copilot_ray.algorithms.copilot.settings import SETTINGS

    # each revert changes its reading: a variant at the default (a reading whose default became the
    # paper's) would run the default twice under another name
    reverts = {n: v for n, v in spec.variants.items() if n not in ("default", "paper_literal")}
    for name, ((key, value),) in ((n, v.items()) for n, v in reverts.items()):
        assert SETTINGS[key].default != value, f"variant {name}: {key} {value!r} is the default"


def test_a_layout_that_one_of_the_envs_does_not_fit_names_the_layout_and_the_env(tmp_path):
    rows = ["." * 20 if r % 2 == 0 else "#" * 19 + "." for r in range(20)]
    layout = tmp_path / "corridors.txt"
    layout.write_text("\n".join(rows) + "\n")
    data = {
        "name": "t",
        "env": {"id": ["maze-point", "maze-rigid"], "config": {"layout": str(layout)}},
        "algorithm": "rrt_star",
        "stop": {"iterations": 1},
    }
    with pytest.raises(SpecError) as err:
        parse_spec(data)
    (line,) = err.value.problems
    assert line.startswith(
        f"<spec>: env.config.layout: '{layout}' is invalid: building env 'maze-rigid' failed"
    )
    assert "BodyDoesNotFitError" in line and "fits nowhere" in line


def test_env_id_list_is_a_grid_axis_and_builds_each_trial_on_its_env():
    data = {
        "name": "t",
        "env": {"id": ["maze-point", "maze-snake"], "config": {"layout": "u-maze"}},
        "algorithm": "sgt_pg",
        "search": {"tree_depth": {"grid": [2, 3]}},
        "seeds": [0, 1],
        "stop": {"iterations": 1},
    }
    spec = parse_spec(data)
    plan = spec.trial_plan()
    assert len(plan) == spec.num_configurations() * 2 == 8
    assert {(p["env.id"], p["tree_depth"]) for p in plan} == {
        (e, k) for e in ("maze-point", "maze-snake") for k in (2, 3)
    }
    config = build_algorithm_config(plan[-1], spec)
    assert config.env_id == plan[-1]["env.id"] and config.tree_depth == plan[-1]["tree_depth"]
    assert to_tune_search_space(spec)["env.id"]  # a grid_search over the envs
    with pytest.raises(SpecError, match=r"trial.env.id: 'maze-rigid' is invalid"):
        build_algorithm_config({"env.id": "maze-rigid"}, spec)
    for bad, why in (
        (["maze-point", "maze-point"], "a list of distinct ones"),
        (["maze-point", "maze-pont"], r"env.id\[1\]: 'maze-pont' is invalid: unknown env id"),
    ):
        with pytest.raises(SpecError, match=why):
            parse_spec({**data, "env": {"id": bad}})


def test_a_file_of_several_specs_is_checked_whole_naming_the_part(tmp_path):
    good = "name: a\nenv: {id: maze-point}\nalgorithm: rrt_star\nstop: {iterations: 1}\n"
    bad = "name: b\nenv: {id: maze-point}\nalgorithm: rrt_star\nconfig: {time_limit_s: 0}\nstop: {iterations: 1}\n"
    path = tmp_path / "two.yaml"
    path.write_text(good + "---\n" + bad)
    with pytest.raises(SpecError) as err:
        load_specs(path)
    assert err.value.problems == [
        f"part 2 of 2: {path}: config.time_limit_s: 0 is invalid: time_limit_s must be a number > 0"
    ]
    path.write_text(good + "---\n" + good)
    with pytest.raises(SpecError, match="name: 'a' is invalid: every part of a spec file needs its own name"):
        load_specs(path)
    with pytest.raises(SpecError, match="expected one YAML document, found 2"):
        load_spec(path)


def test_fault_tolerance_is_checked_and_planned():
    base = {"name": "t", "env": {"id": "maze-point"}, "algorithm": "rrt_star", "stop": {"iterations": 1}}
    spec = parse_spec(base)
    assert (spec.fault_tolerance.checkpoint_every, spec.fault_tolerance.max_failures) == (1, 2)
    spec = parse_spec({**base, "fault_tolerance": {"checkpoint_every": 5, "max_failures": -1}})
    assert (
        "a checkpoint every 5 iteration(s); a failed trial is retried from it without limit"
        in format_plan(spec)
    )
    with pytest.raises(SpecError) as err:
        parse_spec({**base, "fault_tolerance": {"checkpoint_every": 0, "max_failures": -2, "retries": 3}})
    assert err.value.problems[0].startswith("<spec>: fault_tolerance.retries: unknown key")
    with pytest.raises(SpecError) as err:
        parse_spec({**base, "fault_tolerance": {"checkpoint_every": 0, "max_failures": -2}})
    assert err.value.problems == [
        "<spec>: fault_tolerance.checkpoint_every: 0 is invalid: must be an integer >= 1",
        "<spec>: fault_tolerance.max_failures: -2 is invalid: must be >= 0, or -1 for no limit",
    ]


def test_a_spec_with_mistakes_in_several_sections_gets_them_all_in_one_report():
    """Section checks (stop, resources, tracking) and the checks across sections (config keys against
    the algorithm, the searcher's metric) used to stop at the first failing pass."""
    data = spec_with(
        config={"tree_deph": 3, "eval_num_tasks": 0},
        stop={"env_steps": -5},
        tracking={"uri": "ftp://x"},
        searcher={"type": "grid", "metric": "copilot/eval/success", "mode": "max"},
        resources={"max_concurrent_trials": 0},
    )
    text = rejected(data)
    for expected in (
        "stop.env_steps: -5 is invalid",
        "resources.max_concurrent_trials: 0 is invalid",
        "tracking.uri: 'ftp://x' is invalid",
        "config.tree_deph: unknown key; did you mean 'tree_depth'?",
        "config.eval_num_tasks: 0 is invalid",
        "searcher.metric: 'copilot/eval/success' is invalid: is a test-set metric",
    ):
        assert expected in text, expected


# ------------------------------------------------------------------------------------------ stacked seeds
@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"seeds_per_trial": 0}, "seeds_per_trial: 0 is invalid: must be >= 1"),
        ({"seeds": [0, 1, 2], "seeds_per_trial": 2}, "must divide the 3 seeds [0, 1, 2] into equal groups"),
        ({"seeds_per_trial": 2, "algorithm": "ppo", "config": {}}, "'ppo' has no stacked update"),
        (
            {"seeds_per_trial": 2, "searcher": _optuna()},
            "seeds_per_trial: 2 is invalid: needs searcher.type grid",
        ),
        (
            {"seeds_per_trial": 2, "resources": {"num_env_runners": 1}},
            "needs resources.num_env_runners 0, got 1",
        ),
        *(  # the seeds step in one loop with the lean traversal and update through the fused step
            (
                {
                    "seeds_per_trial": 2,
                    "config": {"tree_depth": 2, key: False},
                    "resources": {"num_env_runners": 0, **gpu},
                },
                f"stacked seeds need {key}: true (they step in one loop with the lean traversal and "
                "update through the fused step), and it is false in: repetitions=1, repetitions=2",
            )
            for key in ("fast_learner", "fused_update", "lean_traversal")
            for gpu in ({}, {"gpus_per_trial": 1})
        ),
    ],
)
def test_stacked_seeds_are_refused_where_a_stack_cannot_run(changes, expected):
    data = spec_with(**changes)
    if "searcher" in changes:
        data["search"] = {"repetitions": {"int": [1, 2]}}
    assert expected in rejected(data)


def test_stacked_seeds_make_a_trial_per_group_and_say_so_in_the_plan():
    spec = parse_spec(
        spec_with(seeds=[0, 1, 2, 3], seeds_per_trial=2, resources={"num_env_runners": 0}), "x.yaml"
    )
    assert spec.seed_groups() == [[0, 1], [2, 3]]
    assert spec.trial_plan() == [
        {"repetitions": 1, "seeds": [0, 1]},
        {"repetitions": 1, "seeds": [2, 3]},
        {"repetitions": 2, "seeds": [0, 1]},
        {"repetitions": 2, "seeds": [2, 3]},
    ]
    assert spec.budget()["trials"] == 4 and spec.budget()["env_steps"] == 4 * 2 * 10000  # every seed's budget
    # a trial's configuration is its searched values; its seeds are not part of it
    assert sorted({config_key(point) for point in spec.trial_plan()}) == ["repetitions=1", "repetitions=2"]
    plan = format_plan(spec)
    assert "2 seeds per trial: each trial steps its seeds together in one process" in plan
    assert "0, 1 | 2, 3" in plan
    if _has("ray"):
        space = to_tune_search_space(spec)
        assert space[keys.SEEDS_KEY] == {"grid_search": [[0, 1], [2, 3]]} and "seed" not in space
