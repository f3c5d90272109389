"""The view the sweep's MLflow link opens (copilot_ray.mlflow_view): the trials as rows grouped by
configuration, the swept settings and the summary's figures as columns, the chart narrowed to success;
every part of a file adds to its experiment's view. (How MLflow's UI shows it: docs/mlflow_ui, made by
benchmarks/mlflow_ui_screenshots.py in headless Chromium.) No Ray."""

from __future__ import annotations

import json
from pathlib import Path

from copilot_ray import mlflow_view, tracking
from copilot_ray.keys import CONFIGURATION_TAG, ENV_STEPS, EVAL_SUCCESS, PATH_SUCCESS, validation_key
from copilot_ray.store import ui_hint
from copilot_ray.sweep import trials_view_of
from copilot_ray.sweep_spec import load_specs

ROOT = Path(__file__).resolve().parents[1]


def test_a_trial_runs_name_and_group_say_its_configuration_and_seed():
    assert mlflow_view.configuration("sac", "default") == "sac default"
    assert mlflow_view.group_id("sac", "default") == f"tag.{CONFIGURATION_TAG}.sac default"


def test_the_demo_shows_both_configurations_open_with_its_figures_as_columns():
    (demo,) = load_specs(ROOT / "sweeps" / "demo.yaml")
    view = mlflow_view.trials_view(*trials_view_of(demo))
    assert view["searchFilter"] == "tags.`copilot.role` = 'trial'"  # trials, not the parent summary
    assert view["groupBy"]["groupByKeys"] == [{"mode": "tag", "groupByData": CONFIGURATION_TAG}]
    # the ids MLflow's UI gives the groups of the tag a trial run carries: every group open
    assert view["groupsExpanded"] == {
        "tag.copilot.configuration.copilot tree_depth=1": True,
        "tag.copilot.configuration.copilot tree_depth=2": True,
    }
    columns = view["selectedColumns"]
    assert columns[:2] == ["params.`tree_depth`", "params.`seed`"]
    assert f"metrics.`{validation_key(EVAL_SUCCESS)}`" in columns and f"metrics.`{ENV_STEPS}`" in columns
    # the swept values first, after the run's name; widths that do not cut a configuration's name
    assert view["columnOrder"][:3] == ["attributes.`Run Name`", *columns[:2]]
    assert set(view["columnWidths"]) <= set(view["columnOrder"])
    assert view["chartsSearchFilter"] == f"^({validation_key(EVAL_SUCCESS)}|{PATH_SUCCESS})$"
    assert view["runsHiddenMode"] == "SHOW_ALL"


def _parts(file: str, experiment: str) -> list:
    return [s for s in load_specs(ROOT / "sweeps" / file) if s.experiment == experiment]


def _view_of(parts) -> dict:
    view = None
    for part in parts:
        view = mlflow_view.trials_view(*trials_view_of(part), earlier=view)
    return view


def _sections(view) -> dict[str, list[str]]:
    """Each chart section's name and the metrics its charts draw."""
    charts = view["compareRunCharts"]
    return {
        section["name"]: [c["metricKey"] for c in charts if c["metricSectionId"] == section["uuid"]]
        for section in view["compareRunSections"]
    }


def test_the_chart_view_has_a_section_per_figure_its_runs_log_and_no_other():
    (her,) = [p for p in _parts("privilege_matched.yaml", "privilege-matched") if p.algorithm == "her"]
    # HER plans no paths: no paths column, no paths section (it would stand empty)
    view = _view_of([her])
    assert _sections(view) == {
        f"{validation_key(EVAL_SUCCESS)} (Step = env steps)": [validation_key(EVAL_SUCCESS)]
    }
    assert not [c for c in view["selectedColumns"] if "paths/" in c]
    # the planners log no validation success; CO-PILOT, its fourth part, adds it to their view
    planners = _parts("planners_maze.yaml", "planners-maze")
    assert [p.algorithm for p in planners] == ["rrt_star", "sgt_pg", "next", "copilot"]
    assert list(_sections(_view_of(planners[:3])).values()) == [[PATH_SUCCESS]]
    assert list(_sections(_view_of(planners)).values()) == [[PATH_SUCCESS], [validation_key(EVAL_SUCCESS)]]
    assert f"metrics.`{validation_key(EVAL_SUCCESS)}`" not in _view_of(planners[:3])["selectedColumns"]
    # every part of the comparison logs success; all but HER paths (SoRB's from its graph search)
    compared = _view_of(_parts("privilege_matched.yaml", "privilege-matched"))
    assert list(_sections(compared).values()) == [[validation_key(EVAL_SUCCESS)], [PATH_SUCCESS]]
    assert compared["chartsSearchFilter"] == f"^({validation_key(EVAL_SUCCESS)}|{PATH_SUCCESS})$"


def test_each_chart_is_full_width_tall_and_says_its_step_is_env_steps():
    view = _view_of(_parts("privilege_matched.yaml", "privilege-matched"))
    assert view["isAccordionReordered"]  # (else MLflow sorts the sections by name)
    for section in view["compareRunSections"]:
        assert section["columns"] == 1 and section["cardHeight"] >= 400
        assert section["name"].endswith("(Step = env steps)")  # MLflow's x axis says "Step"
    for chart in view["compareRunCharts"]:
        # runs log at step = env steps (MLflow's metric-as-x-axis pairs sampled histories: step)
        assert chart["type"] == "LINE" and chart["xAxisKey"] == "step" and not chart["useGlobalXaxisKey"]
        assert chart["lineSmoothness"] > 0 and not chart["useGlobalLineSmoothing"]  # seeds' steps differ
    assert len({c["uuid"] for c in view["compareRunCharts"]}) == len(view["compareRunCharts"])


def test_every_column_is_as_wide_as_its_header_and_the_run_name_as_its_longest_group():
    view = _view_of(_parts("privilege_matched.yaml", "privilege-matched"))
    widths = view["columnWidths"]
    assert set(widths) == {"attributes.`Run Name`", *view["selectedColumns"]}
    for col in view["selectedColumns"]:
        header = col.split(".", 1)[1].strip("`")
        assert widths[col] >= 6.5 * len(header) + 30, col  # 12 px semi-bold, the sort mark beside it
    # "Group: copilot variant=frozen_planner" (the longest label) and its expander, dot and count
    assert widths["attributes.`Run Name`"] >= 6 * len("Group: copilot variant=frozen_planner") + 60
    assert widths["metrics.`copilot/validation/success_auc`"] > 200  # MLflow's default 180 cut it


def test_a_search_is_not_grouped_and_shows_no_test_figure():
    tuning = next(s for s in load_specs(ROOT / "sweeps" / "fair_maze.yaml") if s.searcher.type == "optuna")
    view = mlflow_view.trials_view(*trials_view_of(tuning))
    assert view["groupBy"] is None and view["groupsExpanded"] == {}
    assert not [c for c in view["selectedColumns"] if "paths/" in c or "copilot/eval/" in c]
    assert all(f"params.`{key}`" in view["selectedColumns"] for key in tuning.searched_keys)


def test_each_part_of_a_file_adds_to_its_experiments_view(tmp_path):
    import mlflow

    parts = [s for s in load_specs(ROOT / "sweeps" / "fair_maze.yaml") if s.experiment == "fair-maze"]
    assert len({s.algorithm for s in parts}) > 1
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    exp_id = mlflow.MlflowClient(uri).create_experiment("fair-maze", artifact_location=tmp_path.as_uri())
    for part in parts:
        tracking.show_trials(uri, exp_id, *trials_view_of(part))
    tag = mlflow.MlflowClient(uri).get_experiment(exp_id).tags[mlflow_view.VIEW_TAG]
    view = json.loads(tag)
    grouped = [p for p in parts if p.searcher.type == "grid"]
    for part in grouped:
        configurations, columns, _ = trials_view_of(part)
        assert all(mlflow_view.group_id(*c) in view["groupsExpanded"] for c in configurations)
        assert set(columns) <= set(view["selectedColumns"])
    assert len(tag) < 20_000  # MLflow's limit for an experiment tag's value


def test_the_printed_links_open_the_view_on_its_table_and_its_chart():
    command, table, chart = ui_hint("sqlite:////x/mlflow.db", "7", trials_view=True)
    assert table == f"then open http://127.0.0.1:5000/{mlflow_view.page('7', mlflow_view.TABLE)}"
    # (MLflow 3.17 applies a shared view on an experiment's runs page, not on the experiment's address)
    assert (
        "/#/experiments/7/runs?viewStateShareKey=trials&compareRunsMode=TABLE&workflowType=machine_learning"
        in table
    )
    assert chart.endswith(
        "/runs?viewStateShareKey=trials&compareRunsMode=CHART&workflowType=machine_learning"
    )
    (remote,) = ui_hint("http://tracking:5000/", "7", trials_view=True)[:1]
    assert remote.startswith("open http://tracking:5000/#/experiments/7/runs?viewStateShareKey=trials")
