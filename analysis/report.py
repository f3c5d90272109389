"""`python -m analysis.report [EXPERIMENT] [--experiment NAME] [--tracking-uri URI] [--out DIR]`

Reads one sweep from MLflow and writes, under --out (default: `<store folder>/report` for a SQLite store in
a sweep's folder under `results/`, as `results/depth_k/mlflow.db`; else `results/<experiment>/report`):
  success_vs_env_steps.png   success (planned, direct) against env steps: IQM + 95 % bootstrap band
                             from 5 seeds on, else the mean and each seed (no band)
  final_success.png          final success per configuration (95 % CIs from 5 seeds on; paper Fig. 2b for K
                             on the maze)
  success_by_method.png, final_success_by_method.png
                             when the runs hold several algorithms: copilot/eval/success (each
                             method's headline) against env steps and at the end (paper Fig. 4a, 2a
                             on the maze; 2c on the Ant maze)
  success_vs_collision_checks.png
                             when several methods ran and some used the map: copilot/eval/success
                             against the ground-truth collision checks spent so far (paper Fig. 4c's
                             axis); a method without checks is one point at 0
  return_vs_env_steps.png    copilot/eval/return (R for reaching a test goal, averaged) against env
                             steps on the Ant maze (paper Fig. 2d); elsewhere it is R x the goals
                             reached (R = 1 on the maze: a rate the report already shows), so it is not
                             drawn and the report says so
  mastered_vs_env_steps.png  copilot/eval/mastered (share of the walker's evaluation track
                             distributions mastered) against env steps (paper Fig. 3 on the walker)
  subgoal_tree_<config>.png  one test task's sub-goal paths over training (paper Fig. 4d)
  summary.csv, summary.md    per-configuration tables: the headline (seeds, privileges and their counts,
                             env steps, final test success, success AUC) and the details (planned /
                             direct, steps to thresholds, wall time)
  improvement.csv            P(CO-PILOT's default, or the --reference configuration, beats the best
                             other or each other one), with the readings of its 95 % and 99 % CIs
  paired.csv                 with --paired: per-seed differences, the exact Wilcoxon signed-rank test
                             and Holm's adjusted p of the same pairs, seed for seed
  metrics.csv.gz             every run's copilot/*, paths/* and env-step metrics (run, config, seed,
                             metric, env steps, value)
  planners_paths.png, planners.csv, planners.md
                             runs that logged paths/* (RRT*, SGT-PG, CO-PILOT): success, length and
                             collision checks, each against RRT*'s (paper Fig. 4a-c), per agent
  report.md, report.html     all of the above on one page: provenance (commits, store, spec, command)
                             first, then missing/failed runs and what was left out of the figures (no
                             data, or a figure that would repeat another) and why; CO-PILOT's
                             diagnostics at the budget in numbers; with --target SUCCESS, whether
                             CO-PILOT's default meets that claim, part by part, or by how much it
                             falls short; each configuration's settings against this checkout's
                             defaults (`defaults.py`: is a row the default as the code stands now?)
and logs the folder to the sweep's parent MLflow run under `report/`.

Configurations are grouped by algorithm, config key, env id, env config and every other logged setting
(`load.configurations`): one variant on two layouts is two configurations, labelled `layout=...,
variant=...`, never one with twice the seeds. The paper's figure numbers are named only where the env is
the paper's (`paper_label`).

Tracking store: --tracking-uri, else $MLFLOW_TRACKING_URI, else an existing ./mlflow.db or
./results/*/mlflow.db that holds the experiment (see `load.resolve_tracking_uri`).

Exit status: 0 written (possibly with missing runs listed), 1 written but logging to MLflow failed,
2 bad input (no store, unknown experiment, no child runs, unknown parent run, a flag's bad value, an
unknown --reference).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from copilot_ray.commands import python_module
from copilot_ray.keys import (
    ALGORITHM_TAG,
    EVAL_MASTERED,
    EVAL_RETURN,
    PRIVILEGE_COLLISION_CHECKS,
    REACHED_DIRECT,
    REACHED_PLANNED,
    SUCCESS_METRICS,
    SUCCESS_PLANNED,
    TREES_DIR,
    validation_key,
)

from . import defaults, figures, paths, report_page, run_figures, stats, tables
from .aggregate import (
    IMPROVEMENT_OVER,
    ConfigSummary,
    Missing,
    UnknownConfigurationError,
    find_configuration,
    headline_metric,
    privileges_label,
    summarise,
)
from .export import METRICS_CSV, write_metrics_csv
from .load import (
    AUTO,
    TASK_SETS,
    TEST,
    VALIDATION,
    AnalysisError,
    Sweep,
    Trial,
    add_trials_from,
    axis_name,
    load_sweep,
    load_tree_snapshots,
    log_report_artifacts,
    natural_key,
    resolve_tracking_uri,
)
from .report_page import TEST_BESIDE_VALIDATION, command_line, one_seed_each  # noqa: F401 (command_line: this module's, where callers look)

MAX_TREE_FIGURES = 8
# A method whose final success on the VALIDATION tasks is above this gets `stats.MIN_SEEDS_FOR_CI` seeds in
# a comparison (below it, 2 do: its row shows a range and no CI). Read off the validation tasks so that how
# many seeds a method gets is never decided by the test figures being reported.
MORE_SEEDS_ABOVE = 0.1
_VALIDATION_WHY = (
    "every sweep here is a search, which chose by these tasks; its test figures are not shown, so that "
    "nothing is chosen by them: the comparison's second stage reports the test tasks"
)
# Said instead when --tasks validation chose them: a check of a default is no search, and must not read as one.
_VALIDATION_ASKED = "asked for with --tasks validation; no test figure is shown"
OWNED = (
    "*.png",
    "report.md",
    "report.html",
    "summary.csv",
    "summary.md",
    "planners.csv",
    "planners.md",
    "improvement.csv",
    "paired.csv",
    METRICS_CSV,
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog=python_module("analysis.report"), description=__doc__.split("\n\n")[0])
    p.add_argument("experiment_pos", nargs="?", metavar="EXPERIMENT", help="MLflow experiment name")
    p.add_argument("--experiment", help="MLflow experiment name (same as the positional argument)")
    p.add_argument(
        "--tracking-uri", help="MLflow tracking URI (default: $MLFLOW_TRACKING_URI or a found store)"
    )
    p.add_argument(
        "--out",
        type=Path,
        help="output folder (default: beside a SQLite store in a folder under results/, as "
        "results/<sweep>/report; else results/<experiment>/report)",
    )
    p.add_argument(
        "--parent-run",
        help="sweep (parent) run id when the experiment holds several sweeps; 'all': every one of them "
        "(the parts of a several-spec file, e.g. sweeps/planners_maze.yaml)",
    )
    p.add_argument(
        "--also-from",
        action="append",
        default=[],
        metavar="URI",
        help="another tracking store whose trial runs of the same experiment join the comparison "
        "(sweeps that ran side by side, each with its own SQLite file); repeatable",
    )
    p.add_argument(
        "--also-experiment",
        metavar="NAME",
        help="the experiment the --also-from stores' runs are read from (default: this report's own): "
        "one method rerun in an experiment of its own, put beside the comparison it joins (the "
        "provenance names every commit and warns when they differ)",
    )
    p.add_argument(
        "--tasks",
        choices=TASK_SETS,
        default=AUTO,
        help="whose success the report shows: 'auto' (default): the validation tasks when every sweep is "
        "a search (it chose by them: a test figure beside it would invite choosing by the test tasks), "
        "else the test tasks",
    )
    p.add_argument(
        "--improvement-over",
        choices=IMPROVEMENT_OVER,
        default="best",
        help="whom CO-PILOT's default is held against in the probability of improvement: the best other "
        "method (default), or each other configuration, its own variants included (an ablation's rows)",
    )
    p.add_argument(
        "--reference",
        metavar="CONFIG",
        help="whom the probability of improvement (and --paired) is computed FROM, instead of CO-PILOT's "
        "default: a configuration as the report labels it ('K=5'), its config key ('tree_depth=5'), its "
        "variant's name, or parts of its label ('variant=frozen_planner'); e.g. --reference tree_depth=5 "
        "--improvement-over each gives P(K=5 > K=j) for every j. An unknown one exits 2 listing the labels",
    )
    p.add_argument(
        "--final-evaluations",
        type=int,
        metavar="K",
        help="each seed's final = the mean of its last K evaluations at or before the env-step budget, each "
        "counted at the cadence point it was due at (the one due at the budget runs just after it); a seed "
        "with fewer has none. Default: its curve at the budget, linear between the evaluations on either "
        "side",
    )
    p.add_argument(
        "--paired",
        action="store_true",
        help="also the paired comparison, seed for seed (paired.csv): for each pair the probability of "
        "improvement compares, the per-seed differences of final success and of its AUC over the seeds "
        "both have, the exact two-sided Wilcoxon signed-rank test, and Holm's correction over them all",
    )
    p.add_argument("--task", type=int, default=0, help="test task index for the sub-goal tree figure")
    p.add_argument("--stages", type=int, default=3, help="training stages (columns) in the tree figure")
    p.add_argument(
        "--bootstrap-reps",
        type=int,
        default=stats.DEFAULT_REPS,
        help="resamples drawn for every interval (at least 20,000); default: exact (every resample "
        "enumerated) up to 8 seeds, 20,000 drawn beyond",
    )
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed (the report is reproducible)")
    p.add_argument("--no-log", action="store_true", help="do not log the report to the parent MLflow run")
    p.add_argument(
        "--target",
        type=float,
        metavar="SUCCESS",
        help="the comparison's stated claim: CO-PILOT's default reaches this final success (IQM over >= 5 "
        "seeds) with its CI above the best other method's; the report says, part by part, whether it is "
        "met or by how much it falls short (a success rate in (0, 1])",
    )
    args = p.parse_args(argv)
    if args.bootstrap_reps is not None and args.bootstrap_reps < stats.MC_REPS:
        p.error(
            f"--bootstrap-reps {args.bootstrap_reps} is invalid: at least {stats.MC_REPS:,} (or leave it out: exact)"
        )
    if args.final_evaluations is not None and args.final_evaluations < 1:
        p.error(
            f"--final-evaluations {args.final_evaluations} is invalid: the number of last evaluations "
            "averaged, an integer >= 1"
        )
    if args.target is not None and not 0 < args.target <= 1:
        p.error(f"--target: {args.target:g} is not a success rate in (0, 1]")
    if args.experiment and args.experiment_pos and args.experiment != args.experiment_pos:
        p.error(f"two different experiments given: {args.experiment_pos!r} and {args.experiment!r}")
    args.experiment = args.experiment or args.experiment_pos
    if not args.experiment:
        p.error("an experiment name is required (positional or --experiment)")
    if args.also_experiment and not args.also_from:
        p.error(
            f"--also-experiment {args.also_experiment}: names the experiment of --also-from stores; none given"
        )
    return args


def default_out(experiment: str, uri: str) -> Path:
    """The report's folder without --out: beside its store where the store is a SQLite file in a folder
    under a results folder (a sweep's own: results/depth_k/mlflow.db -> results/depth_k/report, whatever
    its experiment is called), else results/<experiment>/report under the working directory."""
    if uri.startswith("sqlite:///"):
        folder = Path(uri[len("sqlite:///") :]).parent
        if "results" in folder.parts[:-1]:
            return folder / "report"
    return Path("results") / _slug(experiment) / "report"


def join_other_stores(sweep: Sweep, args: argparse.Namespace) -> None:
    """Adds the trial runs of each --also-from store, read from --also-experiment (default: the report's)."""
    experiment = args.also_experiment or args.experiment
    for extra in args.also_from:
        add_trials_from(
            sweep, resolve_tracking_uri(extra, experiment=experiment, flag="--also-from"), experiment
        )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    try:
        uri = resolve_tracking_uri(args.tracking_uri, experiment=args.experiment)
        sweep = load_sweep(uri, args.experiment, args.parent_run, tasks=args.tasks)
        join_other_stores(sweep, args)
    except AnalysisError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    configs, missing = summarise(
        sweep, reps=args.bootstrap_reps, seed=args.seed, final_evaluations=args.final_evaluations
    )
    try:
        reference = find_configuration(configs, args.reference) if args.reference is not None else None
    except UnknownConfigurationError as e:  # before --out is touched: an earlier report stays whole
        print(f"error: --reference {args.reference}: {e}", file=sys.stderr)
        return 2

    out = args.out or default_out(args.experiment, uri)
    out.mkdir(parents=True, exist_ok=True)
    for pattern in OWNED:  # stale figures of an earlier report must not be logged as current
        for f in out.glob(pattern):
            f.unlink()
    _print_status(sweep, configs, missing)
    seed_notes = seeds_wanted(sweep, configs, args)
    for line in seed_notes:
        print(f"note: {line}")
    axes_shown = ", ".join(axis_name(a) for a in sweep.axes()) or "configuration"

    # (title, png, caption): the comparison figures' captions name each configuration's privileges
    figs: list[tuple[str, Path, str]] = []
    notes: list[str] = list(seed_notes)
    left_out: list[str] = []  # what a figure leaves out, and why
    several = len({t.tags.get(ALGORITHM_TAG) for t in sweep.trials}) > 1
    tasks = sweep.tasks
    tasks_why = _VALIDATION_ASKED if args.tasks == VALIDATION else _VALIDATION_WHY
    print(f"tasks: {tasks} ({tasks_why if tasks == VALIDATION else TEST_BESIDE_VALIDATION})")
    if any(c.metrics for c in configs):
        figs += _comparison_figures(configs, sweep, out, axes_shown, several, left_out)
    else:
        notes.append(f"No run has the agent's {tasks} success yet: no success figures.")
    planner_figs, planner_table, planner_frame, planner_title = _planner_section(configs, out, left_out)
    figs += planner_figs
    tree_figs, snapshots = _tree_figures(sweep, configs, args, out, notes)
    diag_figs = _diagnostic_figures(configs, snapshots, out, notes, left_out, tasks)

    frame, improvement, paired = _write_tables(sweep, configs, args, out, notes, reference)

    log_to = None if args.no_log else sweep.parent_run_id
    if not args.no_log and sweep.parent_run_id is None:
        msg = "no sweep (parent) run in this experiment: the report is not logged to MLflow"
        notes.append(msg)
        print(f"note: {msg}")
    provenance = report_page.provenance(sweep, argv, log_to)
    for line in provenance:
        if line.startswith("WARNING"):
            print(line, file=sys.stderr)
    below = _blocks_below_summary(
        configs, tasks, improvement, several, args, planner_table, planner_title, reference, paired
    )
    doc = report_page.document(
        sweep,
        configs,
        missing,
        axes_shown,
        figs,
        tree_figs + diag_figs,
        frame,
        notes,
        left_out,
        provenance,
        below,
        tasks_why,
        args.bootstrap_reps,
        args.final_evaluations,
    )
    (out / "report.md").write_text(report_page.to_markdown(doc))
    (out / "report.html").write_text(report_page.to_html(doc, sweep.experiment))
    print(f"report: {out / 'report.md'}")

    if log_to:
        try:
            log_report_artifacts(sweep.tracking_uri, log_to, out)
        except Exception as e:  # the files are written; say clearly that the MLflow copy is not
            print(f"error: could not log the report to run {log_to}: {e}", file=sys.stderr)
            return 1
        print(f"logged to MLflow run {log_to} under report/")
    return 0


def _write_tables(
    sweep: Sweep, configs: list[ConfigSummary], args, out: Path, notes: list[str], reference=None
):
    """summary.csv / .md, improvement.csv, paired.csv (--paired) and metrics.csv.gz; (the summary
    frame, the improvement frame, the paired frame or None)."""
    frame = tables.summary_frame(configs, sweep.tasks)
    tables.write_csv(frame, out / "summary.csv")
    (out / "summary.md").write_text(tables.markdown(frame))
    improvement = tables.improvement_frame(
        configs, reps=args.bootstrap_reps, seed=args.seed, over=args.improvement_over, reference=reference
    )
    if not improvement.empty:
        tables.write_csv(improvement, out / "improvement.csv")
    paired = None
    if args.paired:
        paired = tables.paired_frame(configs, over=args.improvement_over, reference=reference)
        if not paired.empty:
            tables.write_csv(paired, out / "paired.csv")
    labels = {t.run_id: c.label for c in configs for t in c.all_trials}
    try:
        write_metrics_csv(sweep, labels, out)
    except Exception as e:  # an unreadable history must not cost the report its tables and figures
        notes.append(f"{METRICS_CSV} not written: {type(e).__name__}: {e}")
    return frame, improvement, paired


def _blocks_below_summary(
    configs,
    tasks: str,
    improvement,
    several: bool,
    args,
    planner_table,
    planner_title,
    reference=None,
    paired=None,
) -> list[tuple]:
    """Right under the summary tables: the probability of improvement and the paired comparison (not
    for a look at one seed each, which compares nothing), the target's verdict, the settings against
    this checkout's defaults, the planners' table."""
    below = (
        []
        if one_seed_each(configs)
        else report_page.improvement_blocks(
            configs, improvement, several, args.improvement_over, args.bootstrap_reps, reference
        )
        + report_page.paired_blocks(paired, reference)
    )
    below += report_page.target_blocks(configs, tasks, args)
    settings_table = defaults.defaults_table(configs)
    if settings_table is not None:
        below += [
            ("h2", "Settings against this checkout's defaults"),
            ("p", defaults.TEXT),
            ("table", settings_table),
        ]
    if planner_table is not None:
        below += [
            ("h2", planner_title),
            ("p", paths.__doc__.split("\n\n")[1].replace("\n", " ")),
            ("table", planner_table),
        ]
    return below


def _method_figures(
    configs, out: Path, tasks: str, caption: str, left_out: list[str]
) -> list[tuple[str, Path, str]]:
    """Several algorithms: the one success figure they all report, per method (paper Fig. 2a, 4a), and
    against the collision checks spent where some used the map."""
    figs: list[tuple[str, Path, str]] = []

    def add(title: str, png: Path | None) -> None:
        if png is not None:
            figs.append((title, png, caption))

    by = figures.BY_METHOD
    curves = paper_label(configs, maze="paper Fig. 4a", ant="paper Fig. 2c")
    add(
        _titled("Success against environment steps, by method", curves),
        figures.success_curves(
            configs,
            "method",
            out / "success_by_method.png",
            by,
            title=_titled(f"{tasks.capitalize()} success against environment steps", curves),
            notes=left_out,
        ),
    )
    bars = paper_label(configs, maze="paper Fig. 2a")
    add(
        _titled("Final success by method", bars),
        figures.final_success(
            configs,
            "method",
            out / "final_success_by_method.png",
            by,
            paper=bars,
            notes=left_out,
            tasks=tasks,
        ),
    )
    if any(c.privilege_counts.get(PRIVILEGE_COLLISION_CHECKS, 0) > 0 for c in configs):
        add(
            "Success against collision checks (paper Fig. 4c's axis)",
            figures.success_vs_checks(
                configs,
                "method",
                out / "success_vs_collision_checks.png",
                title=f"{tasks.capitalize()} success against collision checks",
                notes=left_out,
            ),
        )
    return figs


def _comparison_figures(
    configs: list[ConfigSummary], sweep: Sweep, out: Path, axes_shown: str, several: bool, left_out: list[str]
) -> list[tuple[str, Path, str]]:
    """The comparison's figures, (title, png, caption) each: success against env steps and final success
    per configuration, per method when several algorithms ran, against the collision checks spent, the
    Ant maze's return and the walker's mastered distributions; the captions name each configuration's
    privileges. What a figure leaves out is said in `left_out`."""
    figs: list[tuple[str, Path, str]] = []
    caption = _privilege_caption(configs)
    tasks = sweep.tasks

    def add(title: str, png: Path | None) -> None:
        if png is not None:
            figs.append((title, png, caption))

    add(
        "Success against environment steps",
        figures.success_curves(
            configs,
            axes_shown,
            out / "success_vs_env_steps.png",
            title=f"{tasks.capitalize()} success against environment steps",
            notes=left_out,
        ),
    )
    k_label = paper_label(configs, maze="paper Fig. 2b") if sweep.axes() == ["K"] else ""
    add(
        _titled("Final success", k_label),
        figures.final_success(
            configs, axes_shown, out / "final_success.png", paper=k_label, notes=left_out, tasks=tasks
        ),
    )
    if several:
        figs += _method_figures(configs, out, tasks, caption, left_out)
    by = "method" if several else axes_shown
    ant = _return_configs(configs, left_out)
    if ant:
        title = "Return against environment steps on the Ant maze (paper Fig. 2d)"
        add(
            title,
            figures.success_curves(
                ant, by, out / "return_vs_env_steps.png", (EVAL_RETURN,), title=title, notes=left_out
            ),
        )
    if any(EVAL_MASTERED in c.metrics for c in configs):
        title = _titled(
            "Mastered track distributions against environment steps",
            paper_label(configs, walker="paper Fig. 3"),
        )
        add(
            title,
            figures.success_curves(
                configs,
                by,
                out / "mastered_vs_env_steps.png",
                (EVAL_MASTERED,),
                title=title,
                notes=left_out,
            ),
        )
    else:
        left_out.append(
            f"mastered_vs_env_steps.png: no run logged {EVAL_MASTERED} (the stump-track walker's measure)."
        )
    return figs


def seeds_wanted(sweep: Sweep, configs: list[ConfigSummary], args) -> list[str]:
    """One line per configuration reported on the test tasks with fewer than `MIN_SEEDS_FOR_CI` seeds.
    One short because runs of it ended unfinished (FAILED or KILLED) is told so: it does not meet the
    seed rule, and no seed is suggested in their place (running seeds until enough finish would choose
    by outcome). One run with few seeds on purpose is read off its final success on the validation tasks
    (the same runs' evaluations, mean over seeds): above `MORE_SEEDS_ABOVE` the comparison's rule asks for
    more seeds, and the line says which to run; at or below it the line says the rule allows the few
    (else "lacks seeds" reads as a defect). [] for validation reports and runs that logged no validation
    success."""
    short = [c for c in configs if 0 < c.n_seeds < stats.MIN_SEEDS_FOR_CI]
    if sweep.tasks != TEST or not short or one_seed_each(configs):
        return []  # (one seed each: a demo's look at its runs, not a comparison the rule is about)
    out = []
    for c in short:
        ended = sorted({str(t.seed) for t in c.all_trials if not t.usable}, key=natural_key)
        if ended:
            out.append(
                f"{c.label}: {c.n_seeds} seed(s) behind its figures; seed(s) {', '.join(ended)} ended "
                "unfinished (FAILED or KILLED, named above) and are left out: its cells show the seeds' "
                f"range, not a CI, and the row does not meet the comparison's {stats.MIN_SEEDS_FOR_CI}-seed "
                "rule. No seed is suggested in their place (running seeds until enough finish would "
                "choose by outcome)."
            )
    short = [c for c in short if all(t.usable for t in c.all_trials)]
    if not short:
        return out
    try:
        validation = load_sweep(sweep.tracking_uri, sweep.experiment, args.parent_run, tasks=VALIDATION)
        join_other_stores(validation, args)
    except AnalysisError:
        return out
    on_validation = {
        c.key: c
        for c in summarise(validation, reps=10, seed=args.seed, final_evaluations=args.final_evaluations)[0]
    }
    metric = headline_metric(configs)
    for c in short:
        v = on_validation.get(c.key)
        finals = v.metrics[metric].finals if v is not None and metric in v.metrics else np.array([])
        if finals.size and np.nanmean(finals) > MORE_SEEDS_ABOVE:
            more = _unused_seeds(c, stats.MIN_SEEDS_FOR_CI - c.n_seeds)
            out.append(
                f"{c.label}: {c.n_seeds} seed(s), and its final validation success ({validation_key(metric)}) is "
                f"{np.nanmean(finals):.2f}, above {MORE_SEEDS_ABOVE}: a method above it gets "
                f"{stats.MIN_SEEDS_FOR_CI} seeds in a comparison (decided on the validation tasks, not on "
                f"these test figures). Run seeds {more} as a part of their own, with the same config (or "
                f"best_of) and `seeds: {more}` (a started part takes no new seeds on --resume), and report "
                "it with this one (--parent-run all in one store, --also-from its own)."
            )
        elif finals.size:
            out.append(
                f"{c.label}: {c.n_seeds} seed(s), within the comparison's seed rule: its final validation "
                f"success ({validation_key(metric)}) is {np.nanmean(finals):.2f}, not above {MORE_SEEDS_ABOVE}, so "
                f"{c.n_seeds} may do (decided on the validation tasks, not on these test figures)."
            )
    return out


def _unused_seeds(config: ConfigSummary, count: int) -> list[int]:
    """`count` seeds after the largest any run of `config` used: a repeated seed would not be a new
    draw, and a smaller unused one may be the seed its stage 1 tuned on (privilege_matched's 0)."""
    used = [int(t.seed) for t in config.all_trials if str(t.seed).lstrip("-").isdigit()]
    start = max(used) + 1 if used else 0
    return list(range(start, start + count))


# ---------------------------------------------------------------------------------------------- planners
def _planner_section(configs: list[ConfigSummary], out: Path, left_out: list[str]):
    """(figures, table, frame, title): the paths' figure and table (planners.md / .csv) when any run logged
    paths/*, one row per env and configuration."""
    frame = paths.path_frame(configs)
    if frame.empty:
        return [], None, frame, ""
    frame.to_csv(out / "planners.csv", index=False)
    table = paths.table(frame)
    (out / "planners.md").write_text(table.markdown())
    with_rrt = frame[list(paths.COLUMNS.values())[1::2]].notna().any().any()  # the ratios to RRT*'s
    paper = paper_label(configs, maze="paper Fig. 4a-c") if with_rrt else ""
    fig = paths.path_figure(configs, out / "planners_paths.png", paper=paper, notes=left_out)
    groups: dict[str, list[Trial]] = {}
    for c in configs:
        groups.setdefault(c.method, []).extend(paths.path_trials(c.trials))
    caption = "Privileges: " + "; ".join(
        f"{a}: {privileges_label(ts)}" for a, ts in sorted(groups.items()) if ts
    )
    title = _titled("Planners: success, length and collision checks against RRT*", paper)
    if not with_rrt:
        title = "Planners: success of the planned paths (no RRT* reference: no length or check ratios)"
    figs = [(title, fig, caption)] if fig else []
    table_title = _titled("Planners: paths on the test tasks", "paper Fig. 4b/4c" if paper else "")
    return figs, table, frame, table_title


# The paper's figures are about its envs: a label is given only where every configuration ran on one.
MAZE_PREFIX = "maze-"  # maze-point, maze-rigid, maze-snake: Fig. 2a / 2b / 4
ANT_MAZE = "ant-maze"  # Fig. 2c / 2d
WALKER_PREFIX = "walker-stumps"  # Fig. 3


def paper_label(configs: list[ConfigSummary], maze: str = "", ant: str = "", walker: str = "") -> str:
    """The paper's figure for this comparison's env ("" when the env is not the paper's for it, or when
    the configurations ran on different kinds of env)."""
    envs = {c.env_id for c in configs if c.metrics or c.trials}
    if not envs:
        return ""
    if all(e.startswith(MAZE_PREFIX) for e in envs):
        return maze
    if envs == {ANT_MAZE}:
        return ant
    if all(e.startswith(WALKER_PREFIX) for e in envs):
        return walker
    return ""


def _titled(title: str, paper: str) -> str:
    return f"{title} ({paper})" if paper else title


def _return_configs(configs: list[ConfigSummary], left_out: list[str]) -> list[ConfigSummary]:
    """The configurations whose return is drawn: those on the Ant maze (paper Fig. 2d). Elsewhere the
    return is the task reward R times the goals reached: on the maze (R = 1) the success curve again,
    so it is left out, and `left_out` says why."""
    have = [c for c in configs if EVAL_RETURN in c.metrics]
    ant = [c for c in have if c.env_id == ANT_MAZE]
    others = [c for c in have if c.env_id != ANT_MAZE]
    if not have:
        left_out.append(f"return_vs_env_steps.png: no run logged {EVAL_RETURN}.")
    elif others:
        envs = ", ".join(sorted({c.env_id or "?" for c in others}))
        trials = [t for c in others for t in c.trials if EVAL_RETURN in t.curves]
        equal = {_return_equals(t) for t in trials}
        if None not in equal:  # R = 1 (the maze): the return is a rate the report has already
            names = " / ".join(sorted(m.split("/")[-1] for m in equal))
            why = f"it equals {names} in every run (task reward R = 1), so it would repeat that curve"
        else:
            why = "outside the Ant maze (paper Fig. 2d) it is the task reward R times the goals reached"
        which = "the configurations on " + envs if ant else "every configuration"
        left_out.append(f"return_vs_env_steps.png leaves out {which} ({EVAL_RETURN}, {envs}): {why}.")
    return ant


# What the return of R = 1 equals: the goals reached (collisions allowed; R x reached is the return), or a
# success (collision-free) rate where the two agree.
RETURN_TWINS = (REACHED_PLANNED, REACHED_DIRECT, *SUCCESS_METRICS)


def _return_equals(trial: Trial) -> str | None:
    """The rate `trial`'s return equals at every evaluation (R = 1), or None."""
    return next((metric for metric in RETURN_TWINS if trial.curves_agree(EVAL_RETURN, metric)), None)


def _privilege_caption(configs: list[ConfigSummary]) -> str:
    """Under a comparison figure: what each configuration may use that its baselines may not."""
    return (
        "Privileges ('-': runs older than the privileges tag): "
        + "; ".join(f"{c.label}: {c.privileges}" for c in configs)
        + "."
    )


# ---------------------------------------------------------------------------------------------- trees


def _tree_figures(sweep: Sweep, configs: list[ConfigSummary], args, out: Path, notes: list[str]):
    """One Fig. 4d per configuration (the best few when there are many), from its lowest-seed run that
    has tree snapshots; only the snapshots drawn are downloaded."""
    candidates = [c for c in configs if any(t.tree_artifacts for t in c.all_trials)]
    if len(candidates) > MAX_TREE_FIGURES:

        def score(c):
            m = c.metrics.get(SUCCESS_PLANNED)
            return m.final.point if m and np.isfinite(m.final.point) else -1.0

        best = {c.key for c in sorted(candidates, key=score, reverse=True)[:MAX_TREE_FIGURES]}
        notes.append(
            f"Sub-goal trees drawn for the {MAX_TREE_FIGURES} best of {len(candidates)} configurations."
        )
        candidates = [c for c in candidates if c.key in best]
    if not candidates and sweep.tasks == VALIDATION:  # the snapshots are of test tasks: withheld, not absent
        notes.append(
            f"No tree figure in a validation report: sub-goal tree snapshots ({TREES_DIR}/*.npz) are drawn on test tasks."
        )
    elif not candidates:
        notes.append(f"No run has sub-goal tree snapshots ({TREES_DIR}/*.npz): no tree figure.")
    result = []
    loaded: list[tuple[str, list]] = []
    for c in candidates:
        trial = _tree_trial(c)
        files = trial.tree_artifacts
        picks = sorted({int(round(i)) for i in np.linspace(0, len(files) - 1, max(1, args.stages))})
        try:
            snaps = load_tree_snapshots(
                trial.tracking_uri or sweep.tracking_uri, trial.run_id, [files[i] for i in picks]
            )
            if snaps[0].depth == 0:
                notes.append(f"{c.label} has tree depth 0 (no planner, plain SAC): no sub-goal tree to draw.")
                continue
            if snaps[0].trees.shape[-1] < 2:
                notes.append(
                    f"{c.label} plans in a 1-d goal space (the walker's x): no map to draw its trees on."
                )
                continue
            n_tasks = snaps[0].trees.shape[0]
            if not 0 <= args.task < n_tasks:
                notes.append(
                    f"--task {args.task} out of range for {c.label} ({n_tasks} test tasks): drew task 0"
                )
            task = args.task if 0 <= args.task < n_tasks else 0
            title = f"{c.label}: run {trial.run_name}, seed {trial.seed}, K={snaps[0].depth}"
            path = run_figures.subgoal_tree_evolution(
                snaps, task, title, out / f"subgoal_tree_{_slug(c.label)}.png"
            )
            result.append((f"Sub-goal tree, {c.label}", path))
            loaded.append((c.label, snaps))
        except Exception as e:  # one malformed snapshot must not sink the rest of the report
            msg = f"tree figure for {c.label} (run {trial.run_id}) failed: {type(e).__name__}: {e}"
            notes.append(msg)
            print(f"warning: {msg}", file=sys.stderr)
    return result, loaded


def _diagnostic_figures(
    configs: list[ConfigSummary], snapshots, out: Path, notes: list[str], left_out: list[str], tasks: str
):
    """The diagnostics page: why runs do or do not learn (copilot/diag/... curves, tau_hat profiles)."""
    result = []
    path = run_figures.diagnostics(configs, out / "diagnostics.png", notes=left_out, tasks=tasks)
    if path is None:
        notes.append("No run logged copilot/diag/... metrics: no diagnostics figure.")
    else:
        result.append(("Diagnostics", path))
    # The finest layer's reach (what the tau_hat plot is read against).
    keys = [
        (t, f"copilot/diag/reachable_length_layer_{run_figures.depth_of(t)}")
        for c in configs
        for t in c.trials
    ]
    reach = [t.curves[k][1][-1] for t, k in keys if k in t.curves]
    path = run_figures.tau_hat_profiles(
        snapshots, float(np.median(reach)) if reach else None, out / "tau_hat.png"
    )
    if path is not None:
        result.append(("Learned time cost tau_hat against segment length", path))
    return result


def _tree_trial(c: ConfigSummary) -> Trial:
    with_trees = [t for t in c.all_trials if t.tree_artifacts]
    finished = [t for t in with_trees if t.status == "FINISHED"]
    return (finished or with_trees)[0]  # all_trials is sorted by seed


def _print_status(sweep: Sweep, configs, missing: Missing) -> None:
    print(
        f"experiment {sweep.experiment!r}: {len(sweep.trials)} trials, {len(configs)} configurations, "
        f"parent run {sweep.parent_run_id or '(none)'}"
    )
    for line in missing.lines():
        print(f"missing: {line}")


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "_", text).strip("_") or "config"


if __name__ == "__main__":
    sys.exit(main())
