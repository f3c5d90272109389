"""The report's page: a short list of blocks (headings, text, tables, figures) rendered twice, as Markdown
(report.md) and HTML (report.html, which the MLflow UI previews); and the blocks whose wording is the
report's own: the provenance (commits, stores, spec, command), the summary's text, the probability of
improvement and the target's verdict. `report.py` gathers the figures and tables and calls `document`.
"""

from __future__ import annotations

import datetime as _dt
import html
import subprocess
from pathlib import Path

import numpy as np

from copilot_ray.commands import python_module
from copilot_ray.keys import GIT_COMMIT_TAG, PLANNER_WARM_START_COST, SUCCESS_METRICS
from copilot_ray.privileges import DESCRIPTIONS

from . import stats, tables, target
from .aggregate import ConfigSummary, Missing
from .export import METRICS_CSV
from .load import VALIDATION, Sweep, spec_artifacts


def command_line(argv: list[str]) -> str:
    """The command that produced the report, as one can paste it again."""
    return python_module("analysis.report", *argv)


def one_seed_each(configs: list[ConfigSummary]) -> bool:
    """Every configuration has (at most) one seed: a demo or a first look, not a comparison; its report
    leaves out what only a comparison needs (the long summary of the statistics, the seed rule's notes,
    the probability of improvement)."""
    return all(c.n_seeds <= 1 for c in configs)


# The page is a short list of blocks rendered twice: Markdown (report.md) and HTML (report.html, which
# the MLflow UI previews).


def provenance(sweep: Sweep, argv: list[str], log_to: str | None) -> list[str]:
    """Where the numbers come from: commits, stores, experiment, spec, and the command that made the report."""
    commits = sorted({t.tags.get(GIT_COMMIT_TAG, "") for t in sweep.trials} - {""})
    untagged = sum(1 for t in sweep.trials if not t.tags.get(GIT_COMMIT_TAG))
    lines = [f"git commit{'s' if len(commits) > 1 else ''}: {', '.join(commits) or '(not tagged)'}"]
    if len(commits) > 1:
        lines.append(
            f"WARNING: the runs come from {len(commits)} different commits, not from one: "
            "the code may differ between the configurations compared"
        )
    if untagged:
        lines.append(f"{untagged} of {len(sweep.trials)} runs carry no {GIT_COMMIT_TAG} tag")
    stores = sorted({sweep.tracking_uri, *(t.tracking_uri for t in sweep.trials if t.tracking_uri)})
    lines.append(f"tracking URI{'s' if len(stores) > 1 else ''}: {', '.join(stores)}")
    joined = "".join(f" + experiment {name} (--also-experiment)" for name in sweep.joined_experiments)
    lines.append(
        f"experiment: {sweep.experiment} (id {sweep.experiment_id}){joined}; sweep: {sweep.sweep_name}"
    )
    lines += _spec_lines(sweep)
    lines.append(f"command: {command_line(argv)}")
    lines.append(_report_code())
    lines.append(
        f"generated {_dt.datetime.now().isoformat(timespec='seconds')}"
        + (f"; logged to run {log_to} under report/" if log_to else "")
    )
    return lines


def _report_code() -> str:
    """Which code read the store: the runs' commit says how they ran, this one how they were summarised
    (a later report may read the same store differently, e.g. final success at the budget)."""
    root = Path(__file__).resolve().parents[1]

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if not commit:
        return "report code: not a git checkout (its commit is unknown)"
    dirty = git("status", "--porcelain", "--", "analysis", "copilot_ray")
    return f"report code: commit {commit[:12]}" + (
        " with uncommitted changes to analysis/ or copilot_ray/" if dirty else ""
    )


def _spec_lines(sweep: Sweep) -> list[str]:
    if not sweep.parents:
        return [f"spec: no sweep (parent) run; sweep names from the runs' tags: {sweep.sweep_name}"]
    out = []
    for uri, run_id, name in sweep.parents:
        files = spec_artifacts(uri, run_id)  # the resolved spec (what ran) first
        if files:
            out.append(f"spec: {', '.join(f'runs:/{run_id}/{f}' for f in files)} (sweep {name!r})")
        else:
            out.append(f"spec: sweep {name!r}; its sweep run {run_id} holds no spec artifact")
    return out


def improvement_blocks(
    configs, frame, several: bool, over: str = "best", reps: int | None = None, reference=None
) -> list[tuple]:
    """Under the headline table: P(X beats the best other method, or each other row), X being CO-PILOT's
    default or the --reference configuration."""
    if not (several or reference is not None) or not any(
        m in c.metrics for c in configs for m in SUCCESS_METRICS
    ):
        return []  # one method and no reference, or planners alone (no success of an agent to compare)
    if reference is None:
        whom = (
            "the best other method (highest final success)"
            if over == "best"
            else "each other configuration (its own variants, an ablation's rows, included)"
        )
        who = (
            "a seed of CO-PILOT's default configuration (algorithm copilot, no preset; a variant such as "
            "the privileged after_failure restart is a row of its own, its privileges beside it)"
        )
        mine = "CO-PILOT's"
    else:
        whom = (
            "the best other configuration (highest final success)"
            if over == "best"
            else "each other configuration"
        )
        who = f"a seed of the reference configuration, {reference.label} (--reference)"
        mine = "the reference's"
    head = ("h2", f"Probability of improvement over {whom.split(' (')[0]}")
    why = (
        f"P(X > Y) (Agarwal et al. 2021): the chance that {who} scores higher than a seed of {whom}, "
        "ties counting 1/2, from the seeds' final success and success AUC; 95% percentile "
        "bootstrap CI with the seeds of both resampled independently ("
        + bootstrap_words(reps, pairs=True)
        + f"). Only with >= {stats.MIN_SEEDS_FOR_CI} "
        "seeds on each side. The reading holds the CI against 0.5: ahead (wholly above), behind (wholly "
        "below), not separated (it holds 0.5); with 5 seeds a side and no ties the CI clears 0.5 only from "
        "P >= 0.84. Beside each reading, in brackets, the same reading of the 99% CI (improvement.csv: "
        "the _99 columns), a Bonferroni check where several comparisons decide together (five 99% "
        f"intervals hold all at once with about 95% confidence or more). The last column says whether {mine} CI of final success "
        "lies wholly above the other's (a CI on both sides needs as many seeds)."
    )
    if frame.empty:
        none = (
            "No CO-PILOT default configuration or no other method with success."
            if reference is None
            else f"No other configuration with success beside {reference.label}."
        )
        return [head, ("p", why), ("p", none)]
    return [head, ("p", why), ("table", tables.improvement_table(frame, reference is not None))]


def paired_blocks(frame, reference=None) -> list[tuple]:
    """--paired: the per-seed differences, the exact Wilcoxon signed-rank test and Holm's adjusted p."""
    if frame is None:
        return []
    head = ("h2", "Paired comparison, seed for seed (--paired)")
    who = reference.label if reference is not None else "CO-PILOT's default"
    if frame.empty:
        return [head, ("p", f"No pair to compare: no configuration beside {who} with success.")]
    smallest = sorted({int(n) for n in frame["n_pairs"] if n > 0})
    floor = "; ".join(f"{n} pairs: {2 / 2**n:.4f}" for n in smallest)
    why = (
        f"The pairs of the probability of improvement above, seed for seed: each seed both configurations "
        f"ran, the difference {who} minus the other, of final success (the primary figure) and of its "
        "AUC (the secondary). The exact two-sided Wilcoxon signed-rank test over those differences "
        "(scipy.stats.wilcoxon, method='exact'): differences of exactly 0 are dropped before ranking "
        "(Wilcoxon's treatment; the pairs column says how many), tied |differences| share their average "
        "rank, and then p is enumerated over all 2^n sign patterns of those ranks (scipy's exact table "
        "assumes no ties); every difference 0: p = 1. W = the smaller of the rank sums of positive (W+) and "
        "negative (W-) differences. Holm's step-down correction over the tests of one figure (a family "
        "per figure: the comparisons against the reference on final success, and apart from them those "
        "on its AUC); the reading on the adjusted p at alpha "
        f"{stats.PAIRED_ALPHA:g}: ahead (the reference higher), behind, not separated. The smallest "
        f"two-sided p n pairs can give, 2 / 2^n ({floor})"
        + (
            f": with {smallest[0]} pairs no difference can reach alpha {stats.PAIRED_ALPHA:g}"
            if smallest and 2 / 2 ** smallest[0] >= stats.PAIRED_ALPHA
            else ""
        )
        + ". Seeds that only one side has are left out (paired.csv: unpaired_seeds)."
    )
    return [head, ("p", why), ("p", _warm_start_words(frame)), ("table", tables.paired_table(frame))]


def _warm_start_words(frame) -> str:
    """The pairing check, said before the table: do the paired rows share each seed's planner warm start?"""
    checks = frame.drop_duplicates(["reference", "other"])
    broken = checks[checks["warm_start"].str.startswith("differs")]
    unknown = checks[checks["warm_start"] == "not logged"]
    words = (
        "Pairing check (the warm start column): two rows pair seed for seed only if the seed ran the same "
        "planner warm start in both; the report compares each seed's logged warm-start cost "
        f"(`{PLANNER_WARM_START_COST}`) between them, to the bit. "
    )
    if not broken.empty:
        names = "; ".join(
            f"{r['reference']} and {r['other']}: {r['warm_start']}" for _, r in broken.iterrows()
        )
        return words + f"**The pairing is broken** for {names}: their paired tests do not compare twins."
    if len(unknown) == len(checks):
        return (
            words + "No pair logged it (rows without a planner, or older runs): the pairing is not checked."
        )
    shared = ", ".join(
        f"{r['other']}" for _, r in checks.iterrows() if r["warm_start"] == tables.WARM_START_SHARED
    )
    rest = f"; not logged for {', '.join(unknown['other'])}" if not unknown.empty else ""
    return words + f"Shared at every seed with {shared}{rest}."


def target_blocks(configs: list[ConfigSummary], tasks: str, args) -> list[tuple]:
    """The stated claim judged (with --target), then the diagnostics at the budget in numbers."""
    blocks: list[tuple] = []
    if args.target is not None:
        blocks += [("h2", f"Target: final {tasks} success >= {args.target:g}"), ("p", TARGET_TEXT)]
        blocks.append(("ul", target.verdict(configs, args.target, tasks)))
    table = target.diagnostics_table(configs, reps=args.bootstrap_reps, seed=args.seed)
    if table is not None:
        blocks += [("h2", "Diagnostics at the budget"), ("p", DIAGNOSTICS_TEXT), ("table", table)]
    return blocks


TARGET_TEXT = (
    "The claim, stated before the runs: CO-PILOT's default configuration reaches the target in final "
    f"success, IQM over >= {stats.MIN_SEEDS_FOR_CI} seeds, and the lower end of its 95% CI lies above the "
    "upper end of the best other method's (the other algorithm with the highest final success). Each part "
    "is met, NOT met with the amount it falls short by, or cannot be judged on fewer seeds; the "
    "diagnostics below say where a shortfall comes from."
)
DIAGNOSTICS_TEXT = (
    "The diagnostics figure's curves in numbers, for the configurations that logged sub-goal tree "
    "diagnostics: each seed's value at the env-step budget (linear between the rows on either side, as "
    f"final success is by default): IQM [95% CI] from {stats.MIN_SEEDS_FOR_CI} seeds on, else the mean (the seeds' "
    "range, n). The first three are evaluations on the report's tasks: the share of plans without a "
    "collision, of goals the agent reached along its plan with collisions allowed, and the agent's "
    "success without a plan. The rest are the training traversals' (the iteration's sub-tasks; K is the "
    "tree's finest layer): sub-task success, after a reached and after a missed sub-task (a low second "
    "figure: one miss costs the rest of a traversal), and the new sub-goals placed inside obstacles and "
    "the segments longer than one sub-task can cover (the planner asking for what the agent cannot do)."
)


def final_text(final_evaluations: int | None, short: bool = False) -> str:
    """How the page's "final" was computed, in words (the comparison's rule, or --final-evaluations K);
    `short`: one clause, for a look at one seed each."""
    if short:
        if final_evaluations is None:
            return "Final = the success at the env-step budget, linear between the evaluations on either side"
        return (
            f"Final = the mean of the last {final_evaluations} evaluations due at or before the env-step budget "
            f"(--final-evaluations {final_evaluations})"
        )
    if final_evaluations is None:
        return (
            "Final = each seed's success at the env-step budget (stop.env_steps, the same for every method "
            "of a comparison), linear between its evaluations on either side; a seed whose evaluations end "
            "before it (still running) or a sweep without one: its last evaluation; one first evaluated "
            "after it: its first. Not simply the last evaluation: a trial stops at the first iteration end "
            "past the budget, so long iterations would buy extra env steps."
        )
    last = (
        "each seed's last evaluation"
        if final_evaluations == 1
        else f"the mean of each seed's last {final_evaluations} evaluations"
    )
    return (
        f"Final = {last} at or before the env-step budget (stop.env_steps, the same for every method of a "
        f"comparison; --final-evaluations {final_evaluations}), read at the last of them. An evaluation "
        "counts at the cadence point it was due at (eval_every_env_steps): it runs at the end of the first "
        "iteration past its point, so the one due at the budget runs a little after it and is the "
        "evaluation at the budget; none due after it counts. A seed with fewer such evaluations has no "
        "final (named under Missing); a sweep without a budget: its last ones. Not the curve at the budget (the "
        "report's default)."
    )


# The test tasks' figures beside the sweep's own console: said on the console and the page, since the same
# runs' summary table and progress lines show the validation tasks' and their figures differ.
TEST_BESIDE_VALIDATION = (
    "the sweep's summary table and progress lines show the validation tasks' figures of the same runs"
)


def summary_text(
    configs: list[ConfigSummary],
    tasks: str,
    tasks_why: str,
    reps: int | None = None,
    final_evaluations: int | None = None,
) -> str:
    windows = []
    for metric, short in tables.SHORT.items():
        m = next((c.metrics[metric] for c in configs if metric in c.metrics), None)
        if m is not None:
            lo, hi = m.auc_window
            windows.append(f"{short} [{lo:,.0f}, {hi:,.0f}]" if np.isfinite(lo) else f"{short}: none")
    which = (
        f"Validation tasks only ({tasks_why}). "
        if tasks == VALIDATION
        else f"Test tasks only ({TEST_BESIDE_VALIDATION}). "
    )
    if one_seed_each(configs):
        return (
            one_seed_words(configs)
            + f" {which}"
            + final_text(final_evaluations, short=True)
            + "; AUC = the area under the success curve over the env steps "
            + (", ".join(windows) or "none")
            + ", divided by their length; steps to a threshold = the first evaluation at or above it."
        )
    return (
        which + final_text(final_evaluations) + " Rows that only repeat an earlier "
        "evaluation are left out everywhere. AUC = area under each seed's success curve, linear between "
        "evaluations, over one env-step window for every configuration (from the latest first evaluation "
        "to the earliest last evaluation among the finished seeds, and at the budget at the latest: no "
        "success is assumed before an evaluation or after a seed's last; a seed that does not cover it, "
        "e.g. one still running, has "
        "no AUC), divided by its length; windows: "
        + (", ".join(windows) or "none")
        + f". No best-over-evaluations figure. With >= {stats.MIN_SEEDS_FOR_CI} seeds: IQM over seeds "
        "(inter-quartile mean) and 95% CI = percentile bootstrap over seeds (one env per experiment, so "
        "the stratified bootstrap resamples seeds within the configuration), "
        + bootstrap_words(reps)
        + "; with fewer: the mean and the "
        "range over the seeds, no CI. Steps to a threshold = first evaluation at or above it, IQM (mean "
        "with fewer than 5 seeds) over seeds counting a seed that never got there as infinitely late, so "
        "'not reached' means that figure is infinite; (k/n) = seeds that reached it. Env steps: mean over "
        "seeds at the last result. Privileges: from the runs' tags ('-': runs older than the tag): "
        + "; ".join(f"{k} = {v}" for k, v in DESCRIPTIONS.items())
        + "; collision checks, resets, map queries: cumulative counts, mean over seeds ('-': not logged), "
        "each seed's read where its final success is read (at the same evaluations, weighted alike: a "
        "method that checks only inside evaluations counts those of the evaluations its final comes "
        "from, and no later one). FAILED/KILLED runs are excluded; RUNNING runs count with what they have "
        "so far. A configuration is one algorithm, config key, env and env config: seeds are pooled only "
        "within it."
    )


def one_seed_words(configs: list[ConfigSummary]) -> str:
    """The opening of a one-seed report: one configuration or several; a demo, or a sweep that has not
    got further yet (some of its runs have no figures: they failed, or have not evaluated yet)."""
    waiting = sum(len(c.all_trials) - c.n_seeds for c in configs)
    if len(configs) == 1:
        head = "One configuration, one seed with evaluations: a look at how the run went"
    else:
        head = "One seed per configuration: a look at how the runs went"
    head += ", not a comparison (no spread, no confidence interval, no probability of improvement"
    if waiting:
        return (
            head + f"). The sweep is incomplete: {waiting} more run(s) without figures yet (or unfinished), "
            "listed under Missing; its comparison needs "
            f"{stats.MIN_SEEDS_FOR_CI} seeds or more per configuration."
        )
    return head + (
        f": a comparison runs {stats.MIN_SEEDS_FOR_CI} seeds or more, as sweeps/fair_maze.yaml does)."
    )


def highest_line(configs: list[ConfigSummary], tasks: str) -> str | None:
    """Which configuration has the highest final success (the summary's point estimate: IQM from 5 seeds
    on, else the mean), ties all named; beside a rule that reads it (docs/depth_k), not a ranking: the
    intervals and the probability of improvement say whether it is separated from the rest."""
    from .aggregate import headline_metric

    metric = headline_metric(configs)
    have = [c for c in configs if metric in c.metrics and np.isfinite(c.metrics[metric].final.point)]
    if len(have) < 2:
        return None
    top = max(c.metrics[metric].final.point for c in have)
    best = [c for c in have if c.metrics[metric].final.point == top]
    what = best[0].metrics[metric].final.estimator
    names = " and ".join(c.label for c in best)
    return (
        f"Highest final {tasks} success ({what}, the table's point estimate): {names}, {top:.3f}"
        + (" (tied)" if len(best) > 1 else "")
        + ". The highest point is not a separation: the intervals and the probability of improvement say "
        "whether it stands apart."
    )


DETAILS_TEXT = (
    "Details: one row per configuration and success metric it logged. success = what every method "
    "reports (CO-PILOT, SoRB and the RRT* curriculum: the agent following its plan; SAC, HER, PPO: the agent "
    "alone); planned = the agent following the planner's finest path (SoRB: its graph's waypoints); direct = "
    "the agent alone. The RRT* curriculum (rrt_curriculum) and SoRB with the map (sorb_map) ask the map on "
    "the evaluation tasks themselves (RRT* plans each task; SoRB checks each task's start and goal edges), "
    "counted in their collision checks; CO-PILOT's plans come from its learned planner. A row named 'success = "
    "planned' (or '= direct') stands for metrics that agree in every figure. Steps to a threshold and "
    "wall time as above; final at = the env step the final success is read at (mean over seeds)."
)


def document(
    sweep,
    configs,
    missing: Missing,
    axes_shown,
    figs,
    tree_figs,
    frame,
    notes,
    left_out,
    provenance,
    below,
    tasks_why: str,
    reps: int | None = None,
    final_evaluations: int | None = None,
):
    statuses: dict[str, int] = {}
    for t in sweep.trials:
        statuses[t.status] = statuses.get(t.status, 0) + 1
    seeds = "; ".join(f"{c.label}: {c.n_seeds}" for c in configs)
    doc: list[tuple] = [("h1", f"Sweep report: {sweep.experiment}"), ("h2", "Provenance"), ("ul", provenance)]
    doc.append(
        (
            "ul",
            [
                f"sweep: {sweep.sweep_name}; parent run: {sweep.parent_run_id or '(none)'}",
                f"trials: {len(sweep.trials)} ({', '.join(f'{n} {s}' for s, n in sorted(statuses.items()))}); "
                f"configurations: {len(configs)}; varying: {axes_shown}",
                f"seeds with evaluations per configuration: {seeds}",
                f"every run's metrics: {METRICS_CSV}",
            ],
        )
    )
    if sweep.other_parent_ids:
        notes.append(
            "Other sweep runs in this experiment (use --parent-run): " + ", ".join(sweep.other_parent_ids)
        )
    doc.append(("h2", "Missing or incomplete"))
    doc.append(
        ("ul", missing.lines() + notes)
        if not missing.empty() or notes
        else ("p", "Nothing missing: every trial finished with evaluations.")
    )
    if left_out:
        doc.append(("h2", "Left out of the figures"))
        doc.append(("ul", left_out))
    doc.append(("h2", "Summary"))
    doc.append(("p", summary_text(configs, sweep.tasks, tasks_why, reps, final_evaluations)))
    doc.append(("table", tables.headline_table(frame)))
    if not one_seed_each(configs) and (top := highest_line(configs, sweep.tasks)):
        doc.append(("p", top))
    details = tables.details_table(frame)
    if details.rows:
        doc.append(("h3", "Details by success metric"))
        doc.append(("p", DETAILS_TEXT))
        doc.append(("table", details))
    doc += below
    for title, path, *caption in figs + tree_figs:
        doc.append(("h2", title))
        doc.append(("img", path.name, title))
        if caption and caption[0]:
            doc.append(("p", caption[0]))
    return doc


def to_markdown(doc) -> str:
    out = []
    for block in doc:
        kind = block[0]
        if kind in HEADINGS:
            out.append(f"{'#' * HEADINGS[kind]} {block[1]}\n")
        elif kind == "p":
            out.append(block[1] + "\n")
        elif kind == "ul":
            out.append("\n".join(f"- {item}" for item in block[1]) + "\n")
        elif kind == "table":
            out.append(block[1].markdown())
        elif kind == "img":
            out.append(f"![{block[2]}]({block[1]})\n")
    return "\n".join(out)


HEADINGS = {"h1": 1, "h2": 2, "h3": 3}
# Tables fit the page: small type, the full width, cells that wrap between words (a long word breaks only
# where it would overflow).
HTML_STYLE = (
    "body{font-family:sans-serif;max-width:1200px;margin:auto;padding:0 12px;line-height:1.4}"
    "table{border-collapse:collapse;font-size:12px;width:100%;table-layout:auto;margin:8px 0 16px}"
    "td,th{border:1px solid #ccc;padding:3px 6px;vertical-align:top;overflow-wrap:break-word}"
    "th{background:#f2f2f2;text-align:left;font-weight:600}"
    "tr:nth-child(even) td{background:#fafafa}"
    "p,li{font-size:14px}img{max-width:100%;height:auto}"
)


def to_html(doc, title: str) -> str:
    body = []
    for block in doc:
        kind = block[0]
        if kind in HEADINGS or kind == "p":
            body.append(f"<{kind}>{html.escape(block[1])}</{kind}>")
        elif kind == "ul":
            body.append("<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in block[1]) + "</ul>")
        elif kind == "table":
            body.append(block[1].html())
        elif kind == "img":
            body.append(f'<img src="{html.escape(block[1])}" alt="{html.escape(block[2])}">')
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{HTML_STYLE}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )


def bootstrap_words(reps: int | None, pairs: bool = False) -> str:
    """How the report's intervals were resampled, in words."""
    if reps is not None:
        return f"{reps:,} resamples drawn (--bootstrap-reps)"
    what = "every pair of resamples of the two sides" if pairs else "every resample of the seeds"
    return (
        f"exact: {what} enumerated (5 seeds: all 5^5 = 3,125 per side) up to 8 seeds, "
        f"{stats.MC_REPS:,} resamples drawn beyond"
    )
