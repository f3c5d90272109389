"""A comparison is fair by construction: searchers read validation metrics only, the parts of one
experiment share env, budget, evaluation cadence and tuning budget, each algorithm declares its search
space, and stage 2 takes stage 1's winner from the store. No Ray is started."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from copilot_ray import keys
from copilot_ray.sweep_spec import SpecError, format_plan, load_specs, parse_spec

ROOT = Path(__file__).resolve().parents[1]
MAZE = {"id": "maze-point", "config": {"layout": "empty"}}


def part(name, algorithm="her", **changes) -> dict:
    data = {
        "name": name,
        "experiment": "cmp",
        "env": copy.deepcopy(MAZE),
        "algorithm": algorithm,
        "config": {"eval_every_env_steps": 1000},
        "seeds": [0],
        "stop": {"env_steps": 5000, "min_evaluations": 1},
    }
    data.update(changes)
    return data


def write(tmp_path, *parts) -> Path:
    path = tmp_path / "cmp.yaml"
    path.write_text("---\n".join(yaml.safe_dump(p, sort_keys=False) for p in parts))
    return path


def problems(path) -> str:
    with pytest.raises(SpecError) as err:
        load_specs(path)
    return str(err.value)


def test_a_test_metric_as_the_searcher_metric_is_refused_naming_the_key_and_the_validation_one():
    data = part("t", search={"actor_lr": {"float": [1e-4, 1e-3]}}) | {
        "searcher": {"type": "optuna", "metric": keys.EVAL_SUCCESS, "mode": "max", "num_samples": 2}
    }
    with pytest.raises(SpecError) as err:
        parse_spec(data)
    text = str(err.value)
    assert "searcher.metric: 'copilot/eval/success' is invalid: is a test-set metric" in text
    assert "use 'copilot/validation/success'" in text
    # with a scheduler, the message says that it would choose by the test tasks too
    data["scheduler"] = {"type": "asha", "max_t": 5000}
    assert "the searcher and the asha scheduler would choose" in str(
        pytest.raises(SpecError, parse_spec, data).value
    )
    # path metrics are test-set figures with no validation twin
    data["searcher"]["metric"] = keys.PATH_SUCCESS
    assert "no validation figure is logged for it" in str(pytest.raises(SpecError, parse_spec, data).value)
    data["searcher"]["metric"] = keys.validation_key(keys.EVAL_SUCCESS)
    data.pop("scheduler")
    assert parse_spec(data).searcher.metric == "copilot/validation/success"


def test_the_command_line_refuses_it_without_starting_ray(tmp_path):
    path = tmp_path / "bad.yaml"
    data = part("t", search={"actor_lr": {"float": [1e-4, 1e-3]}}) | {
        "searcher": {"type": "optuna", "metric": keys.SUCCESS_DIRECT, "mode": "max", "num_samples": 2}
    }
    path.write_text(yaml.safe_dump(data))
    code = f"import sys; from copilot_ray.sweep import main; rc = main([{str(path)!r}, '--check']); print('ray' in sys.modules); sys.exit(rc)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2 and out.stdout.strip() == "False"
    assert "searcher.metric: 'copilot/eval/success_direct' is invalid: is a test-set metric" in out.stderr
    assert "Traceback" not in out.stderr


def test_search_declared_is_the_algorithms_own_space_and_its_defaults_are_tried_first():
    from copilot_ray.algorithms.sac.her_settings import SEARCH_SPACE

    data = part("t", search="declared") | {
        "searcher": {
            "type": "optuna",
            "metric": "copilot/validation/success_auc",
            "mode": "max",
            "num_samples": 3,
        }
    }
    spec = parse_spec(data)
    assert list(spec.search) == list(SEARCH_SPACE)
    plan = format_plan(spec)
    assert "first trial of each study: the defaults actor_lr=0.0003, critic_lr=0.0003, gamma=0.99" in plan
    with pytest.raises(SpecError, match=r"search: 'declared' is invalid: rrt_star declares no search space"):
        parse_spec({**data, "algorithm": "rrt_star", "config": {}})


@pytest.mark.parametrize("algorithm", ["copilot", "sac", "her", "sorb", "sorb_map", "rrt_curriculum", "ppo"])
def test_every_compared_algorithm_declares_a_space_whose_ranges_hold_its_defaults(algorithm):
    from copilot_ray.registry import get_algorithm
    from copilot_ray.sweep_spec.plan import default_point

    entry = get_algorithm(algorithm)
    assert entry.search_space
    data = part("t", algorithm, search="declared") | {
        "config": {},
        "searcher": {
            "type": "optuna",
            "metric": "copilot/validation/success_auc",
            "mode": "max",
            "num_samples": 2,
        },
    }
    spec = parse_spec(data)  # every domain passes its setting's own rule
    assert set(default_point(spec)) == set(entry.search_space)


def test_parts_of_one_experiment_must_share_budget_cadence_and_tasks(tmp_path):
    text = problems(
        write(
            tmp_path,
            part("a"),
            part("b", "sac", stop={"env_steps": 9000, "min_evaluations": 1}),
            part("c", "ppo", config={"eval_interval": 3}, stop={"env_steps": 5000, "min_evaluations": 0}),
        )
    )
    assert "experiment 'cmp': stop.env_steps differs between its parts (a: 5000, b: 9000, c: 5000)" in text
    assert (
        "c: config.eval_every_env_steps: 0 is invalid: the parts of experiment 'cmp' are a comparison" in text
    )
    assert "eval_every_env_steps differs between its parts (a: 1000, b: 1000, c: 0)" in text


def test_parts_that_tune_get_the_same_tuning_budget(tmp_path):
    searcher = {"type": "optuna", "metric": "copilot/validation/success", "mode": "max", "num_samples": 4}
    text = problems(
        write(
            tmp_path,
            part("a", search="declared", searcher=searcher),
            part("b", "sac", search="declared", searcher={**searcher, "num_samples": 8}, seeds=[0, 1]),
            part("c", "sac"),
        )
    )
    assert "trials per seed differs between its parts (a: 4, b: 8)" in text
    assert "seeds differs between its parts (a: [0], b: [0, 1])" in text
    assert "c search nothing while other parts tune" in text


def test_a_part_whose_seeds_share_trials_has_the_tuning_budget_of_one_whose_seeds_do_not(tmp_path):
    """Two grids of 2 configurations x 2 seeds: 4 trials, or 2 trials of 2 stacked seeds; the same
    budget per seed either way."""
    grid = {"search": {"actor_lr": {"grid": [1e-4, 1e-3]}}, "seeds": [0, 1]}
    stacked = {**grid, "seeds_per_trial": 2, "resources": {"num_env_runners": 0}}
    specs = load_specs(write(tmp_path, part("a", **grid), part("b", "sac", **stacked)))
    assert [len(s.trial_plan()) for s in specs] == [4, 2]


def test_another_env_config_is_another_comparison_refused_in_one_experiment(tmp_path):
    other = {"id": "maze-point", "config": {"layout": "empty", "goal_reward": 2.0}}
    text = problems(write(tmp_path, part("a"), part("b", "sac", env=other)))
    assert "env differs between its parts" in text


def test_best_of_names_a_tuning_part_with_the_same_algorithm_and_a_validation_metric(tmp_path):
    searcher = {"type": "optuna", "metric": "copilot/validation/success", "mode": "max", "num_samples": 2}
    tune = part("tune", search="declared", searcher=searcher) | {"experiment": "tuning"}
    final = part("final", "sac", best_of={"sweep": "tune", "metric": "copilot/eval/success"})
    assert "best_of.metric: 'copilot/eval/success' is invalid: is a test-set metric" in problems(
        write(tmp_path, tune, final)
    )
    final["best_of"]["metric"] = "copilot/validation/success"
    text = problems(
        write(
            tmp_path,
            tune,
            final,
            part("ghost", best_of={"sweep": "tun", "metric": "copilot/validation/success"}),
        )
    )
    assert "final: best_of.sweep: 'tune' is invalid: it runs her, this part sac" in text
    assert (
        "best_of.sweep: 'tun' is invalid: not a part of this file" in text and "did you mean 'tune'?" in text
    )
    # a best_of part searches nothing itself
    with pytest.raises(
        SpecError, match=r"best_of: 'tune' is invalid: a part that takes the best configuration"
    ):
        parse_spec(
            part("x", best_of={"sweep": "tune", "metric": "copilot/validation/success"}, search="declared")
        )


def test_the_shipped_fair_comparison_is_valid_and_reads_stage_one_from_the_store():
    specs = load_specs(ROOT / "sweeps" / "fair_maze.yaml")
    tuning = [s for s in specs if s.search]
    final = [s for s in specs if s.best_of is not None]
    assert (
        len(tuning) == 6 and len(final) == 7 and len(specs) == 13
    )  # stage 2 adds the privileged restart row
    assert {s.experiment for s in tuning} == {"fair-maze-tuning"} and {s.experiment for s in final} == {
        "fair-maze"
    }
    for s in specs:
        assert not keys.is_test_metric(s.searcher.metric or s.best_of.metric)
    for s in final:
        uri, experiment = s.best_of_store()
        tuned = next(t for t in tuning if t.name == s.best_of.sweep)
        assert (uri, experiment) == (
            tuned.tracking.uri,
            "fair-maze-tuning",
        ) and tuned.algorithm == s.algorithm
        assert "read from its MLflow store when this part starts" in format_plan(s)


# ------------------------------------------------------------------------------------------- stages
def _store_with_a_tuning_sweep(tmp_path) -> str:
    """A hand-made stage-1 store: three configurations of sweep 'tune' (two seeds for one of them), one
    FAILED run that scored best and one run of another sweep scoring higher still."""
    import mlflow

    uri = f"sqlite:///{tmp_path}/store.db"
    client = mlflow.MlflowClient(uri)
    exp = client.create_experiment("tuning", artifact_location=(tmp_path / "art").as_uri())
    metric = "copilot/validation/success_auc"

    def trial(sweep, key, values, score, status="FINISHED", seed=0):
        tags = {keys.SWEEP_TAG: sweep, keys.ROLE_TAG: keys.ROLE_TRIAL, keys.CONFIG_KEY_TAG: key}
        run = client.create_run(exp, tags=tags)
        client.log_metric(run.info.run_id, metric, score - 0.1, step=1000)
        client.log_metric(run.info.run_id, metric, score, step=2000)  # the last value counts
        doc = {"trial": {**values, "seed": seed}}
        client.log_text(run.info.run_id, yaml.safe_dump(doc), keys.CONFIG_ARTIFACT)
        client.set_terminated(run.info.run_id, status=status)

    trial("tune", "actor_lr=0.0003", {"actor_lr": 3e-4}, 0.40)
    trial("tune", "actor_lr=0.001", {"actor_lr": 1e-3}, 0.70, seed=0)
    trial("tune", "actor_lr=0.001", {"actor_lr": 1e-3}, 0.30, seed=1)  # mean 0.50
    trial("tune", "actor_lr=0.0005", {"actor_lr": 5e-4}, 0.55)
    trial("tune", "actor_lr=0.0002", {"actor_lr": 2e-4}, 0.90, status="FAILED")
    trial("other", "actor_lr=0.0001", {"actor_lr": 1e-4}, 0.99)
    return uri


def test_stage_two_picks_the_best_finished_configuration_by_its_mean_over_seeds(tmp_path):
    from copilot_ray.stages import StageError, best_configuration

    uri = _store_with_a_tuning_sweep(tmp_path)
    winner = best_configuration(uri, "tuning", "tune", "copilot/validation/success_auc", "max")
    assert winner.values == {"actor_lr": 5e-4} and winner.score == pytest.approx(0.55) and winner.trials == 1
    worst = best_configuration(uri, "tuning", "tune", "copilot/validation/success_auc", "min")
    assert worst.values == {"actor_lr": 3e-4}
    with pytest.raises(StageError, match=r"none with 'copilot/validation/success'"):
        best_configuration(uri, "tuning", "tune", "copilot/validation/success", "max")
    with pytest.raises(StageError, match=r"no experiment 'nope'"):
        best_configuration(uri, "nope", "tune", "copilot/validation/success_auc", "max")


def test_the_stage_one_table_lists_every_trial_on_validation_tasks_and_marks_the_choice(tmp_path, capsys):
    """`python -m copilot_ray.stages`: each stage-1 sweep's trials (failed ones too, with their status)
    by the validation objective, the configuration stage 2 gets marked; a wrong experiment exits 2."""
    import mlflow

    from copilot_ray.stages import main

    uri = _store_with_a_tuning_sweep(tmp_path)
    client = mlflow.MlflowClient(uri)
    exp = client.get_experiment_by_name("tuning").experiment_id
    for sweep in ("tune", "other"):
        parent = client.create_run(exp, tags={keys.SWEEP_TAG: sweep, keys.ROLE_TAG: keys.ROLE_SWEEP})
        client.set_terminated(parent.info.run_id, status="FINISHED")
    assert main(["tuning", "--tracking-uri", uri]) == 0
    out = capsys.readouterr().out
    tune = out.split("### other")[0]
    assert "### tune (finished: 5 trial run(s))" in tune
    rows = [line for line in tune.splitlines() if line.startswith("| ") and "status" not in line]
    assert len(rows) == 5
    chosen = [r for r in rows if "**chosen**" in r]
    assert len(chosen) == 1 and "actor_lr=0.0005" in chosen[0] and "0.550" in chosen[0]
    assert any("failed" in r and "actor_lr=0.0002" in r for r in rows)  # shown, never chosen
    assert "stage 2 gets: {'actor_lr': 0.0005}" in tune
    assert "### other (finished: 1 trial run(s))" in out
    assert main(["tunning", "--tracking-uri", uri]) == 2
    assert "experiment 'tunning' is not in" in capsys.readouterr().err


def test_a_stage_two_part_writes_the_winner_into_the_spec_it_runs_with(tmp_path):
    """The resolved spec records the chosen values and where they came from; the trials' merged config
    has them; a resumed part reads them from that copy (no second look at the store)."""
    from copilot_ray.sweep import resolve_sweep

    uri = _store_with_a_tuning_sweep(tmp_path)
    data = part(
        "final",
        best_of={
            "sweep": "tune",
            "metric": "copilot/validation/success_auc",
            "uri": uri,
            "experiment": "tuning",
        },
        tracking={"storage": str(tmp_path / "results")},
    )
    spec = load_specs(write(tmp_path, data))[0]
    run = resolve_sweep(spec, resume=False, tracking_uri=None)
    assert run.spec.best_of.chosen == {"actor_lr": 5e-4}
    assert "best of sweep 'tune' by copilot/validation/success_auc = 0.55" in run.spec.best_of.chosen_from
    assert run.spec.merged({"seed": 3})["actor_lr"] == 5e-4
    saved = yaml.safe_load(run.saved_spec.read_text())
    assert saved["best_of"]["chosen"] == {"actor_lr": 5e-4}
    (run.root / "tune" / "final").mkdir(parents=True)  # as if it had started
    again = resolve_sweep(spec, resume=True, tracking_uri=None)
    assert again.spec.best_of.chosen == {"actor_lr": 5e-4}


@pytest.mark.parametrize("store", ["missing", "without the sweep"])
def test_a_stage_two_part_with_no_winner_yet_is_refused_before_ray_and_writes_nothing(
    tmp_path, store, capsys
):
    """Run alone, a stage 2 part whose stage 1 has not run (no store file; a store without its trials):
    one error line, exit 2, Ray's start not announced, no console log, no store made."""
    from copilot_ray.sweep import main

    uri = f"sqlite:///{tmp_path}/store.db" if store == "missing" else _store_with_a_tuning_sweep(tmp_path)
    best_of = {
        "sweep": "tuna",
        "metric": "copilot/validation/success_auc",
        "uri": uri,
        "experiment": "tuning",
    }
    path = write(tmp_path, part("final", best_of=best_of, tracking={"storage": str(tmp_path / "results")}))
    before = sorted(p.name for p in tmp_path.iterdir())
    capsys.readouterr()  # (what making the stage-1 store printed)
    assert main([str(path)]) == 2
    out, err = capsys.readouterr()
    assert len(err.splitlines()) == 1 and err.startswith("error: best_of: ") and "'tuna'" in err, err
    assert "starting Ray" not in out
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no results/, no store.db


def test_resuming_a_stage_two_part_notes_only_real_changes_and_says_added_seeds_do_not_run(tmp_path, capsys):
    """The saved copy differs from the file by what resolving wrote (stage 1's winner, the store): no
    note for that. Seeds added to the file are named, with what to do: a started part keeps its seeds."""
    from copilot_ray.sweep import resolve_sweep

    uri = _store_with_a_tuning_sweep(tmp_path)
    best_of = {
        "sweep": "tune",
        "metric": "copilot/validation/success_auc",
        "uri": uri,
        "experiment": "tuning",
    }
    data = part("final", best_of=best_of, seeds=[0, 1], tracking={"storage": str(tmp_path / "results")})
    spec = load_specs(write(tmp_path, data))[0]
    run = resolve_sweep(spec, resume=False, tracking_uri=None)
    (run.root / "tune" / "final").mkdir(parents=True)  # as if it had started
    capsys.readouterr()
    resolve_sweep(spec, resume=True, tracking_uri=None)
    assert "note:" not in capsys.readouterr().out

    grown = load_specs(write(tmp_path, {**data, "seeds": [0, 1, 2, 3, 4]}))[0]
    again = resolve_sweep(grown, resume=True, tracking_uri=None)
    out = capsys.readouterr().out
    assert again.spec.seeds == [0, 1]
    assert "differs from the spec this sweep began with in seeds;" in out
    assert "seeds [2, 3, 4] added to" in out and "do not run on --resume" in out
    assert "`seeds: [2, 3, 4]`" in out
    # A search runs one Tune experiment per seed: on --resume, too, only those of the seeds it began with.
    search = part(
        "tuned",
        search="declared",
        searcher={
            "type": "optuna",
            "metric": "copilot/validation/success_auc",
            "mode": "max",
            "num_samples": 2,
        },
        tracking={"storage": str(tmp_path / "results")},
    )
    run = resolve_sweep(load_specs(write(tmp_path, search))[0], resume=False, tracking_uri=None)
    (run.root / "tune" / "tuned-seed0").mkdir(parents=True)
    grown = load_specs(write(tmp_path, {**search, "seeds": [0, 1]}))[0]
    assert resolve_sweep(grown, resume=True, tracking_uri=None).experiments == [("tuned-seed0", 0)]
    assert "seeds [1] added to" in capsys.readouterr().out


@pytest.mark.ray
def test_a_two_stage_file_tunes_then_runs_the_winner_in_one_command(ray_session, tmp_path):
    """Stage 1 (HER, Optuna, its declared space, the defaults first) then stage 2 (best_of) from one
    file through Tune and MLflow: stage 2's trial runs the configuration that scored best in stage 1.
    Stage 1 is Ctrl-C'd in its second trial and the file resumed, as a long comparison is: its Optuna
    study continues (no trial lost, none run twice), then stage 2 runs."""
    import mlflow
    import optuna

    from copilot_ray.sweep import main, run_sweep, sweep_root
    from tests import interrupts

    open_maze = {"layout": "empty", "speed": 0.05, "success_radius": 0.1}
    common = {
        "env": {"id": "maze-point", "config": open_maze},
        "algorithm": "her",
        "config": {
            "tau_max": 20,
            "task_batch_size": 4,
            "eval_every_env_steps": 80,
            "eval_num_tasks": 10,
            "num_steps_sampled_before_learning_starts": 100,
        },
        "stop": {"env_steps": 160, "min_evaluations": 1},
        "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},  # (one at a time: cut the 2nd)
        "tracking": {"storage": str(tmp_path / "results"), "uri": f"sqlite:///{tmp_path}/fair.db"},
    }
    metric = "copilot/validation/success_auc"
    tune = {
        "name": "tune_her",
        "experiment": "tuning",
        **common,
        "search": "declared",
        "seeds": [0],
        "searcher": {"type": "optuna", "metric": metric, "mode": "max", "num_samples": 2, "seed": 0},
    }
    final = {
        "name": "final_her",
        "experiment": "final",
        **common,
        "seeds": [5],
        "best_of": {"sweep": "tune_her", "metric": metric},
    }
    path = write(tmp_path, tune, final)
    stage1 = load_specs(path)[0]
    cut = run_sweep(stage1, extra_callbacks=[interrupts.when_a_trial_starts_after_one_finished()])
    assert cut.status == "interrupted"
    assert main([str(path), "--resume"]) == 0

    client = mlflow.MlflowClient(common["tracking"]["uri"])
    tuning = client.get_experiment_by_name("tuning").experiment_id
    trials = [r for r in client.search_runs([tuning]) if r.data.tags.get(keys.ROLE_TAG) == keys.ROLE_TRIAL]
    assert len(trials) == 2 and all(r.info.status == "FINISHED" for r in trials)
    assert len({r.data.tags[keys.TRIAL_ID_TAG] for r in trials}) == 2
    for r in trials:  # each iteration logged once, in order
        steps = [m.step for m in client.get_metric_history(r.info.run_id, keys.TRAINING_ITERATION)]
        assert steps and steps == sorted(set(steps))
    studies = f"sqlite:///{sweep_root(stage1) / 'optuna.db'}"
    (summary,) = optuna.get_all_study_summaries(studies)  # one study: one seed, continued
    study = optuna.load_study(study_name=summary.study_name, storage=studies)
    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(complete) == 2, [t.state for t in study.trials]
    # the first trial of the study was the defaults
    assert any(r.data.params["actor_lr"] == "0.0003" and r.data.params["gamma"] == "0.99" for r in trials)
    top = max(r.data.metrics[metric] for r in trials)
    best = [r for r in trials if r.data.metrics[metric] == top]  # (a tie at this tiny budget: any of them)
    (run,) = [
        r
        for r in client.search_runs([client.get_experiment_by_name("final").experiment_id])
        if r.data.tags.get(keys.ROLE_TAG) == keys.ROLE_TRIAL
    ]
    assert run.data.tags[keys.SEED_TAG] == "5" and run.info.status == "FINISHED"
    # HER learns from its own episodes alone: no privilege, every count 0
    assert run.data.tags[keys.PRIVILEGES_TAG] == "none"
    for key in keys.PRIVILEGE_COUNTS:
        assert {m.value for m in client.get_metric_history(run.info.run_id, key)} == {0.0}, key
    searched = ("actor_lr", "critic_lr", "gamma", "her.n_sampled_goal")
    (winner,) = [r for r in best if all(run.data.params[k] == r.data.params[k] for k in searched)]
    saved = yaml.safe_load((tmp_path / "results" / "final_her" / "spec.yaml").read_text())
    assert winner.info.run_id in saved["best_of"]["chosen_from"]
    assert saved["best_of"]["chosen"]["actor_lr"] == pytest.approx(float(winner.data.params["actor_lr"]))
