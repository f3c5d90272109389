"""analysis.report against a small real MLflow store built by hand (no Ray, a few seconds)."""

from __future__ import annotations

import itertools
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest

from analysis import stats
from analysis.report import main
from copilot_ray.commands import python
from copilot_ray.keys import (
    ALGORITHM_TAG,
    ALPHA_SCHEDULE_TAG,
    B_TAG,
    CONFIG_KEY_TAG,
    DIAG_EUCLIDEAN_ERROR,
    DIAG_Q_MEAN,
    DIAG_REACHABLE_LENGTH_LAYER,
    DIAG_SEGMENT_LENGTH_LAYER,
    DIAG_SEGMENT_UNREACHABLE_LAYER,
    DIAG_SUBGOAL_IN_OBSTACLE_LAYER,
    DIAG_SUCCESS_AFTER_FAILED,
    DIAG_SUCCESS_AFTER_REACHED,
    DIAG_TAU_HAT_ERROR,
    ENV_STEPS,
    ENV_TAG,
    GIT_COMMIT_TAG,
    K_TAG,
    PARENT_TAG,
    PLANNER_WARM_START_COST,
    PRESET_TAG,
    REPORT_ARTIFACT,
    ROLE_SWEEP,
    ROLE_TAG,
    ROLE_TRIAL,
    SEED_TAG,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    SWEEP_TAG,
    TIME_TOTAL_S,
    TREES_DIR,
    TRIAL_ID_TAG,
    eval_by_action,
)

EXP = "copilot-test-sweep"
STEPS = [1000, 2000, 3000, 4000]
# config tree_depth=2: four seeds, hand-chosen planned success per evaluation; direct = planned / 2
A_PLANNED = {
    "0": [0.1, 0.3, 0.6, 0.8],
    "1": [0.2, 0.5, 0.7, 0.9],
    "2": [0.0, 0.2, 0.4, 0.45],
    "3": [0.3, 0.6, 0.9, 1.0],
}
A_WALL = {"0": 10.0, "1": 20.0, "2": 30.0, "3": 40.0}
# config tree_depth=3: seeds 0-2 finish, seed 3 FAILED (its 0.0 must not count)
B_PLANNED = {"0": [0.1, 0.2, 0.3, 0.4], "1": [0.2, 0.3, 0.4, 0.5], "2": [0.5, 0.6, 0.8, 0.9]}
B_FAILED = [0.0, 0.0]


def _metrics(client, run_id, planned, steps, wall=None, direct_scale=0.5):
    from mlflow.entities import Metric

    now = int(time.time() * 1000)
    ms = []
    for s, v in zip(steps, planned, strict=True):
        ms += [
            Metric(SUCCESS_PLANNED, v, now, s),
            Metric(SUCCESS_DIRECT, v * direct_scale, now, s),
            Metric(ENV_STEPS, s, now, s),
        ]
    if wall is not None:
        ms.append(Metric(TIME_TOTAL_S, wall, now, steps[-1]))
    client.log_batch(run_id, metrics=ms)


# diagnostics of config tree_depth=2 (depth 2): the value at each of STEPS
DIAG = {
    DIAG_SEGMENT_LENGTH_LAYER + "2": [0.05, 0.04, 0.03, 0.03],
    DIAG_REACHABLE_LENGTH_LAYER + "2": [0.0875] * 4,
    DIAG_SEGMENT_UNREACHABLE_LAYER + "2": [0.3, 0.2, 0.1, 0.05],
    DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "2": [0.2, 0.1, 0.0, 0.0],
    DIAG_SUCCESS_AFTER_REACHED: [0.5, 0.6, 0.8, 0.9],
    DIAG_SUCCESS_AFTER_FAILED: [0.1, 0.2, 0.4, 0.6],
    DIAG_Q_MEAN: [0.1, 0.3, 0.5, 0.6],
    DIAG_TAU_HAT_ERROR: [9.0, 6.0, 4.0, 3.0],
    DIAG_EUCLIDEAN_ERROR: [5.0, 5.0, 4.5, 4.5],
    eval_by_action(SUCCESS_PLANNED, "sampled"): [0.2, 0.4, 0.7, 0.9],
}


def _diag_metrics(client, run_id):
    from mlflow.entities import Metric

    now = int(time.time() * 1000)
    client.log_batch(
        run_id,
        metrics=[Metric(k, v, now, s) for k, vals in DIAG.items() for s, v in zip(STEPS, vals, strict=True)],
    )


def _child(client, exp_id, parent_id, key, k, seed):
    tags = {
        PARENT_TAG: parent_id,
        ROLE_TAG: ROLE_TRIAL,
        SWEEP_TAG: "test_sweep",
        TRIAL_ID_TAG: f"{key}-{seed}",
        CONFIG_KEY_TAG: key,
        ALGORITHM_TAG: "copilot",
        ENV_TAG: "maze-point",
        K_TAG: str(k),
        B_TAG: "5",
        ALPHA_SCHEDULE_TAG: "paper_per_task",
        SEED_TAG: seed,
        GIT_COMMIT_TAG: "abcdef1234567",
    }
    return client.create_run(exp_id, run_name=f"{key}_s{seed}", tags=tags).info.run_id


def _tree_npz(path: Path, iteration: int, rng, k_depth: int = 3) -> None:
    n_tasks = 2
    trees = rng.uniform(0.05, 0.95, size=(n_tasks, 2**k_depth + 1, 2))
    steps = np.full((n_tasks, k_depth + 1, 2**k_depth), -1, dtype=np.int64)
    reached = np.zeros_like(steps, dtype=bool)
    for k in range(k_depth + 1):
        steps[:, k, : 2**k] = rng.integers(1, 26, size=(n_tasks, 2**k))
        reached[:, k, : 2**k] = rng.random((n_tasks, 2**k)) < 0.7
    np.savez(
        path,
        iteration=iteration,
        env_steps=iteration * 200,
        depth=k_depth,
        trees=trees,
        subtask_steps=steps,
        subtask_reached=reached,
        layout="u-maze",
        tau_hat_length=np.array([0.0125, 0.025, 0.05, 0.1]),
        tau_hat=np.array([0.05, 0.06, 0.08, 0.11]) - iteration * 0.001,
    )


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    import mlflow

    root = tmp_path_factory.mktemp("mlflow")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment(EXP, artifact_location=(root / "artifacts").as_uri())
    parent = client.create_run(exp_id, run_name="sweep", tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "test_sweep"})
    pid = parent.info.run_id
    ids = {}
    for seed, vals in A_PLANNED.items():
        rid = _child(client, exp_id, pid, "tree_depth=2", 2, seed)
        _metrics(client, rid, vals, STEPS, A_WALL[seed])
        _diag_metrics(client, rid)
        client.set_terminated(rid, "FINISHED")
    for seed, vals in B_PLANNED.items():
        rid = ids[f"B{seed}"] = _child(client, exp_id, pid, "tree_depth=3", 3, seed)
        _metrics(client, rid, vals, STEPS, 100.0)
        client.set_terminated(rid, "FINISHED")
    rid = ids["failed"] = _child(client, exp_id, pid, "tree_depth=3", 3, "3")
    _metrics(client, rid, B_FAILED, STEPS[:2], 5.0)
    client.set_terminated(rid, "FAILED")
    # config tree_depth=4: a single evaluation per seed; seed 1 still running, seed 2 running, no evals yet
    rid = _child(client, exp_id, pid, "tree_depth=4", 4, "0")
    _metrics(client, rid, [0.7], [1500], 7.0)
    client.set_terminated(rid, "FINISHED")
    rid = ids["running"] = _child(client, exp_id, pid, "tree_depth=4", 4, "1")
    _metrics(client, rid, [0.5], [1600], 7.0)
    ids["no_eval"] = _child(client, exp_id, pid, "tree_depth=4", 4, "2")
    # tree snapshots for config tree_depth=3, seed 0
    rng = np.random.default_rng(3)
    tree_dir = root / "npz" / TREES_DIR
    tree_dir.mkdir(parents=True)
    for it in (5, 10, 15, 20):
        _tree_npz(tree_dir / f"trees_iter{it:06d}.npz", it, rng)
    client.log_artifacts(ids["B0"], str(tree_dir), TREES_DIR)
    # config tree_depth=0 (plain SAC): its snapshots hold [s0, g] only, no tree to draw
    rid = ids["plain"] = _child(client, exp_id, pid, "tree_depth=0", 0, "0")
    _metrics(client, rid, [0.0, 0.1], STEPS[:2], 3.0)
    client.set_terminated(rid, "FINISHED")
    flat_dir = root / "npz0" / TREES_DIR
    flat_dir.mkdir(parents=True)
    for it in (5, 10):
        _tree_npz(flat_dir / f"trees_iter{it:06d}.npz", it, rng, k_depth=0)
    client.log_artifacts(rid, str(flat_dir), TREES_DIR)

    # an experiment with a parent but no children, and one with children but no parent
    empty_id = client.create_experiment("empty-sweep", artifact_location=(root / "a2").as_uri())
    client.create_run(empty_id, tags={ROLE_TAG: ROLE_SWEEP})
    orphan_id = client.create_experiment("orphans", artifact_location=(root / "a3").as_uri())
    rid = client.create_run(
        orphan_id, tags={ROLE_TAG: ROLE_TRIAL, CONFIG_KEY_TAG: "default", SEED_TAG: "0"}
    ).info.run_id
    _metrics(client, rid, [0.2, 0.4], STEPS[:2], 3.0)
    client.set_terminated(rid, "FINISHED")

    out = root / "report"
    rc = main(["--experiment", EXP, "--tracking-uri", uri, "--out", str(out)])
    return {"uri": uri, "client": client, "parent": pid, "ids": ids, "out": out, "rc": rc, "root": root}


@pytest.fixture(scope="module")
def table(store):
    return pd.read_csv(store["out"] / "summary.csv").set_index("config_key")


def _boot_ci(x):
    # independent of analysis.stats: the exact bootstrap built by brute force (every one of the n^n
    # ordered resamples), IQM by sorting each row by hand
    x = np.asarray(x, dtype=float)
    n = len(x)
    idx = np.array(list(itertools.product(range(n), repeat=n)))
    s = np.sort(x[idx], axis=1)
    g = int(np.floor(0.25 * n))
    boots = s[:, g : n - g].mean(axis=1)
    return np.percentile(boots, [2.5, 97.5])


def test_report_succeeds(store):
    assert store["rc"] == 0


def test_table_final_success_below_five_seeds_is_mean_and_range(table, store):
    """4 seeds: no IQM, no CI; the mean and the seeds' range, and the table says so."""
    finals = [v[-1] for v in A_PLANNED.values()]
    row = table.loc["tree_depth=2"]
    assert row["n_seeds"] == 4
    assert row["planned_final"] == pytest.approx(np.mean(finals)) == pytest.approx(0.7875)
    assert row["planned_final_estimator"] == "mean" and row["planned_final_interval"] == "range"
    assert (row["planned_final_low"], row["planned_final_high"]) == (min(finals), max(finals))
    assert row["direct_final"] == pytest.approx(0.7875 / 2)
    assert row["wall_time_s_mean"] == pytest.approx(25.0)
    md = (store["out"] / "summary.md").read_text()
    assert f"mean {np.mean(finals):.3f}, range over 4 seeds: [0.450, 1.000]" in md
    assert "CI" not in md.split("\n", 2)[2]  # no configuration has 5 seeds: no interval is a CI


def test_failed_run_is_excluded_from_numbers(table):
    row = table.loc["tree_depth=3"]
    assert row["n_seeds"] == 3  # the FAILED seed does not count
    assert row["planned_final"] == pytest.approx(np.mean([0.4, 0.5, 0.9]))
    assert row["wall_time_s_mean"] == pytest.approx(100.0)


def test_steps_to_threshold(table):
    row = table.loc["tree_depth=2"]
    # to 0.5: seeds reach at 3000, 2000, never, 2000; 4 seeds: the mean, infinite -> not reached, 3/4
    assert row["planned_steps_to_0.5"] == "not reached"
    assert row["planned_seeds_reaching_0.5"] == 3
    assert row["planned_steps_to_0.9"] == "not reached"
    assert row["planned_seeds_reaching_0.9"] == 2
    # direct success (= planned / 2) reaches 0.5 only for seed 3 at 4000
    assert row["direct_steps_to_0.5"] == "not reached"
    assert row["direct_seeds_reaching_0.5"] == 1
    # both seeds of tree_depth=4 reach 0.5 (at 1500 and 1600): the mean
    assert float(table.loc["tree_depth=4", "planned_steps_to_0.5"]) == pytest.approx(1550.0)


def test_single_evaluation_config(table, store):
    row = table.loc["tree_depth=4"]
    assert row["n_seeds"] == 2  # FINISHED and RUNNING with one evaluation each; the one without evals not
    assert row["planned_final"] == pytest.approx(0.6)
    report = (store["out"] / "report.md").read_text()
    assert "tree_depth=4" in report or "K=4" in report
    assert "single evaluation" in report


def test_pngs_exist_and_are_not_blank(store):
    pngs = sorted(store["out"].glob("*.png"))
    names = {p.name for p in pngs}
    assert {"success_vs_env_steps.png", "final_success.png", "subgoal_tree_K_3.png"} <= names
    # these runs logged no return and no mastered share: no figure pretends they did
    assert not names & {"return_vs_env_steps.png", "mastered_vs_env_steps.png"}
    for p in pngs:
        img = mpimg.imread(p)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
        assert img[..., :3].std() > 0.02, f"{p.name} looks blank"


def test_diagnostics_page_draws_the_diag_curves_and_tau_hat(store):
    names = {p.name for p in store["out"].glob("*.png")}
    assert {"diagnostics.png", "tau_hat.png"} <= names
    report = (store["out"] / "report.md").read_text()
    assert "## Diagnostics" in report and "## Learned time cost tau_hat against segment length" in report


def test_every_diagnostics_panel_says_what_its_y_axis_is(store, tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from analysis import run_figures
    from analysis.aggregate import summarise
    from analysis.load import load_sweep

    drawn = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
    configs, _ = summarise(load_sweep(store["uri"], EXP), reps=10)
    assert run_figures.diagnostics(configs, tmp_path / "diagnostics.png") is not None
    (fig,) = drawn
    labels = {ax.get_title().replace("\n", " "): ax.get_ylabel() for ax in fig.axes if ax.get_title()}
    assert labels and all(labels.values()), labels
    assert labels["critic's mean Q"] == "mean Q (return units)"
    assert (
        labels["time costs: tau_hat against the agent's steps"]
        == "env steps (new sub-tasks, before the refit)"
    )


def test_diagnostics_draw_a_flat_methods_lines_only_where_they_mean_what_the_panel_says():
    """HER's "plan" is the straight segment and its training "sub-task" the whole task: drawn in the
    sub-goal panels they would read as a planner's. A tree draws everywhere; SoRB (planned success
    differs from direct) draws its planned path; HER (planned = direct) only the critic and success."""
    from analysis.load import Trial
    from analysis.run_figures import _DIAG_PANELS, PLAN, TREE, diagnostic_keys
    from copilot_ray.keys import DIAG_SEGMENT_LENGTH_LAYER, PLANNED_COLLISION_FREE

    def trial(curves):
        return Trial(
            run_id="r", run_name="r", status="FINISHED", config_key="c", seed="0", tags={}, curves=curves
        )

    steps = np.array([1000.0, 2000.0])
    curves = {SUCCESS_DIRECT: (steps, np.array([0.1, 0.2])), DIAG_Q_MEAN: (steps, np.array([0.1, 0.2]))}
    her = trial({**curves, SUCCESS_PLANNED: (steps, np.array([0.1, 0.2]))})
    sorb = trial({**curves, SUCCESS_PLANNED: (steps, np.array([0.1, 0.4]))})
    tree = trial({**her.curves, DIAG_SEGMENT_LENGTH_LAYER + "3": (steps, steps)})
    panels = {title: (lines, needs) for title, lines, needs in _DIAG_PANELS}
    by_needs = {
        TREE: panels["training sub-task success by layer"][0],
        PLAN: panels["{tasks}: planned path collision-free / followed"][0],
    }
    assert panels["training sub-task success by layer"][1] == TREE
    assert panels["{tasks}: planned path collision-free / followed"][1] == PLAN
    for trial, tree_lines, plan_lines in ((her, 0, 0), (sorb, 0, 3), (tree, 3, 3)):
        assert len(diagnostic_keys(trial, by_needs[TREE], TREE)) == tree_lines
        assert len(diagnostic_keys(trial, by_needs[PLAN], PLAN)) == plan_lines
    assert (PLANNED_COLLISION_FREE, ":") in diagnostic_keys(sorb, by_needs[PLAN], PLAN)
    assert diagnostic_keys(her, (("x{K}", "-", "mean Q"),), "any") == [("x0", "-")]


def test_diag_curves_and_tau_hat_are_loaded(store):
    from analysis.load import load_sweep, load_tree_snapshots

    sweep = load_sweep(store["uri"], EXP)
    trial = next(t for t in sweep.trials if t.config_key == "tree_depth=2")
    steps, values = trial.curves[DIAG_Q_MEAN]
    np.testing.assert_allclose(steps, STEPS)
    np.testing.assert_allclose(values, DIAG[DIAG_Q_MEAN])
    b0 = next(t for t in sweep.trials if t.run_id == store["ids"]["B0"])
    snap = load_tree_snapshots(store["uri"], b0.run_id, b0.tree_artifacts[:1])[0]
    np.testing.assert_allclose(snap.tau_hat_length, [0.0125, 0.025, 0.05, 0.1])
    np.testing.assert_allclose(snap.tau_hat, np.array([0.05, 0.06, 0.08, 0.11]) - 0.005)


def test_tree_depth_zero_gets_a_note_not_a_failed_figure(store):
    report = (store["out"] / "report.md").read_text()
    assert "K=0 has tree depth 0 (no planner, plain SAC): no sub-goal tree to draw." in report
    assert "tree figure for K=0" not in report  # not reported as a failed figure
    assert not list(store["out"].glob("subgoal_tree_K_0*.png"))
    assert list(store["out"].glob("subgoal_tree_K_3*.png"))


@pytest.mark.parametrize(
    ("depth", "layers"), [(5, [2, 3, 4]), (4, [2, 3, 4]), (3, [1, 2, 3]), (2, [1, 2]), (1, [1])]
)
def test_tree_figure_shows_the_papers_layers(depth, layers):
    from analysis.run_figures import tree_figure_layers

    assert tree_figure_layers(depth) == layers


def test_report_references_every_png(store):
    report = (store["out"] / "report.md").read_text()
    for p in store["out"].glob("*.png"):
        assert f"]({p.name})" in report
    assert "| K=2 |" in report  # the Markdown table, labelled by the varying axis
    assert (store["out"] / "report.html").is_file()


def test_missing_runs_listed(store, capsys):
    report = (store["out"] / "report.md").read_text()
    missing = report.split("## Missing or incomplete")[1].split("## Summary")[0]
    ids = store["ids"]
    assert "failed run" in missing and ids["failed"] in missing
    assert "still running" in missing and ids["running"] in missing
    assert "no evaluation metrics yet" in missing and ids["no_eval"] in missing
    assert "K=3 lacks seeds 3" in missing
    assert "K=4 lacks seeds 2, 3" in missing


def test_terminal_lists_missing(store, tmp_path, capsys):
    rc = main(
        [
            EXP,
            "--tracking-uri",
            store["uri"],
            "--out",
            str(tmp_path / "r"),
            "--no-log",
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert store["ids"]["failed"] in out and "still running" in out
    with pytest.raises(SystemExit) as stopped:  # fewer resamples than the rules allow: refused by name
        main([EXP, "--tracking-uri", store["uri"], "--no-log", "--bootstrap-reps", "2000"])
    assert stopped.value.code == 2
    assert "--bootstrap-reps 2000 is invalid: at least 20,000" in capsys.readouterr().err


def test_parent_run_got_the_artifacts(store):
    client = store["client"]
    names = {Path(f.path).name for f in client.list_artifacts(store["parent"], REPORT_ARTIFACT)}
    assert {
        "report.md",
        "report.html",
        "summary.csv",
        "summary.md",
        "success_vs_env_steps.png",
        "final_success.png",
        "subgoal_tree_K_3.png",
    } <= names


def test_missing_experiment_exit_2_names_it(store):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "analysis.report",
            "--experiment",
            "no-such-sweep",
            "--tracking-uri",
            store["uri"],
        ],
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parent.parent,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "no-such-sweep" in proc.stderr and EXP in proc.stderr  # names it and lists what exists


def test_experiment_without_children_exit_2(store, tmp_path, capsys):
    assert main(["empty-sweep", "--tracking-uri", store["uri"], "--out", str(tmp_path)]) == 2
    assert "no child" in capsys.readouterr().err


def test_no_parent_run_reports_and_skips_logging(store, tmp_path, capsys):
    assert main(["orphans", "--tracking-uri", store["uri"], "--out", str(tmp_path)]) == 0
    assert "not logged" in capsys.readouterr().out
    assert "not logged" in (tmp_path / "report.md").read_text()


def test_without_out_the_report_goes_beside_a_sweeps_store(store, tmp_path, monkeypatch, capsys):
    """A sweep's store results/<sweep>/mlflow.db gets its report in results/<sweep>/report (its
    experiment's name is another: the sweep's folder is what the user knows); a store elsewhere keeps
    results/<experiment>/report under the working directory."""
    import shutil

    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "results" / "depth_k"
    sweep.mkdir(parents=True)
    shutil.copy(Path(store["uri"].removeprefix("sqlite:///")), sweep / "mlflow.db")
    assert main(["orphans", "--tracking-uri", f"sqlite:///{sweep / 'mlflow.db'}"]) == 0
    assert f"report: {sweep / 'report' / 'report.md'}" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == ["depth_k"]
    elsewhere = tmp_path / "stores" / "mlflow.db"
    elsewhere.parent.mkdir()
    shutil.copy(sweep / "mlflow.db", elsewhere)
    assert main(["orphans", "--tracking-uri", f"sqlite:///{elsewhere}"]) == 0
    assert (tmp_path / "results" / "orphans" / "report" / "report.md").is_file()
    assert not (elsewhere.parent / "report").exists()


def test_no_store_found_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    monkeypatch.chdir(tmp_path)
    assert main(["anything"]) == 2
    assert "--tracking-uri" in capsys.readouterr().err
    assert not (tmp_path / "mlflow.db").exists()  # never creates an empty store


# ---------------------------------------------------------------------------------------------- stats


def test_iqm_matches_scipy_trim_mean():
    from scipy.stats import trim_mean

    rng = np.random.default_rng(0)
    for n in range(1, 12):
        x = rng.normal(size=(n, 7))
        np.testing.assert_allclose(stats.iqm(x), trim_mean(x, 0.25, axis=0))


def test_bootstrap_ci_contains_iqm_and_collapses_for_identical_seeds():
    x = np.array([0.2, 0.4, 0.5, 0.9, 0.3])
    lo, hi = stats.bootstrap_ci(x)
    assert lo <= stats.iqm(x) <= hi and lo < hi
    lo, hi = stats.bootstrap_ci(np.full(5, 0.7))
    assert lo == pytest.approx(0.7) and hi == pytest.approx(0.7)
    # curves: per grid column, and NaN (no data) columns stay NaN
    mat = np.array([[0.1, 0.5, np.nan], [0.3, 0.7, np.nan], [0.2, 0.6, np.nan]])
    lo, hi = stats.bootstrap_ci(mat, reps=300)
    mid = stats.iqm(mat)
    assert np.all(lo[:2] <= mid[:2]) and np.all(mid[:2] <= hi[:2]) and np.isnan(lo[2])


def test_the_bootstrap_is_exact_up_to_eight_seeds_and_draws_20000_beyond():
    """Every ordered resample of the seeds, enumerated by brute force, gives the same percentiles as the
    exact bootstrap (which enumerates the 126 multisets of 5 seeds with their weights); P(X > Y)'s CI is
    that of every pair of resamples. Beyond 8 seeds it draws 20,000 resamples; a number asked for is used."""
    rng = np.random.default_rng(3)
    for n in (3, 5):
        x = rng.random(n).round(2)
        everything = np.array(list(itertools.product(range(n), repeat=n)))
        population = np.sort(x[everything], axis=1)[:, n // 4 : n - n // 4].mean(axis=1)
        np.testing.assert_allclose(stats.bootstrap_ci(x), np.percentile(population, [2.5, 97.5]))
    x, y = rng.random(4).round(1), rng.random(4).round(1)
    every = np.array(list(itertools.product(range(4), repeat=4)))
    xb, yb = x[every][:, None, :, None], y[every][None, :, None, :]
    pairs = ((xb > yb) + 0.5 * (xb == yb)).mean(axis=(2, 3)).ravel()
    values, counts = stats._improvement_distribution(x, y)
    for q in (2.5, 50.0, 97.5):
        assert stats.population_percentile(values, counts, q) == pytest.approx(np.percentile(pairs, q))
    # with 5 seeds a side and no ties, the exact CI clears 0.5 from 21 of 25 pair wins on
    readings = {}
    for ranks in itertools.combinations(range(10), 5):
        a = np.array(ranks, float)
        b = np.array([r for r in range(10) if r not in ranks], float)
        imp = stats.improvement(a, b)
        readings.setdefault(round(imp.p * 25), set()).add(imp.reading())
    assert readings[21] == readings[25] == {"ahead"} and readings[20] == readings[5] == {"not separated"}
    assert readings[4] == {"behind"}
    assert stats.bootstrap_method(5) == "exact: all 5^5 = 3,125 resamples of the 5 seeds"
    assert stats.bootstrap_method(9) == "20,000 bootstrap resamples" and not stats.exact_bootstrap(9)
    nine = rng.random(9)
    drawn = np.random.default_rng(0).integers(0, 9, size=(20_000, 9))
    np.testing.assert_allclose(
        stats.bootstrap_ci(nine), np.percentile(stats.iqm(nine[drawn], axis=1), [2.5, 97.5])
    )


def test_interpolate_never_extrapolates():
    out = stats.interpolate([10, 20], [0.0, 1.0], [5, 10, 15, 20, 25])
    np.testing.assert_allclose(out[1:4], [0.0, 0.5, 1.0])
    assert np.isnan(out[0]) and np.isnan(out[4])


def test_steps_to_threshold_and_inf_iqm():
    assert stats.steps_to_threshold([1, 2, 3], [0.1, 0.5, 0.9], 0.5) == 2
    assert stats.steps_to_threshold([1, 2, 3], [0.1, 0.2, 0.3], 0.5) == np.inf
    assert stats.iqm(np.array([1.0, 2.0, 3.0, np.inf])) == 2.5  # one laggard is trimmed
    assert stats.iqm(np.array([1.0, 2.0, np.inf, np.inf])) == np.inf


def test_axes_fall_back_to_config_key_when_tags_do_not_separate_configs():
    from analysis.load import Sweep, Trial

    def trial(key, k):
        return Trial("r", "r", "FINISHED", key, "0", {"K": k, "b": "5"})

    sweep = Sweep("uri", "e", "1", None, "s", [trial("tree_depth=2", "2"), trial("tree_depth=3", "3")])
    assert sweep.axes() == ["K"]
    sweep.trials = [trial("K=2,lr=1", "2"), trial("K=2,lr=2", "2"), trial("K=3,lr=1", "3")]
    assert sweep.axes() == ["config_key"]


# ------------------------------------------------------------------------------------------- planners
def test_planners_from_several_sweep_runs_get_one_table_and_figure(tmp_path):
    """RRT* and SGT-PG (two parts of one spec file: two sweep runs) on two agents, reported together with
    --parent-run all: one row per (env, algorithm) with the seeds' mean of each final value."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import PATH_CHECKS_VS_RRT, PATH_LENGTH_VS_RRT, PATH_SUCCESS

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("planners", artifact_location=(tmp_path / "art").as_uri())
    now = int(time.time() * 1000)
    finals = {}
    for algorithm in ("rrt_star", "sgt_pg"):
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: f"p_{algorithm}"}).info.run_id
        for env in ("maze-point", "maze-rigid"):
            for seed in ("0", "1"):
                tags = {
                    PARENT_TAG: pid,
                    ROLE_TAG: ROLE_TRIAL,
                    SWEEP_TAG: f"p_{algorithm}",
                    CONFIG_KEY_TAG: f"env.id={env}",  # the same keys in both parts
                    ALGORITHM_TAG: algorithm,
                    ENV_TAG: env,
                    SEED_TAG: seed,
                }
                rid = client.create_run(exp_id, tags=tags).info.run_id
                success = [0.2, 0.5 + 0.1 * int(seed)] if algorithm == "sgt_pg" else [1.0, 1.0]
                ratio = [3.0, 2.0 + int(seed)] if algorithm == "sgt_pg" else [1.0, 1.0]
                steps = [1000, 5000 + int(seed)]
                lengths = [(s, v) for s, v in zip(steps, ratio, strict=True)]
                if env == "maze-point" and algorithm == "sgt_pg" and seed == "1":
                    success[-1] = 0.0  # no successful path at the end: its length ratio is not logged then
                    lengths = lengths[:1]
                client.log_batch(
                    rid,
                    metrics=[Metric(PATH_SUCCESS, v, now, s) for s, v in zip(steps, success, strict=True)]
                    + [Metric(PATH_CHECKS_VS_RRT, v, now, s) for s, v in zip(steps, ratio, strict=True)]
                    + [Metric(PATH_LENGTH_VS_RRT, v, now, s) for s, v in lengths],
                )
                client.set_terminated(rid, "FINISHED")
                finals[(env, algorithm, seed)] = (success[-1], ratio[-1])
    out = tmp_path / "report"
    assert main(["planners", "--tracking-uri", uri, "--out", str(out), "--parent-run", "all"]) == 0
    frame = pd.read_csv(out / "planners.csv")
    assert len(frame) == 4
    row = frame[(frame.env == "maze-rigid") & (frame.algorithm == "sgt_pg")].iloc[0]
    assert row["n_seeds"] == 2
    assert row["success"] == pytest.approx(np.mean([finals[("maze-rigid", "sgt_pg", s)][0] for s in "01"]))
    assert row["length / RRT*"] == pytest.approx(2.5) and row["length / RRT* max"] == 3.0
    # a seed whose last evaluation had no length does not count with an older one
    point = frame[(frame.env == "maze-point") & (frame.algorithm == "sgt_pg")].iloc[0]
    assert point["length / RRT*"] == 2.0 and point["checks / RRT*"] == pytest.approx(2.5)
    md = (out / "report.md").read_text()
    assert "Planners: paths on the test tasks" in md and "planners_paths.png" in md
    assert "| maze-point | rrt_star | 2 | 1.00 |" in md
    # two seeds: their range, never a bracketed pair that would read as a confidence interval
    assert "| maze-rigid | sgt_pg | 2 |" in md and "2.50 (range 2.00-3.00)" in md and "[2.00, 3.00]" not in md
    assert (out / "planners_paths.png").stat().st_size > 10_000


def test_baselines_get_the_by_method_figures_and_the_common_success_column(tmp_path):
    """CO-PILOT (planned, direct, success) against PPO (success, direct only) on the Ant maze, from two
    stores (--also-from): the table's success column is each method's headline, the by-method figures
    and the Ant maze's return (paper Fig. 2d) are drawn; a store given twice is refused."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_MASTERED, EVAL_RETURN, EVAL_SUCCESS

    now = int(time.time() * 1000)
    finals = {"copilot": {"0": 0.8, "1": 0.9}, "ppo": {"0": 0.1, "1": 0.3}}
    uris = {}
    for algorithm, seeds in finals.items():  # two sweeps that ran side by side, one SQLite file each
        uri = uris[algorithm] = f"sqlite:///{tmp_path / algorithm}.db"
        client = mlflow.MlflowClient(uri)
        exp_id = client.create_experiment("baselines", artifact_location=(tmp_path / algorithm).as_uri())
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: f"b_{algorithm}"}).info.run_id
        for seed, final in seeds.items():
            tags = {
                PARENT_TAG: pid,
                ROLE_TAG: ROLE_TRIAL,
                SWEEP_TAG: f"b_{algorithm}",
                CONFIG_KEY_TAG: "default",
                ALGORITHM_TAG: algorithm,
                ENV_TAG: "ant-maze",
                SEED_TAG: seed,
            }
            rid = client.create_run(exp_id, tags=tags).info.run_id
            values = [final / 2, final]
            metrics = [Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(STEPS[:2], values, strict=True)]
            metrics += [Metric(SUCCESS_DIRECT, v / 2, now, s) for s, v in zip(STEPS[:2], values, strict=True)]
            metrics += [Metric(EVAL_RETURN, 1000 * v, now, s) for s, v in zip(STEPS[:2], values, strict=True)]
            if algorithm == "copilot":
                metrics += [
                    Metric(SUCCESS_PLANNED, v, now, s) for s, v in zip(STEPS[:2], values, strict=True)
                ]
                metrics += [Metric(EVAL_MASTERED, v, now, s) for s, v in zip(STEPS[:2], values, strict=True)]
            client.log_batch(rid, metrics=metrics)
            client.set_terminated(rid, "FINISHED")
    out = tmp_path / "report"
    argv = ["baselines", "--tracking-uri", uris["copilot"], "--out", str(out), "--parent-run", "all"]
    assert main([*argv, "--also-from", uris["ppo"]]) == 0
    frame = pd.read_csv(out / "summary.csv").set_index("configuration")
    assert frame.loc["algorithm=ppo", "success_final"] == pytest.approx(0.2)
    assert frame.loc["algorithm=copilot", "success_final"] == pytest.approx(0.85)
    assert np.isnan(frame.loc["algorithm=ppo", "planned_final"])  # PPO has no plan
    # the Ant maze's return (Fig. 2d) from both, the walker's mastered share where logged (not the
    # walker here: not labelled Fig. 3)
    names = ("success_by_method.png", "final_success_by_method.png", "return_vs_env_steps.png")
    report = (out / "report.md").read_text()
    for name in (*names, "mastered_vs_env_steps.png"):
        assert (out / name).stat().st_size > 10_000
        assert name in report
    assert "## Return against environment steps on the Ant maze (paper Fig. 2d)" in report
    assert (
        "Fig. 3" not in report and "Fig. 4a" not in report and "Fig. 2a" not in report
    )  # maze and walker figures
    assert main([*argv, "--also-from", uris["copilot"]]) == 2  # the same runs twice


def test_a_label_leaves_out_axes_the_trials_algorithm_lacks():
    """A baseline has no K and no alpha schedule: its tags are empty or "None", and its label says
    only what it has."""
    from analysis.aggregate import config_label
    from analysis.load import Trial

    axes = ["algorithm", "K", "alpha_schedule"]
    sac = Trial("r1", "sac", "FINISHED", "k", "0", {"algorithm": "sac", "K": "None", "alpha_schedule": ""})
    copilot = Trial(
        "r2", "cp", "FINISHED", "k", "0", {"algorithm": "copilot", "K": "3", "alpha_schedule": "p"}
    )
    assert config_label(sac, axes) == "algorithm=sac"
    assert config_label(copilot, axes) == "algorithm=copilot, K=3, alpha_schedule=p"


# ------------------------------------------------------------------------ honest numbers and provenance
# A second hand-made store: CO-PILOT's default (5 seeds, three privileges) against SAC (5 seeds, none)
# and an old PPO run (2 seeds, no privileges tag, no counters). Every trial evaluates at 1000, 2000 and
# 3000 env steps; its 4000 row only repeats the 3000 evaluation (copilot/eval/fresh = 0).
HONEST = "honest-sweep"
FRESH_STEPS = [1000, 2000, 3000, 4000]
FRESH_FLAGS = [1.0, 1.0, 1.0, 0.0]
HONEST_SUCCESS = {
    "copilot": [[0.2 + 0.05 * i, 0.5 + 0.05 * i, 0.7 + 0.05 * i] for i in range(5)],
    "sac": [[0.0, 0.1 + 0.02 * i, 0.2 + 0.02 * i] for i in range(5)],
    "ppo": [[0.0, 0.05, 0.1 + 0.05 * i] for i in range(2)],
}
PRIVILEGE_TAGS = {"copilot": "collision_checks,map_queries,reset_to_state", "sac": "none", "ppo": None}
COMMITS = {"copilot": "1111111aaaaaaa", "sac": "2222222bbbbbbb", "ppo": None}


def _honest_trial(client, exp_id, pid, algorithm, seed, values):
    from mlflow.entities import Metric

    from copilot_ray.keys import (
        EVAL_FRESH,
        EVAL_SUCCESS,
        PRESET_TAG,
        PRIVILEGE_COLLISION_CHECKS,
        PRIVILEGE_MAP_QUERIES,
        PRIVILEGE_RESETS,
        PRIVILEGES_TAG,
    )

    tags = {
        PARENT_TAG: pid,
        ROLE_TAG: ROLE_TRIAL,
        SWEEP_TAG: "honest",
        CONFIG_KEY_TAG: "default",
        ALGORITHM_TAG: algorithm,
        ENV_TAG: "maze-point",
        PRESET_TAG: "default",
        SEED_TAG: str(seed),
    }
    if PRIVILEGE_TAGS[algorithm] is not None:  # the old PPO run predates the tags
        tags[PRIVILEGES_TAG] = PRIVILEGE_TAGS[algorithm]
        tags[GIT_COMMIT_TAG] = COMMITS[algorithm]
    rid = client.create_run(exp_id, run_name=f"{algorithm}-seed{seed}", tags=tags).info.run_id
    now = int(time.time() * 1000)
    logged = [*values, values[-1]]  # the last row repeats the last evaluation
    ms = [Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(FRESH_STEPS, logged, strict=True)]
    ms += [Metric(ENV_STEPS, s, now, s) for s in FRESH_STEPS]
    ms.append(Metric("timers/training_step", 1.0, now, FRESH_STEPS[-1]))  # not exported
    if PRIVILEGE_TAGS[algorithm] is not None:
        ms += [Metric(EVAL_FRESH, f, now, s) for s, f in zip(FRESH_STEPS, FRESH_FLAGS, strict=True)]
        scale = (seed + 1) * (algorithm == "copilot")  # cumulative counts; SAC's are 0
        for key, final in (
            (PRIVILEGE_COLLISION_CHECKS, 100),
            (PRIVILEGE_RESETS, 1),
            (PRIVILEGE_MAP_QUERIES, 10),
        ):
            ms += [Metric(key, final * scale * s / FRESH_STEPS[-1], now, s) for s in FRESH_STEPS]
    client.log_batch(rid, metrics=ms)
    client.set_terminated(rid, "FINISHED")
    return rid


@pytest.fixture(scope="module")
def honest(tmp_path_factory):
    import mlflow

    from copilot_ray.keys import RESOLVED_SPEC_ARTIFACT, SPEC_ARTIFACT

    root = tmp_path_factory.mktemp("honest")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment(HONEST, artifact_location=(root / "artifacts").as_uri())
    pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "honest"}).info.run_id
    client.log_text(pid, "name: honest\n", RESOLVED_SPEC_ARTIFACT)
    client.log_text(pid, "name: honest\n", SPEC_ARTIFACT)
    for algorithm, seeds in HONEST_SUCCESS.items():
        for seed, values in enumerate(seeds):
            _honest_trial(client, exp_id, pid, algorithm, seed, values)
    out = root / "report"
    argv = [HONEST, "--tracking-uri", uri, "--out", str(out), "--no-log"]
    rc = main(argv)
    frame = pd.read_csv(out / "summary.csv").set_index("configuration")
    return {"uri": uri, "out": out, "rc": rc, "argv": argv, "frame": frame, "parent": pid}


def _auc(values):  # three evaluations 1000 apart, window [1000, 3000]: the trapezoid by hand
    return (values[0] + 2 * values[1] + values[2]) / 4


def test_fresh_evaluations_only(tmp_path):
    """fresh = 1, 0, 0, 1 at four steps: the curve keeps two points; a run that never logged the flag
    (copilot_ray.train, older stores) keeps all four."""
    import mlflow
    from mlflow.entities import Metric

    from analysis.load import fresh_only, load_sweep
    from copilot_ray.keys import EVAL_FRESH, EVAL_SUCCESS, validation_key

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("fresh", artifact_location=(tmp_path / "art").as_uri())
    now = int(time.time() * 1000)
    for seed, flags in (("0", [1.0, 0.0, 0.0, 1.0]), ("1", None)):
        tags = {ROLE_TAG: ROLE_TRIAL, CONFIG_KEY_TAG: "default", SEED_TAG: seed}
        rid = client.create_run(exp_id, tags=tags).info.run_id
        ms = [Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(STEPS, [0.2, 0.2, 0.2, 0.6], strict=True)]
        if flags:
            ms += [Metric(EVAL_FRESH, f, now, s) for s, f in zip(STEPS, flags, strict=True)]
        client.log_batch(rid, metrics=ms)
        client.set_terminated(rid, "FINISHED")
    trials = {t.seed: t for t in load_sweep(uri, "fresh").trials}
    steps, values = trials["0"].curves[EVAL_SUCCESS]
    np.testing.assert_array_equal(steps, [1000, 4000])
    np.testing.assert_allclose(values, [0.2, 0.6])
    assert len(trials["1"].curves[EVAL_SUCCESS][0]) == 4
    # validation curves are filtered the same way; other metrics are not
    curve = (np.array(STEPS, float), np.array([0.1, 0.1, 0.1, 0.3]))
    fresh = (np.array(STEPS, float), np.array([1.0, 0.0, 0.0, 1.0]))
    kept = fresh_only({validation_key(EVAL_SUCCESS): curve, ENV_STEPS: curve}, fresh)
    assert len(kept[validation_key(EVAL_SUCCESS)][0]) == 2 and len(kept[ENV_STEPS][0]) == 4


def test_seed_summary_range_below_five_seeds_ci_from_five():
    two = stats.summarise_seeds(np.array([0.2, 0.4]))
    assert two.text() == "mean 0.300, range over 2 seeds: [0.200, 0.400]"
    assert not two.has_ci and "CI" not in two.text()
    assert stats.summarise_seeds(np.array([0.7])).text() == "0.700 (n = 1)"
    five = np.array([0.2, 0.4, 0.5, 0.9, 0.3])
    s = stats.summarise_seeds(five)
    lo, hi = _boot_ci(five)
    assert s.has_ci and s.point == pytest.approx(stats.iqm(five))
    assert (s.low, s.high) == (pytest.approx(lo), pytest.approx(hi))
    assert s.text() == f"IQM {s.point:.3f} [95% CI {lo:.3f}, {hi:.3f}]"
    assert stats.MIN_SEEDS_FOR_CI == 5


def test_probability_of_improvement_on_hand_made_scores():
    x, y = np.array([0.6, 0.7, 0.8, 0.9, 1.0]), np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    assert stats.probability_of_improvement(x, y) == 1.0
    assert stats.probability_of_improvement(y, x) == 0.0
    assert stats.probability_of_improvement(x, x) == 0.5  # identical: every tie counts 1/2
    # one pair of four higher, one tie: (1 + 0.5) / 4
    assert stats.probability_of_improvement([1.0, 0.5], [0.5, 2.0]) == pytest.approx(0.375)
    imp = stats.improvement(x, y)
    assert imp.available and (imp.p, imp.low, imp.high) == (1.0, 1.0, 1.0)
    same = stats.improvement(x, x)
    assert same.p == 0.5 and same.low < 0.5 < same.high
    few = stats.improvement(x, y[:2])
    # below 5 seeds a side: the point estimate without an interval; no seeds: nothing
    assert not few.available and few.text() == "1.00 (no CI: n = 5 and 2; a CI needs 5 each)"
    assert stats.improvement(x, y[:0]).text() == "n/a (no seeds on a side; here 5 and 0)"
    # the reading holds the CI against 0.5
    assert imp.reading() == "ahead" and stats.improvement(y, x).reading() == "behind"
    assert same.reading() == "not separated"
    assert few.reading() == "no reading (n = 5 and 2; a CI needs 5 each)"


def test_auc_over_the_common_window():
    assert stats.auc_window([np.array([1000, 2000, 3000]), np.array([1500, 4000]), np.array([9.0])]) == (
        1500,
        3000,
    )
    assert stats.normalised_auc([0, 10], [0.0, 1.0], 0, 10) == pytest.approx(0.5)
    assert stats.normalised_auc([0, 5, 10], [0.0, 1.0, 1.0], 0, 10) == pytest.approx(0.75)
    assert stats.normalised_auc([0, 10], [0.0, 1.0], 5, 10) == pytest.approx(0.75)
    assert np.isnan(stats.normalised_auc([0, 5], [0.0, 1.0], 0, 10))  # never extrapolated


def test_headline_table_final_auc_and_ci_only_from_five_seeds(honest):
    assert honest["rc"] == 0
    frame = honest["frame"]
    assert not [c for c in frame.columns if "best" in c or "max" in c]  # no best-over-evaluations figure
    cp = frame.loc["algorithm=copilot"]
    finals = [v[-1] for v in HONEST_SUCCESS["copilot"]]  # the stale 4000 row repeats these
    lo, hi = _boot_ci(finals)
    assert cp["success_final_estimator"] == "IQM" and cp["success_final_interval"] == "95% CI"
    assert cp["success_final"] == pytest.approx(stats.iqm(np.array(finals)))
    assert (cp["success_final_low"], cp["success_final_high"]) == (pytest.approx(lo), pytest.approx(hi))
    assert cp["success_final_env_steps"] == 3000  # the last fresh evaluation, not the stale row
    assert (cp["success_auc_from"], cp["success_auc_to"]) == (1000, 3000)
    aucs = [_auc(v) for v in HONEST_SUCCESS["copilot"]]
    assert cp["success_auc"] == pytest.approx(stats.iqm(np.array(aucs)))
    ppo = frame.loc["algorithm=ppo"]
    assert ppo["success_final_estimator"] == "mean" and ppo["success_final_interval"] == "range"
    assert ppo["success_auc"] == pytest.approx(np.mean([_auc(v) for v in HONEST_SUCCESS["ppo"]]))
    md = (honest["out"] / "summary.md").read_text()
    assert f"IQM {cp['success_final']:.3f} [95% CI {lo:.3f}, {hi:.3f}]" in md
    assert "mean 0.125, range over 2 seeds: [0.100, 0.150]" in md


def test_final_success_is_read_at_the_budget(tmp_path):
    """Two sweeps with a 3,000-env-step budget: CO-PILOT's long iterations end at 2,000 and 4,000 (its
    last evaluation 1,000 steps past the budget), HER's at 1,000, 2,000, 3,000 and 3,100. Final is each
    seed's success at 3,000 (CO-PILOT's read halfway between 0.2 and 0.8), the AUC ends there, and a
    sweep without a budget keeps the last evaluation."""
    import mlflow
    from mlflow.entities import Metric

    from analysis.aggregate import summarise
    from analysis.load import load_sweep
    from analysis.tables import details_table, summary_frame
    from copilot_ray.keys import BUDGET_PARAM, EVAL_SUCCESS

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("budget", artifact_location=(tmp_path / "art").as_uri())
    now = int(time.time() * 1000)
    curves = {"copilot": ([2000, 4000], [0.2, 0.8]), "her": ([1000, 2000, 3000, 3100], [0.1, 0.3, 0.5, 0.9])}
    for algorithm, (steps, values) in curves.items():
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: algorithm}).info.run_id
        client.log_param(pid, BUDGET_PARAM, 3000)
        tags = {PARENT_TAG: pid, ROLE_TAG: ROLE_TRIAL, SWEEP_TAG: algorithm, ALGORITHM_TAG: algorithm}
        rid = client.create_run(exp_id, tags={**tags, CONFIG_KEY_TAG: "default", SEED_TAG: "0"}).info.run_id
        client.log_batch(
            rid, metrics=[Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(steps, values, strict=True)]
        )
        client.set_terminated(rid, "FINISHED")
    configs, _ = summarise(load_sweep(uri, "budget", parent_run_id="all"), reps=50)
    got = {c.algorithm: c.metrics[EVAL_SUCCESS] for c in configs}
    assert got["copilot"].finals.tolist() == pytest.approx([0.5])  # not its 0.8 after 4,000 env steps
    assert got["her"].finals.tolist() == pytest.approx([0.5])  # not its 0.9 after 3,100
    assert got["copilot"].final_step == got["her"].final_step == 3000
    assert got["her"].auc_window == (2000, 3000)  # from the latest first evaluation to the budget
    assert got["her"].aucs.tolist() == pytest.approx([0.4])
    # the cadence each final rests on: evaluations up to the budget, median gap through the one past it
    assert (got["copilot"].evaluations, got["copilot"].evaluation_gap) == (1, 2000)
    assert (got["her"].evaluations, got["her"].evaluation_gap) == (3, 1000)
    details = details_table(summary_frame(configs)).markdown()
    assert (
        "evaluations to it (median gap)" in details
        and "| 1 (2,000) |" in details
        and "| 3 (1,000) |" in details
    )
    # a seed evaluated only after the budget gives its first evaluation, the closest to it
    from analysis.aggregate import final_values

    late = load_sweep(uri, "budget", parent_run_id="all").trials
    finals, steps = final_values(late, EVAL_SUCCESS, 1500.0)
    assert {t.tags[ALGORITHM_TAG]: (f, s) for t, f, s in zip(late, finals, steps, strict=True)} == {
        "copilot": (0.2, 2000.0),
        "her": (pytest.approx(0.2), 1500.0),
    }

    # without a budget (stopped by iterations, or older stores): the last evaluation
    sweep = load_sweep(uri, "budget", parent_run_id="all")
    for t in sweep.trials:
        t.budget = float("nan")
    configs, _ = summarise(sweep, reps=50)
    got = {c.algorithm: c.metrics[EVAL_SUCCESS] for c in configs}
    assert got["copilot"].finals.tolist() == [0.8] and got["copilot"].final_step == 4000
    assert got["her"].auc_window == (2000, 3100)


def test_curves_have_a_band_only_from_five_seeds(honest):
    from analysis.aggregate import summarise
    from analysis.load import load_sweep
    from copilot_ray.keys import EVAL_SUCCESS

    configs, _ = summarise(load_sweep(honest["uri"], HONEST), reps=200)
    curves = {c.algorithm: c.metrics[EVAL_SUCCESS].curve for c in configs}
    assert curves["copilot"].has_ci and not curves["ppo"].has_ci
    assert len(curves["ppo"].seed_curves) == 2  # drawn as thin lines instead of a band
    np.testing.assert_allclose(curves["ppo"].center[0], 0.0)
    assert (honest["out"] / "success_by_method.png").stat().st_size > 10_000


def test_privileges_and_budgets_beside_every_result(honest):
    frame = honest["frame"]
    cp, sac, ppo = (frame.loc[f"algorithm={a}"] for a in ("copilot", "sac", "ppo"))
    assert cp["privileges"] == "collision_checks, map_queries, reset_to_state"
    assert sac["privileges"] == "none" and ppo["privileges"] == "-"
    # cumulative counts, mean over seeds, read where the final is (the last evaluation, at 3000: the row at
    # 4000 only repeats it): 3/4 of 100 * (1..5), 1..5, 10 * (1..5)
    assert (cp["collision_checks"], cp["resets"], cp["map_queries"]) == (225, 2.25, 22.5)
    assert (sac["collision_checks"], sac["resets"], sac["map_queries"]) == (0, 0, 0)
    assert np.isnan(ppo["collision_checks"]) and cp["env_steps"] == 4000
    md = (honest["out"] / "summary.md").read_text()
    assert (
        "| algorithm=copilot | 5 | collision_checks, map_queries, reset_to_state | 4,000 | 225 | 2 | 22 |"
        in md
    )
    assert "| algorithm=sac | 5 | none | 4,000 | 0 | 0 | 0 |" in md
    assert "| algorithm=ppo | 2 | - | 4,000 | - | - | - |" in md
    report = (honest["out"] / "report.md").read_text()
    caption = (
        "Privileges ('-': runs older than the privileges tag): algorithm=copilot: collision_checks, "
        "map_queries, reset_to_state; algorithm=ppo: -; algorithm=sac: none."
    )
    for figure in ("final_success_by_method.png", "success_by_method.png"):
        assert f"]({figure})\n\n{caption}" in report


def test_every_configuration_is_held_against_this_checkouts_defaults(honest):
    report = (honest["out"] / "report.md").read_text()
    section = report.split("## Settings against this checkout's defaults")[1].split("## ")[0]
    rows = [line for line in section.splitlines() if line.startswith("| algorithm=")]
    # These hand-made runs logged no params: each row says so rather than listing every setting.
    assert len(rows) == 3 and all("not compared: its runs logged no settings" in r for r in rows)


def test_probability_of_improvement_in_the_report(honest):
    """CO-PILOT's default against the best other method by final success (SAC, 5 seeds; PPO is worse)."""
    report = (honest["out"] / "report.md").read_text()
    section = report.split("## Probability of improvement over the best other method")[1].split("## ")[0]
    assert (
        "| algorithm=copilot (collision_checks, map_queries, reset_to_state) | algorithm=sac (none) "
        "| 1.00 [95% CI 1.00, 1.00] | ahead (99%: ahead) | 1.00 [95% CI 1.00, 1.00] | ahead (99%: ahead) | yes: "
        in section
    )
    assert report.index("## Summary") < report.index("## Probability of improvement")
    imp = pd.read_csv(honest["out"] / "improvement.csv")
    assert imp.loc[0, "p_final"] == 1.0 and imp.loc[0, "p_auc"] == 1.0
    assert imp.loc[0, "p_final_reading"] == "ahead" and imp.loc[0, "p_auc_reading"] == "ahead"


def test_success_against_collision_checks_draws_each_method_at_the_checks_it_spent(honest):
    """CO-PILOT spent checks (a line at the seeds' mean checks), SAC none (one point at 0), the old PPO
    runs never logged the count (left out, said so)."""
    from analysis.aggregate import summarise
    from analysis.figures import checks_at
    from analysis.load import load_sweep

    png = honest["out"] / "success_vs_collision_checks.png"
    assert png.exists() and mpimg.imread(png).shape[0] > 100
    report = (honest["out"] / "report.md").read_text()
    assert "success_vs_collision_checks.png" in report
    assert "success_vs_collision_checks.png: algorithm=ppo not drawn: its runs did not log" in report
    configs, _ = summarise(load_sweep(honest["uri"], HONEST), reps=200)
    by = {c.algorithm: c for c in configs}
    end = float(FRESH_STEPS[-1])
    # seeds 0-4 end at 100 x (seed + 1) checks: their mean is 300; half way, half of it.
    np.testing.assert_allclose(checks_at(by["copilot"], np.array([end / 2, end])), [150.0, 300.0])
    np.testing.assert_allclose(checks_at(by["sac"], np.array([end])), [0.0])
    assert checks_at(by["ppo"], np.array([end])) is None


def test_improvement_over_each_other_configuration(honest, tmp_path):
    """--improvement-over each: CO-PILOT's default against every other row (SAC and PPO), not the best alone."""
    out = tmp_path / "each"
    argv = [
        HONEST,
        "--tracking-uri",
        honest["uri"],
        "--out",
        str(out),
        "--no-log",
        "--improvement-over",
        "each",
    ]
    assert main(argv) == 0
    imp = pd.read_csv(out / "improvement.csv")
    assert sorted(imp["other"]) == ["algorithm=ppo", "algorithm=sac"]
    report = (out / "report.md").read_text()
    assert "## Probability of improvement over each other configuration" in report


def test_each_other_row_is_held_against_the_plain_default_not_against_its_variants():
    """--improvement-over each: the default as it ships is X; its variant (an ablation) is one of the
    others, never an X of its own; with "best" the other is the best other algorithm only."""
    from types import SimpleNamespace

    from analysis.aggregate import improvement_pairs
    from copilot_ray.keys import EVAL_SUCCESS, VARIANT_TAG

    def config(name, algorithm, default, variant="", final=0.5):
        metric = SimpleNamespace(final=SimpleNamespace(point=final))
        trial = SimpleNamespace(tags={VARIANT_TAG: variant} if variant else {})
        return SimpleNamespace(
            label=name,
            algorithm=algorithm,
            is_copilot_default=default,
            metrics={EVAL_SUCCESS: metric},
            all_trials=[trial],
        )

    plain = config("copilot", "copilot", True)
    frozen = config("frozen", "copilot", True, variant="frozen_planner")
    sorb, her = config("sorb", "sorb", False, final=0.3), config("her", "her", False, final=0.2)
    configs = [plain, frozen, sorb, her]
    each = [(x.label, y.label) for x, y in improvement_pairs(configs, EVAL_SUCCESS, "each")]
    assert each == [("copilot", "frozen"), ("copilot", "sorb"), ("copilot", "her")]
    best = [(x.label, y.label) for x, y in improvement_pairs(configs, EVAL_SUCCESS, "best")]
    assert best == [("copilot", "sorb"), ("frozen", "sorb")]
    with pytest.raises(ValueError, match=r"over='all' is invalid"):
        improvement_pairs(configs, EVAL_SUCCESS, "all")


def test_whether_two_final_success_intervals_are_apart():
    from analysis import stats
    from analysis.tables import ci_apart

    five = stats.SeedSummary(5, 0.6, 0.5, 0.7)
    assert ci_apart(five, stats.SeedSummary(5, 0.3, 0.2, 0.4)) == "yes: 0.500 > 0.400"
    assert ci_apart(stats.SeedSummary(5, 0.3, 0.2, 0.4), five) == "below: 0.400 < 0.500"
    assert ci_apart(five, stats.SeedSummary(5, 0.45, 0.4, 0.55)).startswith("no: they overlap")
    # two seeds have a range, not a CI: nothing to tell, however far apart
    assert ci_apart(five, stats.SeedSummary(2, 0.05, 0.0, 0.1)) == "no CI (n = 5 and 2; a CI needs 5)"


def test_provenance_block_and_metrics_export(honest, store):
    from analysis.report import command_line

    report = (honest["out"] / "report.md").read_text()
    head = report.split("## Missing or incomplete")[0]
    assert head.index("## Provenance") < head.index("git commits")
    assert "git commits: 1111111aaaaaaa, 2222222bbbbbbb" in head
    # the code that read the store, beside the commits its runs came from
    assert re.search(r"report code: (commit [0-9a-f]{12}|not a git checkout)", head)
    assert "WARNING: the runs come from 2 different commits, not from one" in head
    assert "2 of 12 runs carry no git_commit tag" in head
    assert honest["uri"] in head and f"experiment: {HONEST}" in head
    assert f"runs:/{honest['parent']}/spec.resolved.yaml" in head
    assert f"command: {command_line(honest['argv'])}" in head
    # this install's interpreter, so that the command runs again as written
    assert command_line(honest["argv"]).startswith(
        f"{python()} -m analysis.report honest-sweep --tracking-uri"
    )
    html_head = (honest["out"] / "report.html").read_text().split("Missing or incomplete")[0]
    assert "Provenance" in html_head and "1111111aaaaaaa" in html_head
    # the single-commit store: its commit, no warning
    main_report = (store["out"] / "report.md").read_text()
    assert "git commit: abcdef1234567" in main_report and "WARNING" not in main_report
    # every run's metrics: copilot/, paths/ and the env steps, every logged row (stale ones too)
    csv = pd.read_csv(honest["out"] / "metrics.csv.gz")
    assert list(csv.columns) == ["run", "config", "seed", "metric", "env_steps", "value"]
    assert not csv.metric.str.startswith("timers/").any()
    rows = csv[(csv.run == "copilot-seed4") & (csv.metric == "copilot/eval/success")]
    assert list(rows.env_steps) == FRESH_STEPS and set(rows.config) == {"algorithm=copilot"}
    assert rows.value.iloc[-1] == pytest.approx(HONEST_SUCCESS["copilot"][4][-1])
    assert {"copilot/eval/fresh", "copilot/privileges/resets", ENV_STEPS} <= set(csv.metric)
    assert (store["out"] / "metrics.csv.gz").is_file()


# ------------------------------------------------------------------- configurations are not seeds
# Two sweeps with the same variant names on two layouts (as sweeps/choose_defaults.yaml runs them): the
# runs' config keys and axis tags agree, only their env config (param env.config.layout) tells them apart.
LAYOUT_SWEEPS = {"four_rooms": "four-rooms", "u_maze": "u-maze"}
LAYOUT_SUCCESS = {  # (layout, variant) -> each seed's success at STEPS[:3]
    ("four-rooms", "continue"): ([0.1, 0.2, 0.3], [0.1, 0.3, 0.5]),
    ("four-rooms", "abort_layer"): ([0.0, 0.1, 0.2], [0.0, 0.2, 0.4]),
    ("u-maze", "continue"): ([0.5, 0.7, 0.9], [0.4, 0.6, 0.8]),
    ("u-maze", "abort_layer"): ([0.3, 0.4, 0.5], [0.2, 0.3, 0.4]),
}


def _layout_store(root: Path, variants=("continue", "abort_layer")) -> str:
    """Experiment "layouts": one sweep run per layout, `variants` x seeds 0 and 1 in each; success,
    planned (= success), direct, return (= success: R = 1 on the maze) and the planner's path success."""
    import mlflow
    from mlflow.entities import Metric, Param

    from copilot_ray.keys import (
        ENV_PARAM,
        EVAL_RETURN,
        EVAL_SUCCESS,
        PATH_SUCCESS,
        PRIVILEGES_TAG,
        REACHED_PLANNED,
        VARIANT_TAG,
    )

    uri = f"sqlite:///{root / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("layouts", artifact_location=(root / "art").as_uri())
    now = int(time.time() * 1000)
    for sweep, layout in LAYOUT_SWEEPS.items():
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: sweep}).info.run_id
        for variant in variants:
            for seed, values in enumerate(LAYOUT_SUCCESS[(layout, variant)]):
                tags = {
                    PARENT_TAG: pid,
                    ROLE_TAG: ROLE_TRIAL,
                    SWEEP_TAG: sweep,
                    CONFIG_KEY_TAG: f"variant={variant}",  # the same keys in both sweeps
                    ALGORITHM_TAG: "copilot",
                    ENV_TAG: "maze-point",
                    K_TAG: "5",
                    VARIANT_TAG: variant,
                    PRIVILEGES_TAG: "collision_checks",
                    SEED_TAG: str(seed),
                }
                rid = client.create_run(
                    exp_id, run_name=f"variant={variant}-seed{seed}", tags=tags
                ).info.run_id
                params = {ENV_PARAM: "maze-point", "env.config.layout": layout, "seed": str(seed)}
                params["after_failure"] = variant
                steps = STEPS[:3]
                ms = [Metric(ENV_STEPS, s, now, s) for s in steps]
                for key in (EVAL_SUCCESS, SUCCESS_PLANNED, EVAL_RETURN, REACHED_PLANNED, PATH_SUCCESS):
                    ms += [Metric(key, v, now, s) for s, v in zip(steps, values, strict=True)]
                ms += [Metric(SUCCESS_DIRECT, v / 2, now, s) for s, v in zip(steps, values, strict=True)]
                client.log_batch(rid, metrics=ms, params=[Param(k, v) for k, v in params.items()])
                client.set_terminated(rid, "FINISHED")
    return uri


@pytest.fixture(scope="module")
def layouts(tmp_path_factory):
    root = tmp_path_factory.mktemp("layouts")
    uri = _layout_store(root)
    out = root / "report"
    rc = main(["layouts", "--tracking-uri", uri, "--parent-run", "all", "--out", str(out), "--no-log"])
    return {"uri": uri, "out": out, "rc": rc, "frame": pd.read_csv(out / "summary.csv")}


def test_two_configurations_of_two_seeds_each_show_n_2(tmp_path):
    """The issue's case: two configurations (one variant on two layouts) x two seeds; the config keys and
    axis tags agree, the env config does not. Each configuration has n = 2, never one with n = 4."""
    from analysis.aggregate import summarise
    from analysis.load import load_sweep

    uri = _layout_store(tmp_path, variants=("continue",))
    out = tmp_path / "report"
    assert main(["layouts", "--tracking-uri", uri, "--parent-run", "all", "--out", str(out), "--no-log"]) == 0
    frame = pd.read_csv(out / "summary.csv").set_index("configuration")
    assert sorted(frame.index) == ["layout=four-rooms", "layout=u-maze"]
    assert list(frame["n_seeds"]) == [2, 2]
    four, u = (LAYOUT_SUCCESS[(layout, "continue")] for layout in ("four-rooms", "u-maze"))
    assert frame.loc["layout=four-rooms", "success_final"] == pytest.approx(np.mean([v[-1] for v in four]))
    assert frame.loc["layout=u-maze", "success_final"] == pytest.approx(np.mean([v[-1] for v in u]))
    report = (out / "report.md").read_text()
    assert "configurations: 2; varying: layout" in report
    assert "| layout=four-rooms | 2 |" in report and "| layout=u-maze | 2 |" in report
    assert "range over 4 seeds" not in report
    configs, _ = summarise(load_sweep(uri, "layouts", "all"), reps=100)
    assert [(c.label, c.n_seeds) for c in configs] == [("layout=four-rooms", 2), ("layout=u-maze", 2)]


def test_env_config_is_an_axis(layouts):
    """layout x variant x 2 seeds: four configurations labelled by both, n = 2 each; the planners' table
    keeps them apart too."""
    from analysis.load import Sweep, load_sweep

    assert layouts["rc"] == 0
    sweep = load_sweep(layouts["uri"], "layouts", "all")
    assert sweep.axes() == ["env.config.layout", "variant"]
    frame = layouts["frame"].set_index("configuration")
    expected = {f"layout={layout}, variant={variant}" for layout, variant in LAYOUT_SUCCESS}
    assert set(frame.index) == expected and set(frame["n_seeds"]) == {2}
    row = frame.loc["layout=u-maze, variant=abort_layer"]
    assert row["success_final"] == pytest.approx(np.mean([0.5, 0.4]))
    planners = pd.read_csv(layouts["out"] / "planners.csv")
    assert len(planners) == 4 and set(planners["n_seeds"]) == {2}
    assert set(planners["env"]) == {"maze-point, layout=four-rooms", "maze-point, layout=u-maze"}
    assert set(planners["method"]) == {"copilot (variant=continue)", "copilot (variant=abort_layer)"}
    # a layout file the sweep resolved to a path is named by its file
    trial = sweep.trials[0]
    trial.params["env.config.layout"] = "/somewhere/mazes/spiral.txt"
    assert Sweep("u", "e", "1", None, "s", sweep.trials).axes() == ["env.config.layout", "variant"]
    from analysis.aggregate import config_label

    assert config_label(trial, ["env.config.layout", "variant"]).startswith("layout=spiral, variant=")


def test_one_configuration_in_two_sweeps_is_split_not_pooled():
    """Same config key, same params, seeds 0 and 1 in each of two sweeps: a seed repeats, so the runs are
    two configurations (by sweep), never 'n = 4' with each seed twice."""
    from analysis.aggregate import config_label
    from analysis.load import Sweep, Trial, configurations

    def trial(sweep, parent, seed):
        tags = {ALGORITHM_TAG: "copilot", SWEEP_TAG: sweep, PARENT_TAG: parent, SEED_TAG: seed}
        return Trial(f"{sweep}{seed}", "r", "FINISHED", "default", seed, tags)

    trials = [trial("a", "p1", "0"), trial("a", "p1", "1"), trial("b", "p2", "0"), trial("b", "p2", "1")]
    groups = list(configurations(trials).values())
    assert [[t.run_id for t in g] for g in groups] == [["a0", "a1"], ["b0", "b1"]]
    sweep = Sweep("u", "e", "1", None, "s", trials)
    assert sweep.axes() == ["config_key", "sweep"]
    assert config_label(trials[2], sweep.axes()) == "default, sweep=b"
    # seeds 0, 1 and 2, 3: no seed repeats, one configuration of four seeds
    trials[2].seed, trials[3].seed = "2", "3"
    assert len(configurations(trials)) == 1


def test_two_presets_run_under_one_config_key_in_joined_sweeps_are_labelled_by_preset():
    """A comparison joined with a rerun (each method's sweep of its own, every config key "default"): the
    labels must say which CO-PILOT row is the paper-literal preset, not only which sweep it came from."""
    from analysis.aggregate import config_label
    from analysis.load import Sweep, Trial

    def trial(algorithm, preset, sweep, k):
        tags = {ALGORITHM_TAG: algorithm, PRESET_TAG: preset, SWEEP_TAG: sweep, K_TAG: k, SEED_TAG: "0"}
        return Trial(sweep, "r", "FINISHED", "default", "0", tags)

    trials = [
        trial("copilot", "default", "fair_maze_copilot", "5"),
        trial("copilot", "paper_literal", "fair_maze_paper_literal", "5"),
        trial("copilot", "default", "fair_maze_leaky_copilot", "5"),
        trial("her", "", "fair_maze_her", ""),
    ]
    sweep = Sweep("u", "e", "1", None, "s", trials)
    # K differs between algorithms, not within one: it does not join the labels
    assert sweep.axes() == [ALGORITHM_TAG, PRESET_TAG, "config_key", "sweep"]
    assert config_label(trials[1], sweep.axes()) == (
        "algorithm=copilot, preset=paper_literal, default, sweep=fair_maze_paper_literal"
    )


def test_headline_table_is_compact_and_success_is_shown_once(layouts):
    """The headline: configuration, seeds, privileges, env steps and counts, final test success, its AUC
    and the agent alone (ten columns: CO-PILOT plans); the per-metric details in a second table, where
    CO-PILOT's success (= planned) is one row, not two, and its direct row is the headline's agent alone."""
    md = (layouts["out"] / "summary.md").read_text()
    headline, details = md.split("\n\n")
    header = headline.splitlines()[0]
    assert header == (
        "| configuration | seeds | privileges | env steps | collision checks | resets | map queries "
        "| final test success | test success AUC | final test success, agent alone |"
    )
    assert "planned" not in headline and "steps to" not in headline
    rows = [r for r in details.splitlines()[2:] if r.startswith("| layout=u-maze, variant=continue |")]
    assert [r.split(" | ")[1] for r in rows] == ["success = planned", "direct"]
    (row,) = [r for r in headline.splitlines()[2:] if r.startswith("| layout=u-maze, variant=continue |")]
    assert row.rstrip(" |").split(" | ")[-1] == rows[1].split(" | ")[2]  # the direct row's final
    assert "| env steps to 0.5 (seeds) |" in details.splitlines()[0]


def test_report_html_table_has_readable_headers_and_fits(layouts):
    html = (layouts["out"] / "report.html").read_text()
    assert "<th>final test success</th>" in html and "<th>env steps to 0.5 (seeds)</th>" in html
    assert "success_final" not in html and "n_seeds" not in html  # no raw CSV column names
    assert "overflow-wrap:break-word" in html and "width:100%" in html


def test_maze_return_is_left_out_and_the_report_says_why(layouts):
    """On the maze the return (R = 1) repeats a rate the report already has: no figure, a line why, and
    no 'paper Fig. 2d' anywhere."""
    out = layouts["out"]
    assert not (out / "return_vs_env_steps.png").exists()
    report = (out / "report.md").read_text()
    left = report.split("## Left out of the figures")[1].split("## Summary")[0]
    assert "return_vs_env_steps.png leaves out every configuration" in left
    assert "it equals reached_planned in every run (task reward R = 1)" in left
    assert "mastered_vs_env_steps.png: no run logged copilot/eval/mastered" in left
    # no RRT* here: the planners' figure has no ratio rows, and says so
    assert "planners_paths.png: no 'path length / RRT*'s (tasks both solved)' row" in left
    assert "Fig. 2d" not in report  # the maze is not the Ant maze
    assert "Fig. 4" not in report  # no RRT*, so not the paper's planners figure


def test_figures_without_data_are_not_drawn(tmp_path):
    """A store of the common success only (no planned / direct): no planned/direct figures with empty
    panels, and the report names them."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_SUCCESS

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("plain", artifact_location=(tmp_path / "art").as_uri())
    now = int(time.time() * 1000)
    for seed in ("0", "1"):
        tags = {ROLE_TAG: ROLE_TRIAL, CONFIG_KEY_TAG: "default", SEED_TAG: seed, ALGORITHM_TAG: "sac"}
        rid = client.create_run(exp_id, tags=tags).info.run_id
        client.log_batch(rid, metrics=[Metric(EVAL_SUCCESS, 0.1 * i, now, s) for i, s in enumerate(STEPS)])
        client.set_terminated(rid, "FINISHED")
    out = tmp_path / "report"
    assert main(["plain", "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    assert not list(out.glob("*.png"))
    report = (out / "report.md").read_text()
    assert (
        "success_vs_env_steps.png: not drawn: no configuration logged success_planned / success_direct."
        in report
    )
    assert "final_success.png: not drawn" in report and "return_vs_env_steps.png: no run logged" in report


def test_a_search_is_reported_on_its_validation_tasks_and_a_comparison_on_its_test_tasks(tmp_path, capsys):
    """A report on sweeps that searched (parent param searcher = optuna) shows the validation figures, and
    nothing measured on the test tasks (tables, export); a grid sweep's report shows the test figures and
    says, on the console and the page, that the sweep's own lines showed the validation tasks' of the same
    runs; --tasks overrides either way."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_FRESH, EVAL_SUCCESS, PATH_SUCCESS, validation_key

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    now = int(time.time() * 1000)
    test_values, validation_values = [0.91, 0.93, 0.97], [0.11, 0.13, 0.17]
    for experiment, searcher in (("search", "optuna"), ("comparison", "grid")):
        exp_id = client.create_experiment(experiment, artifact_location=(tmp_path / experiment).as_uri())
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: experiment}).info.run_id
        client.log_param(pid, "searcher", searcher)
        for seed in ("0", "1"):
            tags = {PARENT_TAG: pid, ROLE_TAG: ROLE_TRIAL, SWEEP_TAG: experiment, SEED_TAG: seed}
            tags |= {CONFIG_KEY_TAG: "default", ALGORITHM_TAG: "copilot", ENV_TAG: "maze-point"}
            rid = client.create_run(exp_id, tags=tags).info.run_id
            ms = [Metric(EVAL_FRESH, 1.0, now, s) for s in STEPS[:3]]
            ms += [Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(STEPS, test_values, strict=False)]
            ms += [
                Metric(validation_key(EVAL_SUCCESS), v, now, s)
                for s, v in zip(STEPS, validation_values, strict=False)
            ]
            ms += [Metric(ENV_STEPS, s, now, s) for s in STEPS[:3]]
            ms += [Metric(PATH_SUCCESS, 0.5, now, s) for s in STEPS[:3]]  # the planner's, on test tasks
            client.log_batch(rid, metrics=ms)
            client.set_terminated(rid, "FINISHED")

    def report(experiment, *flags):
        out = tmp_path / f"{experiment}{''.join(flags)}"
        assert main([experiment, "--tracking-uri", uri, "--out", str(out), "--no-log", *flags]) == 0
        summary = (out / "summary.md").read_text()
        return summary, pd.read_csv(out / "metrics.csv.gz"), (out / "report.md").read_text()

    summary, csv, text = report("search")
    assert "| final validation success | validation success AUC |" in summary
    assert "mean 0.170" in summary and "0.97" not in summary and "Validation tasks only" in text
    assert "every sweep here is a search" in text
    assert not csv.metric.eq(EVAL_SUCCESS).any() and csv.metric.eq(validation_key(EVAL_SUCCESS)).any()
    assert not csv.metric.eq(PATH_SUCCESS).any() and not (tmp_path / "search" / "planners.md").exists()
    assert (
        "No tree figure in a validation report: sub-goal tree snapshots (copilot_trees/*.npz) are drawn on test tasks."
        in text
    )
    capsys.readouterr()
    summary, csv, text = report("comparison")
    assert "| final test success | test success AUC |" in summary and "mean 0.970" in summary
    beside = (
        "the sweep's summary table and progress lines show the validation tasks' figures of the same runs"
    )
    assert f"Test tasks only ({beside})" in text and csv.metric.eq(EVAL_SUCCESS).any()
    assert f"tasks: test ({beside})" in capsys.readouterr().out
    assert csv.metric.eq(PATH_SUCCESS).any() and (tmp_path / "comparison" / "planners.md").exists()
    summary, _, _ = report("search", "--tasks", "test")
    assert "mean 0.970" in summary
    summary, _, text = report("comparison", "--tasks", "validation")
    assert "mean 0.170" in summary and "0.97" not in summary
    # a grid read on validation tasks by request is no search, and its report must not say it is one
    assert "asked for with --tasks validation" in text and "every sweep here is a search" not in text


def test_a_crowded_figure_keeps_every_methods_best_configuration():
    """14 configurations, 12 drawn: the best of each method (algorithm and sweep) is kept even when
    twelve of another method score higher; the rest by final success."""
    from types import SimpleNamespace

    from analysis.figures import MAX_CURVES, _select
    from copilot_ray.keys import EVAL_SUCCESS

    def config(algorithm, sweep, final):
        m = SimpleNamespace(final=SimpleNamespace(point=final))
        trial = SimpleNamespace(tags={SWEEP_TAG: sweep})
        return SimpleNamespace(algorithm=algorithm, all_trials=[trial], metrics={EVAL_SUCCESS: m})

    her = [config("her", "tune_her", 0.5 + i / 100) for i in range(12)]
    copilot = [config("copilot", "tune_copilot", 0.01), config("copilot", "tune_paper_literal", 0.0)]
    shown, dropped = _select(her + copilot)
    assert MAX_CURVES == 12 and dropped == 2 and len(shown) == 12
    assert copilot[0] in shown and copilot[1] in shown
    assert her[0] not in shown and her[1] not in shown  # the two lowest HER configurations make room


def test_a_short_configuration_above_the_bar_on_validation_is_told_to_get_more_seeds(tmp_path, capsys):
    """The comparison's rule (5 seeds for a method above 0.1, 2 may do below) is read off the validation
    tasks: a 2-seed configuration at 0.30 validation success is told which seeds to add, one at 0.05 that
    its two are the rule's, whatever their test figures say; a validation report gives no such note. A
    configuration short because a run FAILED is told it misses the rule, and no seed is offered instead."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_FRESH, EVAL_SUCCESS, validation_key

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    now = int(time.time() * 1000)
    exp_id = client.create_experiment("comparison", artifact_location=(tmp_path / "a").as_uri())
    pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "comparison"}).info.run_id
    client.log_param(pid, "searcher", "grid")
    # (algorithm, test success, validation success): sac is low on test but above the bar on validation
    seeds = {"sac": ("0", "1"), "ppo": ("0", "1"), "her": ("1", "2", "3", "4", "5")}
    for algorithm, test, validation in (("sac", 0.02, 0.30), ("ppo", 0.40, 0.05), ("her", 0.2, 0.4)):
        for seed in seeds[algorithm]:
            tags = {PARENT_TAG: pid, ROLE_TAG: ROLE_TRIAL, SWEEP_TAG: "comparison", SEED_TAG: seed}
            tags |= {CONFIG_KEY_TAG: algorithm, ALGORITHM_TAG: algorithm, ENV_TAG: "maze-point"}
            rid = client.create_run(exp_id, tags=tags).info.run_id
            ms = [Metric(EVAL_FRESH, 1.0, now, s) for s in STEPS[:3]]
            ms += [Metric(EVAL_SUCCESS, test, now, s) for s in STEPS[:3]]
            ms += [Metric(validation_key(EVAL_SUCCESS), validation, now, s) for s in STEPS[:3]]
            ms += [Metric(ENV_STEPS, s, now, s) for s in STEPS[:3]]
            client.log_batch(rid, metrics=ms)
            client.set_terminated(rid, "FAILED" if (algorithm, seed) == ("her", "3") else "FINISHED")

    out = tmp_path / "test_report"
    assert main(["comparison", "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    printed = capsys.readouterr().out
    notes = sorted(line for line in printed.splitlines() if "final validation success" in line)
    assert len(notes) == 2 and notes[1].startswith("note: algorithm=sac:") and "0.30, above 0.1" in notes[1]
    # below the bar the few seeds are the rule's, said so beside "lacks seeds"
    assert notes[0].startswith("note: algorithm=ppo: 2 seed(s), within") and "0.05, not above 0.1" in notes[0]
    # each note names the metric it read: the validation twin, not the test metric
    assert all(f"final validation success ({validation_key(EVAL_SUCCESS)}) is" in n for n in notes)
    notes = notes[1:]
    # what to do: the seeds not used yet, in a part of their own (a started part keeps its seeds)
    assert "Run seeds [2, 3, 4] as a part of their own" in notes[0] and "`seeds: [2, 3, 4]`" in notes[0]
    assert "algorithm=sac: 2 seed(s)" in (out / "report.md").read_text()
    assert "algorithm=ppo: 2 seed(s), within the comparison's seed rule" in (out / "report.md").read_text()
    (failed,) = [line for line in printed.splitlines() if line.startswith("note: algorithm=her:")]
    assert "4 seed(s) behind its figures; seed(s) 3 ended unfinished" in failed
    assert "does not meet the comparison's 5-seed rule" in failed and "Run seeds" not in failed
    out = tmp_path / "validation_report"
    assert (
        main(["comparison", "--tracking-uri", uri, "--out", str(out), "--no-log", "--tasks", "validation"])
        == 0
    )
    assert "final validation success (" not in capsys.readouterr().out


# ---------------------------------------------------------------- the stated target and the diagnostics
def _target_sweep(copilot_finals, her_finals, budget=2000.0):
    """CO-PILOT's default (K = 2, logging diagnostics) and HER, evaluated at 1000 and 3000 env steps
    with a budget of 2000: every figure is read halfway between, at the budget."""
    from analysis.load import Sweep, Trial
    from copilot_ray.keys import (
        AGENT_SUBTASK_SUCCESS_LAYER,
        DIAG_SEGMENT_LENGTH_LAYER,
        DIAG_SUCCESS_AFTER_FAILED,
        EVAL_SUCCESS,
        PRESET_TAG,
        SUCCESS_DIRECT,
    )

    steps = np.array([1000.0, 3000.0])
    trials = []
    for algorithm, finals in (("copilot", copilot_finals), ("her", her_finals)):
        for seed, final in enumerate(finals):
            tags = {
                ALGORITHM_TAG: algorithm,
                PRESET_TAG: "default",
                SEED_TAG: str(seed),
                ENV_TAG: "maze-point",
            }
            t = Trial(f"{algorithm}{seed}", "r", "FINISHED", "default", str(seed), tags, budget=budget)
            t.curves[EVAL_SUCCESS] = (steps, np.array([0.0, 2 * final]))  # final at 2000 env steps
            if algorithm == "copilot":
                t.curves[SUCCESS_DIRECT] = (steps, np.array([0.0, 0.2]))  # 0.1 at the budget
                t.curves[DIAG_SEGMENT_LENGTH_LAYER + "2"] = (steps, np.array([1.0, 1.0]))  # depth K = 2
                t.curves[AGENT_SUBTASK_SUCCESS_LAYER + "2"] = (steps, np.array([0.2, 0.4 + 0.2 * seed]))
                t.curves[DIAG_SUCCESS_AFTER_FAILED] = (steps, np.array([0.1, 0.1]))
            trials.append(t)
    return Sweep("u", "e", "1", None, "s", trials)


def test_target_verdict_says_how_far_each_part_is_from_the_claim():
    from analysis.aggregate import summarise
    from analysis.target import verdict

    five = [0.40, 0.45, 0.50, 0.55, 0.60]  # IQM 0.5 (the middle three)
    configs, _ = summarise(_target_sweep(five, [0.1, 0.12, 0.14, 0.16, 0.18]), reps=200)
    lines = verdict(configs, 0.6, "test")
    assert lines[0].startswith("algorithm=copilot: final test success IQM 0.500 [95% CI ")
    assert lines[0].endswith("target 0.6: NOT met, the IQM is 0.100 short of it (83% of the target).")
    cp = configs[0].metrics["copilot/eval/success"].final
    her = configs[1].metrics["copilot/eval/success"].final
    assert lines[1].startswith("against the best other method, algorithm=her (IQM 0.140 ")
    assert lines[1].endswith(
        f"met: the lower end of its CI, {cp.low:.3f}, is {cp.low - her.high:.3f} above their upper end, "
        f"{her.high:.3f}."
    )
    assert (
        lines[2]
        == "algorithm=copilot's agent alone (no plan): final test success IQM 0.100 [95% CI 0.100, 0.100]."
    )
    assert verdict(configs, 0.45, "test")[0].endswith("target 0.45: met, the IQM is 0.050 above it.")
    # overlapping intervals: the shortfall is the gap between the two ends
    configs, _ = summarise(_target_sweep(five, [0.40, 0.45, 0.50, 0.55, 0.60]), reps=200)
    cp, her = (c.metrics["copilot/eval/success"].final for c in configs)
    assert verdict(configs, 0.6, "test")[1].endswith(
        f"NOT met: the lower end of its CI, {cp.low:.3f}, is {her.high - cp.low:.3f} short of their upper "
        f"end, {her.high:.3f}."
    )
    # two seeds: neither an IQM nor a CI to judge, and the verdict says so instead of judging a mean
    configs, _ = summarise(_target_sweep([0.2, 0.3], [0.1, 0.2]), reps=200)
    lines = verdict(configs, 0.6, "test")
    assert lines[0].endswith(
        "target 0.6 (an IQM over >= 5 seeds): cannot be judged on 2 seed(s); their mean is 0.350 short of it "
        "(42% of the target)."
    )
    assert lines[1].endswith("CIs apart cannot be judged (n = 2 and 2; a CI needs 5).")


def test_diagnostics_table_reads_each_seed_at_the_budget():
    from analysis.aggregate import summarise
    from analysis.target import diagnostics_table

    configs, _ = summarise(_target_sweep([0.2, 0.3], [0.1, 0.2]), reps=200)
    table = diagnostics_table(configs)
    # only the figures some run logged; HER logged no tree diagnostics, so it has no row
    assert table.header == [
        "configuration",
        "agent alone (no plan)",
        "training sub-task success, layer K",
        "after a missed one",
    ]
    # sub-task success at 2000 env steps: seed 0 (0.2 + 0.4) / 2 = 0.3, seed 1 (0.2 + 0.6) / 2 = 0.4
    assert table.rows == [
        ["algorithm=copilot", "0.10 (0.10-0.10, n = 2)", "0.35 (0.30-0.40, n = 2)", "0.10 (0.10-0.10, n = 2)"]
    ]


def test_report_target_flag_is_checked_and_shown(honest, tmp_path, capsys):
    out = tmp_path / "report"
    with pytest.raises(SystemExit) as e:
        main([HONEST, "--tracking-uri", honest["uri"], "--out", str(out), "--no-log", "--target", "1.5"])
    assert e.value.code == 2 and "--target: 1.5 is not a success rate in (0, 1]" in capsys.readouterr().err
    assert not out.exists()
    assert (
        main([HONEST, "--tracking-uri", honest["uri"], "--out", str(out), "--no-log", "--target", "0.9"]) == 0
    )
    section = (
        (out / "report.md").read_text().split("## Target: final test success >= 0.9")[1].split("\n## ")[0]
    )
    assert "- algorithm=copilot: final test success IQM 0.800 [95% CI " in section
    assert "target 0.9: NOT met, the IQM is 0.100 short of it (89% of the target)." in section
    # without the flag there is no verdict (the honest store logs no tree diagnostics: no table either)
    assert "## Target" not in (honest["out"] / "report.md").read_text()
    assert "## Diagnostics at the budget" not in (honest["out"] / "report.md").read_text()


def test_a_method_rerun_in_its_own_experiment_joins_the_comparison_with_also_experiment(tmp_path, capsys):
    """CO-PILOT rerun at a newer commit in experiment 'rerun' of its own store; the comparison's PPO in
    experiment 'comparison' of another: --also-experiment puts them in one report, with the improvement
    of CO-PILOT over PPO, both commits and the joined experiment named; without it the other store's
    experiment is not found, and the flag without --also-from is refused."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_SUCCESS, PRESET_TAG

    now = int(time.time() * 1000)
    runs = {
        "rerun": ("copilot", "newcommit", [0.6, 0.7, 0.8, 0.7, 0.9]),
        "comparison": ("ppo", "oldcommit", [0.1, 0.2, 0.1, 0.3, 0.2]),
    }
    uris = {}
    for experiment, (algorithm, commit, finals) in runs.items():
        uri = uris[experiment] = f"sqlite:///{tmp_path / experiment}.db"
        client = mlflow.MlflowClient(uri)
        exp_id = client.create_experiment(experiment, artifact_location=(tmp_path / experiment).as_uri())
        pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: algorithm}).info.run_id
        for seed, final in enumerate(finals):
            tags = {
                PARENT_TAG: pid,
                ROLE_TAG: ROLE_TRIAL,
                SWEEP_TAG: algorithm,
                CONFIG_KEY_TAG: "default",
                ALGORITHM_TAG: algorithm,
                ENV_TAG: "maze-point",
                PRESET_TAG: "default",
                SEED_TAG: str(seed),
                GIT_COMMIT_TAG: commit,
            }
            rid = client.create_run(exp_id, tags=tags).info.run_id
            values = [final / 2, final]
            client.log_batch(
                rid, metrics=[Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(STEPS[:2], values, strict=True)]
            )
            client.set_terminated(rid, "FINISHED")
    out = tmp_path / "report"
    argv = [
        "rerun",
        "--tracking-uri",
        uris["rerun"],
        "--out",
        str(out),
        "--no-log",
        "--also-from",
        uris["comparison"],
    ]
    assert main([*argv, "--also-experiment", "comparison"]) == 0
    frame = pd.read_csv(out / "summary.csv").set_index("configuration")
    assert frame.loc["algorithm=copilot", "success_final"] == pytest.approx(stats.iqm(runs["rerun"][2]))
    assert frame.loc["algorithm=ppo", "success_final"] == pytest.approx(stats.iqm(runs["comparison"][2]))
    imp = pd.read_csv(out / "improvement.csv")
    assert len(imp) == 1 and imp.loc[0, "p_final"] == 1.0  # every CO-PILOT seed above every PPO seed
    report = (out / "report.md").read_text()
    assert (
        "git commits: newcommit, oldcommit" in report
        and "WARNING: the runs come from 2 different commits" in report
    )
    assert "experiment: rerun (id 1) + experiment comparison (--also-experiment)" in report
    capsys.readouterr()
    assert main(argv) == 2  # 'rerun' is not in the comparison's store
    assert "experiment 'rerun' not found" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["rerun", "--tracking-uri", uris["rerun"], "--also-experiment", "comparison"])
    assert exit_.value.code == 2
    assert "--also-experiment comparison" in capsys.readouterr().err


def test_a_one_seed_look_gets_a_short_report_and_flat_panels_are_named_not_drawn(tmp_path, capsys):
    """A demo (one seed per configuration) is a look at its runs, not a comparison: a short summary, no
    seed-rule notes, no probability of improvement. Its open maze leaves some figures without signal:
    the diagnostics' flat panels and the paths' flat rows are named, not drawn."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import EVAL_FRESH, EVAL_SUCCESS, PATH_SUCCESS, validation_key

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    now = int(time.time() * 1000)
    exp_id = client.create_experiment("demo", artifact_location=(tmp_path / "a").as_uri())
    pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "demo"}).info.run_id
    for k, rises in ((1, [0.2, 0.5, 0.9, 1.0]), (2, [0.4, 0.8, 1.0, 1.0])):
        key = f"tree_depth={k}"
        tags = {PARENT_TAG: pid, ROLE_TAG: ROLE_TRIAL, SWEEP_TAG: "demo", SEED_TAG: "0", K_TAG: str(k)}
        tags |= {CONFIG_KEY_TAG: key, ALGORITHM_TAG: "copilot", ENV_TAG: "maze-point"}
        rid = client.create_run(exp_id, run_name=key, tags=tags).info.run_id
        curves = {
            EVAL_FRESH: [1.0] * 4,
            EVAL_SUCCESS: rises,
            SUCCESS_PLANNED: rises,
            SUCCESS_DIRECT: rises,
            validation_key(EVAL_SUCCESS): rises,
            ENV_STEPS: STEPS,
            PATH_SUCCESS: [1.0] * 4,  # every plan reaches the goal in an open maze: a flat row
            DIAG_SUBGOAL_IN_OBSTACLE_LAYER + str(k): [0.0] * 4,  # no walls: a flat panel
            DIAG_SEGMENT_LENGTH_LAYER + str(k): [0.3, 0.2, 0.15, 0.1],  # (the run's tree depth)
            DIAG_SEGMENT_UNREACHABLE_LAYER + str(k): [0.5, 0.3, 0.1, 0.0],  # a panel that changes
        }
        ms = [Metric(name, v, now, s) for name, vs in curves.items() for s, v in zip(STEPS, vs, strict=True)]
        client.log_batch(rid, metrics=ms)
        client.set_terminated(rid, "FINISHED")

    out = tmp_path / "report"
    assert main(["demo", "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    printed = capsys.readouterr().out
    text = (out / "report.md").read_text()
    summary = text.split("## Summary")[1].split("|")[0]
    assert "One seed per configuration: a look at how the runs went, not a comparison" in summary
    assert "IQM" not in summary and len(summary.split()) < 120  # not the comparison's 300-word paragraph
    assert "final validation success" not in printed + text  # no seed-rule notes
    assert "Probability of improvement" not in text
    assert (
        "diagnostics.png: panels left out (flat, no signal): sub-goals inside obstacles (every line at 0)"
        in text
    )
    assert (out / "diagnostics.png").is_file()  # the segment-length panel still changes: drawn
    assert (
        "planners_paths.png: no 'success (collision-free path to the goal)' row: every method's curve is flat at 1"
        in text
    )
    assert not (out / "planners_paths.png").exists()


def test_the_headline_shows_the_agent_alone_beside_a_method_that_plans():
    """CO-PILOT's agent alone is its direct success; HER, which has no plan, reports its agent's success
    as its success, said so instead of the figure twice; a method with no direct figure gets a dash."""
    from analysis.aggregate import follows_plan
    from analysis.tables import headline_table

    def row(name, success, direct):
        r = {"configuration": name, "n_seeds": 5, "privileges": "none", "env_steps": 2e5}
        r |= {"collision_checks": 0.0, "resets": 0.0, "map_queries": 0.0, "planned_n_seeds": 0}
        for short, value in (("success", success), ("direct", direct)):
            n = 0 if value is None else 5
            value = math.nan if value is None else value
            for what in ("final", "auc"):
                r |= {f"{short}_{what}": value, f"{short}_{what}_low": value - 0.1}
                r |= {f"{short}_{what}_high": value + 0.1, f"{short}_{what}_n_seeds": n}
            r[f"{short}_n_seeds"] = n
        return r

    frame = pd.DataFrame([row("copilot", 0.7, 0.3), row("her", 0.2, 0.2), row("rrt_star", 0.9, None)])
    table = headline_table(frame)
    assert table.header[-1] == "final test success, agent alone"
    assert [r[-1] for r in table.rows] == [
        "IQM 0.300 [95% CI 0.200, 0.400]",
        "= its success (no plan)",
        "-",
    ]
    # no method plans: no such column
    assert headline_table(frame.iloc[1:2]).header[-1] == "test success AUC"

    # Known algorithms say themselves whether they plan: an RRT* curriculum whose plans and agent alone
    # end level (as a stage-1 trial did, 0.046 both) still plans, and HER still does not.
    level = pd.DataFrame([row("rrt_curriculum", 0.2, 0.2), row("her", 0.2, 0.2)])
    level["follows_plan"] = [follows_plan("rrt_curriculum"), follows_plan("her")]
    assert [r[-1] for r in headline_table(level).rows] == [
        "IQM 0.200 [95% CI 0.100, 0.300]",
        "= its success (no plan)",
    ]
    assert (follows_plan("copilot"), follows_plan("sorb_map"), follows_plan("sac")) == (True, True, False)
    assert follows_plan("not_an_algorithm") is None


def test_curves_and_collision_checks_end_at_the_budget():
    """Runs evaluated at 1000 and 3000 env steps with a budget of 2000 (an iteration past it): the curves
    are drawn to the budget, not past it, and the collision checks shown are those spent by the budget."""
    from analysis.aggregate import summarise
    from copilot_ray.keys import EVAL_SUCCESS, PRIVILEGE_COLLISION_CHECKS

    sweep = _target_sweep([0.4, 0.45, 0.5, 0.55, 0.6], [0.1, 0.12, 0.14, 0.16, 0.18])
    for t in sweep.trials:
        if t.tags[ALGORITHM_TAG] == "copilot":
            t.curves[PRIVILEGE_COLLISION_CHECKS] = (np.array([1000.0, 3000.0]), np.array([100.0, 300.0]))
            t.latest[PRIVILEGE_COLLISION_CHECKS] = 300.0
    configs, _ = summarise(sweep, reps=50)
    copilot = next(c for c in configs if c.algorithm == "copilot")
    assert copilot.metrics[EVAL_SUCCESS].curve.grid[-1] == 2000.0
    assert copilot.metrics[EVAL_SUCCESS].curve.center[-1] == pytest.approx(0.5)  # the final, at the budget
    assert copilot.privilege_counts[PRIVILEGE_COLLISION_CHECKS] == pytest.approx(200.0)


def test_a_plan_of_its_own_is_what_the_algorithm_declares():
    """The diagnostics' plan panels: SoRB with the map plans even where its plans and its agent alone
    ended level at every evaluation (both 0), HER does not; an algorithm this checkout lacks is judged by
    its curves, as before."""
    from analysis.load import Trial
    from analysis.run_figures import plans_of_its_own
    from copilot_ray.keys import ALGORITHM_TAG, SUCCESS_DIRECT, SUCCESS_PLANNED

    steps, zeros, some = np.array([1e4, 2e4]), np.zeros(2), np.array([0.1, 0.3])

    def trial(algorithm, planned, direct):
        curves = {SUCCESS_PLANNED: (steps, planned), SUCCESS_DIRECT: (steps, direct)}
        return Trial("r", "r", "FINISHED", "k", "0", {ALGORITHM_TAG: algorithm}, curves)

    assert plans_of_its_own(trial("sorb_map", zeros, zeros))
    assert not plans_of_its_own(trial("her", zeros, zeros))
    assert plans_of_its_own(trial("retired_method", some, zeros))
    assert not plans_of_its_own(trial("retired_method", zeros, zeros))


# ---------------------------------------------------------------------------------------------- issue 67/68
# --final-evaluations K, --reference CONFIG, the 99 % reading, --paired, counts read with the final


def _depth_sweep(curves_by_k, budget=3000.0, steps=(1000.0, 2000.0, 3000.0, 3100.0), statuses=None):
    """In memory: CO-PILOT configurations K = k (config key tree_depth=k), seeds 1..n, evaluated at
    `steps` (the last one past the budget), each seed's success curve given."""
    from analysis.load import Sweep, Trial
    from copilot_ray.keys import EVAL_SUCCESS

    trials = []
    for k, seeds in curves_by_k.items():
        for i, values in enumerate(seeds):
            seed = str(i + 1)
            tags = {ALGORITHM_TAG: "copilot", K_TAG: str(k), SEED_TAG: seed, ENV_TAG: "maze-point"}
            status = (statuses or {}).get((k, seed), "FINISHED")
            t = Trial(f"K{k}s{seed}", f"K{k}s{seed}", status, f"tree_depth={k}", seed, tags, budget=budget)
            if values is not None:
                t.curves[EVAL_SUCCESS] = (np.array(steps[: len(values)]), np.array(values, dtype=float))
            trials.append(t)
    return Sweep("sqlite:///nowhere.db", "depth", "1", None, "depth", trials)


def test_final_evaluations_is_the_mean_of_the_last_k_at_or_before_the_budget():
    """Budget 3000, evaluations at 1000, 2000, 3000 and 3100 (past it): with K = 2 a seed's final is the
    mean of its 2000 and 3000 evaluations, read at 3000 (never the one at 3100); a seed with one
    evaluation at or before the budget has none, and Missing names it. Without K: the curve at 3000."""
    from analysis.aggregate import final_reading, summarise, value_at
    from copilot_ray.keys import EVAL_SUCCESS

    five = [[0.1, 0.2 + i / 10, 0.4 + i / 10, 0.9] for i in range(5)]
    sweep = _depth_sweep({5: five, 3: [*five[:4], [0.3]]})
    configs, missing = summarise(sweep, reps=20_000, final_evaluations=2)
    by = {c.label: c.metrics[EVAL_SUCCESS] for c in configs}
    expected = [(0.2 + i / 10 + 0.4 + i / 10) / 2 for i in range(5)]
    assert by["K=5"].finals.tolist() == pytest.approx(expected)
    assert by["K=5"].final_step == 3000.0 and by["K=5"].final_evaluations == 2
    assert by["K=5"].final.point == pytest.approx(stats.iqm(np.array(expected)))
    assert np.isnan(by["K=3"].finals[-1]) and by["K=3"].final.n == 4  # seed 5: one evaluation
    assert (
        "configuration K=3, seed 5: 1 evaluation(s) due at or before the budget, fewer than "
        "--final-evaluations 2: no final success (left out of the final's figures)"
    ) in missing.lines()
    # K = 1: the last evaluation at or before the budget; default: the curve at the budget
    assert value_at((np.array([1000.0, 3100.0]), np.array([0.2, 0.9])), 3000.0, 1) == (0.2, 1000.0)
    default, _ = summarise(sweep, reps=20_000)
    assert default[1].metrics[EVAL_SUCCESS].finals.tolist() == pytest.approx([0.4 + i / 10 for i in range(5)])
    index, weights, at = final_reading(np.array([1000.0, 2000.0, 3000.0, 3100.0]), 2500.0)
    assert index.tolist() == [1, 2] and weights.tolist() == [0.5, 0.5] and at == 2500.0
    with pytest.raises(ValueError, match="final_evaluations=0 is invalid"):
        summarise(sweep, final_evaluations=0)


def test_final_evaluations_count_each_evaluation_at_the_point_it_was_due():
    """Evaluated every 10k env steps, a run evaluates at the end of the first iteration past each point:
    the privilege-matched CO-PILOT seed 1's last four at 170,297, 181,425, 191,198 and 200,035. With a
    200k budget the one due at 200k ran 35 env steps past it; it is the evaluation "at 200k", so K = 3
    reads the three due at 180k, 190k and 200k (docs/depth_k's rule), not 170k-190k. A run that logged
    no env-step cadence counts each evaluation at its own env step."""
    from analysis.aggregate import evaluations_up_to, summarise
    from copilot_ray.keys import EVAL_SUCCESS

    steps = (170297.0, 181425.0, 191198.0, 200035.0, 210044.0)
    sweep = _depth_sweep({5: [[0.60, 0.70, 0.80, 0.90, 0.95]] * 5}, budget=200000.0, steps=steps)
    for t in sweep.trials:
        t.params["eval_every_env_steps"] = "10000"
    (c,), _ = summarise(sweep, reps=20_000, final_evaluations=3)
    assert c.metrics[EVAL_SUCCESS].finals.tolist() == pytest.approx([0.8] * 5)  # (0.7 + 0.8 + 0.9) / 3
    assert c.metrics[EVAL_SUCCESS].final_step == 200035.0
    assert evaluations_up_to(np.array(steps), 200000.0, 10000.0) == 4
    assert evaluations_up_to(np.array(steps), 200000.0) == 3
    for t in sweep.trials:
        del t.params["eval_every_env_steps"]
    (c,), _ = summarise(sweep, reps=20_000, final_evaluations=3)
    assert c.metrics[EVAL_SUCCESS].finals.tolist() == pytest.approx([0.7] * 5)  # 170k-190k


def test_counts_are_read_where_the_final_is_read():
    """SoRB with the map spends its checks inside evaluations: rows every 400 env steps repeat the count,
    which jumps at each evaluation (190,164 and 200,326). With a 200k budget the final is read 9,836 /
    10,162 of the way to the evaluation past it; its checks are read with the same weights at the same
    two evaluations (not interpolated between the rows at 199,926 and 200,326, which holds 81 % of the
    last evaluation's checks back). With K = 2: the mean over the two evaluations at or before it."""
    from analysis.aggregate import summarise
    from analysis.figures import checks_at
    from copilot_ray.keys import EVAL_SUCCESS, PRIVILEGE_COLLISION_CHECKS

    evals = np.array([180062.0, 190164.0, 200326.0])
    sweep = _depth_sweep({5: [[0.67, 0.73, 0.90]] * 5}, budget=200000.0, steps=tuple(evals))
    rows = np.array([180062.0, 189764.0, 190164.0, 199926.0, 200326.0])
    counts = np.array([5231781.0, 5231781.0, 5541573.0, 5541573.0, 5854677.0])
    for t in sweep.trials:
        t.curves[PRIVILEGE_COLLISION_CHECKS] = (rows, counts)
        t.latest[PRIVILEGE_COLLISION_CHECKS] = counts[-1]
    w = (200000 - 190164) / (200326 - 190164)
    (c,), _ = summarise(sweep, reps=20_000)
    assert c.metrics[EVAL_SUCCESS].finals[0] == pytest.approx(0.73 + w * (0.90 - 0.73))
    assert c.privilege_counts[PRIVILEGE_COLLISION_CHECKS] == pytest.approx(5541573 + w * 313104)
    assert c.privilege_counts[PRIVILEGE_COLLISION_CHECKS] != pytest.approx(5541573 + 74 / 400 * 313104)
    # the figure of success against checks pairs them the same way along the whole curve
    assert checks_at(c, np.array([200000.0]))[0] == pytest.approx(5541573 + w * 313104)
    (c,), _ = summarise(sweep, reps=20_000, final_evaluations=2)
    assert c.privilege_counts[PRIVILEGE_COLLISION_CHECKS] == pytest.approx((5231781 + 5541573) / 2)


def test_a_reference_configuration_is_found_by_label_config_key_variant_or_label_parts():
    from analysis.aggregate import UnknownConfigurationError, find_configuration, improvement_pairs, summarise
    from copilot_ray.keys import EVAL_SUCCESS, VARIANT_TAG

    sweep = _depth_sweep({k: [[0.1, 0.2, 0.1 * k, 0.9]] * 5 for k in (3, 4, 5)})
    configs, _ = summarise(sweep, reps=20_000)
    assert [c.label for c in configs] == ["K=3", "K=4", "K=5"]
    five = find_configuration(configs, "tree_depth=5")
    assert five.label == "K=5" and find_configuration(configs, "K=5") is five
    assert [(x.label, y.label) for x, y in improvement_pairs(configs, EVAL_SUCCESS, "each", five)] == [
        ("K=5", "K=3"),
        ("K=5", "K=4"),
    ]
    # best: the other configuration with the highest final (here K = 4), whatever its algorithm
    assert [y.label for _, y in improvement_pairs(configs, EVAL_SUCCESS, "best", five)] == ["K=4"]
    with pytest.raises(
        UnknownConfigurationError,
        match=r"'tree_depth=7' is no configuration here; the labels are: 'K=3'; 'K=4'; 'K=5'",
    ):
        find_configuration(configs, "tree_depth=7")
    for t in sweep.trials:
        if t.tags[K_TAG] == "4":
            t.tags[VARIANT_TAG] = "frozen_planner"
    configs, _ = summarise(sweep, reps=20_000)
    assert find_configuration(configs, "frozen_planner").label == "variant=frozen_planner, K=4"
    assert find_configuration(configs, "variant=frozen_planner").label == "variant=frozen_planner, K=4"


def _depth_store(root: Path, finals_by_k: dict[int, list[float]], budget: int = 3000, warm_start=None) -> str:
    """An MLflow store of one all-CO-PILOT sweep: K = k under config key tree_depth=k, seeds 1..n, each
    evaluated at 1000, 2000, 3000 (fresh rows), its final at 3000 given, earlier ones below it.
    `warm_start(k, seed)`: the planner warm-start cost the run logs (none without it)."""
    import mlflow
    from mlflow.entities import Metric

    from copilot_ray.keys import BUDGET_PARAM, EVAL_FRESH, EVAL_SUCCESS

    uri = f"sqlite:///{root / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("depth", artifact_location=(root / "art").as_uri())
    pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "depth"}).info.run_id
    client.log_param(pid, BUDGET_PARAM, budget)
    now = int(time.time() * 1000)
    for k, finals in finals_by_k.items():
        for i, final in enumerate(finals):
            seed = str(i + 1)
            tags = {PARENT_TAG: pid, ROLE_TAG: ROLE_TRIAL, SWEEP_TAG: "depth", SEED_TAG: seed, K_TAG: str(k)}
            tags |= {CONFIG_KEY_TAG: f"tree_depth={k}", ALGORITHM_TAG: "copilot", ENV_TAG: "maze-point"}
            rid = client.create_run(exp_id, run_name=f"K{k}s{seed}", tags=tags).info.run_id
            values = [final / 4, final / 2, final]
            ms = [Metric(EVAL_SUCCESS, v, now, s) for s, v in zip(STEPS[:3], values, strict=True)]
            ms += [Metric(EVAL_FRESH, 1.0, now, s) for s in STEPS[:3]]
            if warm_start is not None:
                ms.append(Metric(PLANNER_WARM_START_COST, warm_start(k, seed), now, 0))
            client.log_batch(rid, metrics=ms)
            client.set_terminated(rid, "FINISHED")
    return uri


def test_report_reference_final_evaluations_and_the_99_reading(tmp_path, capsys):
    """An all-CO-PILOT sweep (the depth sweep's shape): --reference tree_depth=5 --improvement-over each
    gives P(K=5 > K=j) for each j with its 95 % and 99 % readings; --final-evaluations 2 is said on the
    page; bad values exit 2 naming the flag and the value."""
    finals = {
        3: [0.30, 0.32, 0.34, 0.36, 0.38],
        4: [0.50, 0.61, 0.66, 0.71, 0.80],
        5: [0.60, 0.62, 0.64, 0.68, 0.70],
    }
    uri = _depth_store(tmp_path, finals)
    out = tmp_path / "report"
    base = ["depth", "--tracking-uri", uri, "--out", str(out), "--no-log"]
    argv = [*base, "--reference", "tree_depth=5", "--improvement-over", "each", "--final-evaluations", "2"]
    assert main(argv) == 0
    imp = pd.read_csv(out / "improvement.csv")
    assert imp["reference"].tolist() == ["K=5", "K=5"] and imp["other"].tolist() == ["K=3", "K=4"]
    mean2 = {k: [(f / 2 + f) / 2 for f in v] for k, v in finals.items()}  # the 2000 and 3000 evaluations
    for _, r in imp.iterrows():
        k = int(r["other"][2:])
        at95 = stats.improvement(mean2[5], mean2[k])
        at99 = stats.improvement(mean2[5], mean2[k], confidence=0.99)
        assert (r["p_final"], r["p_final_low"], r["p_final_high"]) == pytest.approx(
            (at95.p, at95.low, at95.high)
        )
        assert (r["p_final_low_99"], r["p_final_high_99"]) == pytest.approx((at99.low, at99.high))
        assert (r["p_final_reading"], r["p_final_reading_99"]) == (at95.reading(), at99.reading())
    assert imp.loc[0, "p_final_reading"] == "ahead"  # K=5 beats K=3 in every pair
    report = (out / "report.md").read_text()
    assert "## Probability of improvement over each other configuration" in report
    assert "a seed of the reference configuration, K=5 (--reference)" in report
    assert "| K=5 (-) | K=3 (-) | 1.00 [95% CI 1.00, 1.00] | ahead (99%: ahead) |" in report
    assert "Final = the mean of each seed's last 2 evaluations at or before the env-step budget" in report
    assert "--final-evaluations 2" in report
    # the depth page's "depth with the highest IQM" of the primary figure, from the summary's point
    iqm4, iqm5 = (stats.iqm(np.array(mean2[k])) for k in (4, 5))
    assert iqm4 > iqm5
    assert f"Highest final test success (IQM, the table's point estimate): K=4, {iqm4:.3f}." in report
    summary = pd.read_csv(out / "summary.csv").set_index("configuration")
    assert summary.loc["K=4", "success_final"] == pytest.approx(iqm4)

    capsys.readouterr()
    assert main([*base, "--reference", "tree_depth=7"]) == 2
    err = capsys.readouterr().err
    assert "--reference tree_depth=7" in err and "the labels are: 'K=3'; 'K=4'; 'K=5'" in err
    assert (out / "improvement.csv").exists()  # refused before --out was touched: the report stays
    for bad in ("0", "-1", "two"):
        with pytest.raises(SystemExit) as done:
            main([*base, "--final-evaluations", bad])
        assert done.value.code == 2
        assert "--final-evaluations" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*base, "--final-evaluations", "0"])
    assert "--final-evaluations 0 is invalid" in capsys.readouterr().err


def test_signed_rank_test_exact_on_hand_computed_cases():
    """Two-sided, exact: 8 positive differences give the smallest p, 2 / 2^8; 5 give 2 / 2^5 = 0.0625
    (no difference of five pairs reaches 0.05); a zero is dropped before ranking; tied |d| take their
    average rank and every sign pattern is enumerated (by hand below: 16 patterns of ranks 1.5, 1.5, 3,
    4, W+ = 6: 6 of them at or above it)."""
    from scipy.stats import wilcoxon

    eight = stats.signed_rank_test(np.arange(1, 9) / 100)
    assert (eight.p, eight.statistic, eight.w_plus, eight.n) == (pytest.approx(2 / 256), 0.0, 36.0, 8)
    assert stats.signed_rank_test(np.arange(1, 6) / 10).p == pytest.approx(0.0625)
    zero = stats.signed_rank_test([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    assert (zero.n, zero.zeros, zero.p) == (5, 1, pytest.approx(0.0625))
    tied = stats.signed_rank_test([0.1, 0.1, 0.2, -0.3])
    assert (tied.w_plus, tied.w_minus, tied.statistic) == (6.0, 4.0, 4.0)
    assert tied.p == pytest.approx(2 * 6 / 16) and "tied" in tied.method
    # without ties it is scipy's exact test, whatever the signs
    d = np.array([0.05, -0.12, 0.3, 0.07, -0.01, 0.22])
    assert stats.signed_rank_test(d).p == pytest.approx(wilcoxon(d, method="exact").pvalue)
    # W- = 1 + 4 = 5; subsets of ranks 1..6 summing to <= 5: {}, 1, 2, 3, 12, 4, 13, 5, 14, 23: 10 of 64
    assert stats.signed_rank_test(d).p == pytest.approx(2 * 10 / 64)
    assert stats.signed_rank_test([0.0, 0.0]).p == 1.0
    # float noise splits neither a zero nor a tie: 0.3 - 0.1 - 0.2 is 0; 0.45 - 0.375 ties 0.525 - 0.6
    assert abs(0.45 - 0.375) != abs(0.525 - 0.6) and 0.3 - 0.1 - 0.2 != 0  # as floats they differ
    noisy = stats.signed_rank_test([0.3 - 0.1 - 0.2, 0.45 - 0.375, 0.525 - 0.6, 0.01])
    assert (noisy.zeros, noisy.n, noisy.w_plus, noisy.w_minus) == (1, 3, 3.5, 2.5) and "tied" in noisy.method
    assert np.isnan(stats.signed_rank_test([]).p)
    # Holm: m = 3 tests (the NaN is none); 0.01 x 3, then max(0.03, 0.03 x 2), then max(0.06, 0.04)
    np.testing.assert_allclose(stats.holm([0.01, 0.04, 0.03, np.nan]), [0.03, 0.06, 0.06, np.nan])


def test_paired_comparison_seed_for_seed_with_holm(tmp_path):
    """--paired: K=5 beats K=3 on every one of 8 shared seeds, on final and AUC: p = 2/256 each, Holm
    over each figure's family (K=3 and K=4 on final; apart from them, on AUC) keeps them below 0.05:
    ahead. K=4 shares only seeds 1-5 (its 6-8 never ran)."""
    from analysis.aggregate import find_configuration, summarise
    from analysis.tables import paired_frame, paired_table

    up = [[0.1, 0.2, 0.5 + s / 100, 0.9] for s in range(8)]
    down = [[0.05, 0.1, 0.3 + s / 100, 0.9] for s in range(8)]
    mixed = [[0.1, 0.2, v, 0.9] for v in (0.6, 0.4, 0.7, 0.45, 0.5)]
    configs, _ = summarise(_depth_sweep({3: down, 4: mixed, 5: up}))
    frame = paired_frame(configs, "each", find_configuration(configs, "K=5"))
    rows = {(r["other"], r["figure"]): r for _, r in frame.iterrows()}
    final3 = rows[("K=3", "final")]
    assert final3["n_pairs"] == 8 and final3["seeds"] == "1 2 3 4 5 6 7 8"
    assert final3["_differences"] == pytest.approx([0.2] * 8)
    assert (final3["W"], final3["p"]) == (0.0, pytest.approx(2 / 256))
    four = rows[("K=4", "final")]
    assert four["n_pairs"] == 5 and four["unpaired_seeds"] == "6 7 8"
    assert four["_differences"] == pytest.approx([-0.1, 0.11, -0.18, 0.08, 0.04])
    for figure in ("final", "auc"):  # a family per figure, as a rule fixed before a run states them
        family = frame[frame["figure"] == figure]
        assert len(family) == 2
        np.testing.assert_allclose(family["p_holm"], stats.holm(family["p"].to_numpy()))
    assert not np.allclose(frame["p_holm"], stats.holm(frame["p"].to_numpy()))  # not one family of four
    assert final3["reading"] == "ahead" and rows[("K=3", "auc")]["reading"] == "ahead"
    assert four["reading"] == "not separated"
    assert frame.loc[frame["other"] == "K=3", "p_holm"].max() < 0.05
    cells = paired_table(frame).rows[0]
    assert cells[3].startswith("1: +0.200; 2: +0.200") and cells[-2:] == ["ahead", "not logged"]


def test_report_paired_csv_and_page(tmp_path):
    finals = {3: [0.30, 0.32, 0.34, 0.36, 0.38], 5: [0.60, 0.62, 0.64, 0.68, 0.70]}
    uri = _depth_store(tmp_path, finals, warm_start=lambda k, seed: 1.0 + int(seed) / 7)
    out = tmp_path / "report"
    argv = ["depth", "--tracking-uri", uri, "--out", str(out), "--no-log", "--reference", "K=5", "--paired"]
    assert main(argv) == 0
    paired = pd.read_csv(out / "paired.csv")
    assert paired["figure"].tolist() == ["final", "auc"] and "_differences" not in paired.columns
    assert paired["p"].tolist() == pytest.approx([0.0625, 0.0625])  # five positive differences
    # one test per figure's family: Holm leaves each p as it is
    assert paired["p_holm"].tolist() == pytest.approx([0.0625, 0.0625])
    assert paired["warm_start"].tolist() == ["shared", "shared"]
    assert paired["reading"].tolist() == ["not separated", "not separated"]
    report = (out / "report.md").read_text()
    assert "## Paired comparison, seed for seed (--paired)" in report
    assert "with 5 pairs no difference can reach alpha 0.05" in report
    assert "| K=5 | K=3 | final | 1: +0.300; 2: +0.300; 3: +0.300; 4: +0.320; 5: +0.320 | 5 (0) |" in report
    assert "Shared at every seed with K=3." in report and "pairing is broken" not in report


def test_paired_rows_whose_warm_starts_differ_are_said_broken(tmp_path):
    """The pairing check: seed 2's warm start differs between K=5 and K=3 (another commit, another planner
    setting): the paired frame and the page say so, before the table, naming the seed and both costs; a
    row that logs no warm start is "not logged"."""
    from analysis import report_page
    from analysis.aggregate import find_configuration, summarise
    from analysis.tables import paired_frame

    up = [[0.1, 0.2, 0.5 + s / 100, 0.9] for s in range(3)]
    down = [[0.05, 0.1, 0.3 + s / 100, 0.9] for s in range(3)]
    configs, _ = summarise(_depth_sweep({3: down, 4: down, 5: up}))
    by = {c.label: c for c in configs}
    for label in ("K=3", "K=5"):
        for t in by[label].trials:
            t.latest[PLANNER_WARM_START_COST] = 2.5 if (label, t.seed) == ("K=3", "2") else 1.25
    frame = paired_frame(configs, "each", find_configuration(configs, "K=5"))
    checks = dict(zip(frame["other"], frame["warm_start"], strict=False))
    assert checks == {"K=3": "differs at seed 2 (1.25 vs 2.5)", "K=4": "not logged"}
    blocks = report_page.paired_blocks(frame, by["K=5"])
    said = [text for kind, text in blocks if kind == "p"]
    assert "**The pairing is broken** for K=5 and K=3: differs at seed 2 (1.25 vs 2.5)" in said[1]
    assert [kind for kind, _ in blocks] == ["h2", "p", "p", "table"]  # said before the table


def test_a_lone_configuration_of_an_interrupted_sweep_is_not_told_of_others(tmp_path):
    """One configuration, seed 1 evaluated, seed 2 still running without an evaluation: not "one seed per
    configuration", not "fewer seeds than the others" (there are none); the sweep is said incomplete."""
    from analysis.aggregate import summarise
    from analysis.report_page import summary_text

    sweep = _depth_sweep({1: [[0.1, 0.2, 0.3], None]}, statuses={(1, "2"): "RUNNING"})
    configs, missing = summarise(sweep, reps=20_000)
    lines = missing.lines()
    assert not any("fewer seeds than the others" in line for line in lines)
    assert any(
        "configuration tree_depth=1 lacks seeds 2 (its runs of them ended unfinished or have no evaluation yet"
        in line
        for line in lines
    )
    text = summary_text(configs, "test", "")
    assert text.startswith("One configuration, one seed with evaluations: a look at how the run went")
    assert "per configuration" not in text.split(".")[0]
    assert "The sweep is incomplete: 1 more run(s) without figures yet" in text
    # two configurations, one lacking a seed the other has: "fewer seeds than the others" is right
    sweep = _depth_sweep({1: [[0.1, 0.2, 0.3], None], 2: [[0.1, 0.2, 0.3], [0.2, 0.3, 0.4]]})
    assert any("fewer seeds than the others" in line for line in summarise(sweep, reps=20_000)[1].lines())


def test_a_carried_store_unpacked_elsewhere_finds_its_artifacts(tmp_path):
    """The store names its artifacts by the absolute paths of the machine that ran it; moved with them
    (a carried archive unpacked in another folder), the tree snapshots and the spec are still found."""
    import shutil

    import mlflow

    from analysis.load import RunArtifacts, load_sweep, load_tree_snapshots, spec_artifacts
    from copilot_ray.keys import RESOLVED_SPEC_ARTIFACT

    ran = tmp_path / "main-at-abc1234"
    results = ran / "results"
    results.mkdir(parents=True)
    uri = f"sqlite:///{results / 'x.db'}"
    client = mlflow.MlflowClient(uri)
    exp_id = client.create_experiment("moved", artifact_location=(results / "part" / "mlartifacts").as_uri())
    pid = client.create_run(exp_id, tags={ROLE_TAG: ROLE_SWEEP, SWEEP_TAG: "moved"}).info.run_id
    client.log_text(pid, "name: moved\n", RESOLVED_SPEC_ARTIFACT)
    rid = _child(client, exp_id, pid, "tree_depth=3", 3, "0")
    _metrics(client, rid, [0.1, 0.2], STEPS[:2])
    npz = tmp_path / "npz" / TREES_DIR
    npz.mkdir(parents=True)
    _tree_npz(npz / "trees_iter000005.npz", 5, np.random.default_rng(0))
    client.log_artifacts(rid, str(npz), TREES_DIR)
    client.set_terminated(rid, "FINISHED")

    unpacked = tmp_path / "elsewhere" / "store"
    shutil.move(str(ran), str(unpacked))  # `tar xzf store.tar.gz -C elsewhere/store`: results/ inside
    moved = f"sqlite:///{unpacked / 'results' / 'x.db'}"
    (trial,) = load_sweep(moved, "moved").trials
    assert trial.tree_artifacts == [f"{TREES_DIR}/trees_iter000005.npz"]
    assert load_tree_snapshots(moved, rid, trial.tree_artifacts)[0].depth == 3
    assert spec_artifacts(moved, pid) == [RESOLVED_SPEC_ARTIFACT]
    assert RunArtifacts(moved, rid).moved == unpacked / "results" / "part" / "mlartifacts" / rid / "artifacts"
