"""What the MLflow link a sweep prints opens: the experiment's trials as rows, grouped by configuration
(its algorithm and config key: `CONFIGURATION_TAG`; averaged over seeds, every group open), with the swept settings and the
headline figures as columns, and the chart view narrowed to success against env steps, one line per
configuration.

MLflow 3 keeps such a page as a "shared view": the experiment tag `mlflow.sharedViewState.<key>` holds the
page's state as JSON, and `#/experiments/<id>?viewStateShareKey=<key>` opens it; without one, a first
visit shows the parent runs collapsed and no metric column. `workflowType=machine_learning` in the
address keeps MLflow 3.17's UI on its model-training pages (its GenAI / model-training switch does not
read the experiment's `mlflow.experimentKind` tag, which tracking.py sets all the same). Every part of a
sweep file that writes into one experiment adds its own configurations and columns to the same view
(`trials_view(..., earlier=...)`). Standard library only.
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


def trials_view(
    configurations: Iterable[tuple[str, str]] | None,
    columns: Iterable[str],
    chart_metrics: Iterable[str],
    earlier: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The view's state. `configurations`: (algorithm, config key) of every configuration, known before
    the trials run (a grid); None for a search, whose configurations are drawn as it goes: its trials
    are rows of their own, ungrouped. `columns` (`column(...)`): after the run name and the algorithm;
    `chart_metrics`: what the chart view shows (whichever a run logged). `earlier`: the view an earlier
    part of the file wrote, whose columns, groups and charts are kept."""
    earlier = dict(earlier or {})
    selected = [*earlier.get("selectedColumns", []), *columns]
    selected = list(dict.fromkeys(selected))
    charts = [*earlier.get("chartsSearchFilter", "^()$")[2:-2].split("|"), *chart_metrics]
    charts = [c for c in dict.fromkeys(charts) if c]
    grouped = configurations is not None and (not earlier or earlier.get("groupBy") is not None)
    expanded = {
        **earlier.get("groupsExpanded", {}),
        **{group_id(a, k): True for a, k in configurations or ()},
    }
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
        # the swept settings first, then the figures, wide enough for a configuration's name and a
        # metric's (MLflow's default widths cut both; it applies widths to the columns ordered here)
        "columnOrder": [
            RUN_NAME_COLUMN,
            *sorted(selected, key=lambda c: not c.startswith(("params.", "tags."))),
        ],
        "columnWidths": {RUN_NAME_COLUMN: 280, **{c: 180 for c in selected if c.startswith("metrics.")}},
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
        "chartsSearchFilter": f"^({'|'.join(charts)})$",
        "viewMaximized": False,
        "runListHidden": False,
        "isAccordionReordered": False,
        "globalLineChartConfig": {"xAxisKey": "step", "lineSmoothness": 0, "selectedXAxisMetricKey": ""},
    }


def encode(view: Mapping[str, Any]) -> str:
    return json.dumps(view, separators=(",", ":"))


def decode(text: str | None) -> dict[str, Any] | None:
    """An earlier view's state, or None (none, or one MLflow's own UI wrote compressed)."""
    try:
        return json.loads(text) if text else None
    except ValueError:
        return None
