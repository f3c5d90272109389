"""What the MLflow link a sweep prints opens: the experiment's trials as rows, grouped by configuration
(its algorithm and config key: `CONFIGURATION_TAG`; averaged over seeds, every group open), with the swept
settings and the headline figures as columns, each as wide as its header, and the chart view narrowed to
one full-width section per figure it draws (success against env steps, one line per configuration).

MLflow 3 keeps such a page as a "shared view": the experiment tag `mlflow.sharedViewState.<key>` holds the
page's state as JSON, and `#/experiments/<id>/runs?viewStateShareKey=<key>` opens it; without one, a first
visit shows the parent runs collapsed and no metric column. `workflowType=machine_learning` in the
address keeps MLflow 3.17's UI on its model-training pages (its links inside the UI drop it; the page
copilot_ray.mlflow_app serves keeps them there). Every part of a sweep file that writes into one
experiment adds its own configurations, columns and charts to the same view (`trials_view(...,
earlier=...)`).

The chart: MLflow draws a group's line as the mean over its runs at each step where they logged; our runs
log at step = env steps, which differ from seed to seed (iterations end where they end), so the raw mean
zigzags from one seed's value to another's. The lines are smoothed (MLflow's own line smoothing,
`LINE_SMOOTHING`), the raw values faint behind. Its x axis is MLflow's "Step", which is env steps here:
the section's title says so. (MLflow can put a metric on the x axis, `env_runners/...lifetime`, but it
pairs the two metrics' sampled histories and dropped the last 15% of SoRB's and HER's curves on the
privilege-matched store.) Standard library only.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

from copilot_ray.keys import CONFIGURATION_TAG, ROLE_TAG, ROLE_TRIAL

VIEW_KEY = "trials"
VIEW_TAG = f"mlflow.sharedViewState.{VIEW_KEY}"
TABLE, CHART = "TABLE", "CHART"
RUN_NAME = "tags.`mlflow.runName`"  # the run name's sort key in MLflow's runs table
RUN_NAME_COLUMN = "attributes.`Run Name`"  # and its column


def column(kind: str, name: str) -> str:
    """A column of MLflow's runs table: kind "params", "metrics", "tags" or "attributes"."""
    return f"{kind}.`{name}`"


def configuration(algorithm: str, config_key: str) -> str:
    """One configuration of an experiment, as its trial runs' CONFIGURATION_TAG says it."""
    return f"{algorithm} {config_key}"


def group_id(algorithm: str, config_key: str) -> str:
    """The runs table's id of the group of one configuration's seeds (grouped by CONFIGURATION_TAG)."""
    return f"tag.{CONFIGURATION_TAG}.{configuration(algorithm, config_key)}"


def page(experiment_id: str, mode: str = TABLE) -> str:
    """The fragment of the UI's address that opens the experiment's runs on the view (TABLE or CHART).
    (MLflow 3.17 applies a shared view on the runs page only, not on the experiment's own address.)"""
    return (
        f"#/experiments/{experiment_id}/runs?viewStateShareKey={VIEW_KEY}&compareRunsMode={mode}"
        "&workflowType=machine_learning"
    )


# A column's width in MLflow's runs table, from its header (12 px semi-bold; the sort mark and padding
# after it) or, for the run name, its longest group label ("Group: <configuration>", the expander, the
# colour dot and the count before and after it). Estimates: MLflow has no width-to-fit in a view.
HEADER_PX_PER_CHAR, HEADER_PAD_PX, MIN_SETTING_PX, MIN_SEED_PX = 6.6, 36, 120, 100
NAME_PX_PER_CHAR, NAME_PAD_PX, MIN_NAME_PX, SEARCH_NAME_PX = 6.0, 80, 220, 280
# The chart view: one section per figure, one chart per section, full width and tall enough to read.
CHART_HEIGHT_PX, LINE_SMOOTHING = 480, 95
STEP_IS_ENV_STEPS = "Step = env steps"


def column_name(col: str) -> str:
    """What a column's header says: the name between the backquotes (`metrics.<a/b>` -> `a/b`)."""
    return col.split(".", 1)[1].strip("`")


def column_width(col: str) -> int:
    """How wide `col` needs to be for its header not to be cut (a setting's values: at least MIN_...)."""
    width = round(HEADER_PX_PER_CHAR * len(column_name(col))) + HEADER_PAD_PX
    if col.startswith("metrics."):
        return width
    return max(width, MIN_SEED_PX if column_name(col) == "seed" else MIN_SETTING_PX)


def name_width(configurations: Iterable[tuple[str, str]] | None) -> int:
    """The run name column's width: its longest group label's, or SEARCH_NAME_PX for a search's runs."""
    if configurations is None:
        return SEARCH_NAME_PX
    labels = [f"Group: {configuration(a, k)}" for a, k in configurations]
    return max(MIN_NAME_PX, *(round(NAME_PX_PER_CHAR * len(t)) + NAME_PAD_PX for t in labels))


def _chart_id(kind: str, metric: str) -> str:
    return f"copilot-{kind}-" + "".join(c if c.isalnum() else "-" for c in metric)


def chart_sections(metrics: Iterable[str]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The chart view's sections and charts: for each metric a section of its own ("<metric> against env
    steps (Step = env steps)"), holding its line chart against MLflow's step (env steps), full width."""
    sections, charts = [], []
    for metric in metrics:
        section = _chart_id("section", metric)
        sections.append(
            {
                "uuid": section,
                "name": f"{metric} ({STEP_IS_ENV_STEPS})",
                "display": True,
                "isReordered": True,
                "deleted": False,
                "isGenerated": False,
                "columns": 1,
                "cardHeight": CHART_HEIGHT_PX,
            }
        )
        charts.append(
            {
                "uuid": _chart_id("chart", metric),
                "type": "LINE",
                "metricSectionId": section,
                "metricKey": metric,
                "selectedMetricKeys": [metric],
                "displayName": metric,
                "deleted": False,
                "isGenerated": False,
                "runsCountToCompare": 100,
                "xAxisKey": "step",
                "selectedXAxisMetricKey": "",
                "useGlobalXaxisKey": False,
                "xAxisScaleType": "linear",
                "scaleType": "linear",
                "range": {},  # (as MLflow saves its unset range)
                "lineSmoothness": LINE_SMOOTHING,
                "useGlobalLineSmoothing": False,
                "yAxisKey": "metric",
                "yAxisExpressions": [],
                "ignoreOutliers": False,
            }
        )
    return sections, charts


def trials_view(
    configurations: Iterable[tuple[str, str]] | None,
    columns: Iterable[str],
    chart_metrics: Iterable[str],
    earlier: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The view's state. `configurations`: (algorithm, config key) of every configuration, known before
    the trials run (a grid); None for a search, whose configurations are drawn as it goes: its trials
    are rows of their own, ungrouped. `columns` (`column(...)`): after the run name and the algorithm;
    `chart_metrics`: what the chart view draws (each a section: metrics its runs log, else the section
    would stand empty). `earlier`: the view an earlier part of the file wrote, whose columns, groups and
    charts are kept."""
    configurations = None if configurations is None else list(configurations)
    earlier = dict(earlier or {})
    selected = [*earlier.get("selectedColumns", []), *columns]
    selected = list(dict.fromkeys(selected))
    charts = [*earlier.get("chartsSearchFilter", "^()$")[2:-2].split("|"), *chart_metrics]
    charts = [c for c in dict.fromkeys(charts) if c]
    sections, cards = chart_sections(charts)
    grouped = configurations is not None and (not earlier or earlier.get("groupBy") is not None)
    expanded = {
        **earlier.get("groupsExpanded", {}),
        **{group_id(a, k): True for a, k in configurations or ()},
    }
    names = max(name_width(configurations), earlier.get("columnWidths", {}).get(RUN_NAME_COLUMN, 0))
    return {
        # search facets: the trials only (the parent runs hold each sweep's summary), by name
        "searchFilter": f"tags.`{ROLE_TAG}` = '{ROLE_TRIAL}'",
        "orderByKey": RUN_NAME,
        "orderByAsc": True,
        "startTime": "ALL",
        "lifecycleFilter": "Active",
        "modelVersionFilter": "All Runs",
        "datasetsFilter": [],
        # the page
        "selectedColumns": selected,
        # the swept settings first, then the figures, each as wide as its header (MLflow's default
        # widths cut them; it applies widths to the columns ordered here)
        "columnOrder": [
            RUN_NAME_COLUMN,
            *sorted(selected, key=lambda c: not c.startswith(("params.", "tags."))),
        ],
        "columnWidths": {RUN_NAME_COLUMN: names, **{c: column_width(c) for c in selected}},
        "runsHiddenMode": "SHOW_ALL",  # every trial in the charts, not the first 10
        "groupBy": (
            {
                "aggregateFunction": "average",
                "groupByKeys": [{"mode": "tag", "groupByData": CONFIGURATION_TAG}],
            }
            if grouped
            else None
        ),
        "groupsExpanded": expanded if grouped else {},
        "useGroupedValuesInCharts": True,
        "hideEmptyCharts": True,
        # the charts: ours only (MLflow adds one per other metric; the filter leaves them out)
        "compareRunSections": sections,
        "compareRunCharts": cards,
        "chartsSearchFilter": f"^({'|'.join(charts)})$",
        "viewMaximized": False,
        "runListHidden": False,
        "isAccordionReordered": True,  # the sections in the order given, not MLflow's alphabetical one
        "globalLineChartConfig": {
            "xAxisKey": "step",
            "lineSmoothness": LINE_SMOOTHING,
            "selectedXAxisMetricKey": "",
        },
    }


def encode(view: Mapping[str, Any]) -> str:
    return json.dumps(view, separators=(",", ":"))


def decode(text: str | None) -> dict[str, Any] | None:
    """An earlier view's state, or None (none, or one MLflow's own UI wrote compressed)."""
    try:
        return json.loads(text) if text else None
    except ValueError:
        return None
