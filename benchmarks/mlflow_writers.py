"""Does one SQLite MLflow store keep every metric row when many processes write to it at once?

    PYTHONPATH=. python benchmarks/mlflow_writers.py [--writers 16] [--results 200] [--metrics 60]

Within one sweep every MLflow write comes from the driver (the Tune callback, one writer however many
trials run), so concurrency reaches the store only when several sweeps (or `train` runs, or people)
share one SQLite file. Each writer process here does what `TrialRuns` does per trial result: one
`log_batch` of `--metrics` rows per result, `--results` results, into its own run of one experiment, all
writers started together. Afterwards the rows in the store are counted against the rows sent; a writer
whose call raised (SQLite's "database is locked") is counted too. Prints rows expected / stored / lost
and the writers' wall time.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import tempfile
import time
from pathlib import Path


def _write(uri: str, experiment_id: str, index: int, results: int, metrics: int, start, out) -> None:
    from mlflow.entities import Metric
    from mlflow.tracking import MlflowClient

    client = MlflowClient(uri)
    run_id = client.create_run(experiment_id, run_name=f"writer-{index}").info.run_id
    failures = 0
    start.wait()
    t0 = time.perf_counter()
    for step in range(results):
        now = int(time.time() * 1000)
        rows = [Metric(f"copilot/m{j}", float(step + j), now, step) for j in range(metrics)]
        try:
            client.log_batch(run_id, metrics=rows)
        except Exception:  # noqa: BLE001 - counted: a lost batch is what this measures
            failures += 1
    out.put((run_id, failures, time.perf_counter() - t0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--writers", type=int, default=16)
    parser.add_argument("--results", type=int, default=200, help="log_batch calls per writer")
    parser.add_argument("--metrics", type=int, default=60, help="metric rows per call")
    args = parser.parse_args()
    from mlflow.tracking import MlflowClient

    with tempfile.TemporaryDirectory() as tmp:
        uri = f"sqlite:///{Path(tmp) / 'mlflow.db'}"
        client = MlflowClient(uri)
        experiment_id = client.create_experiment("writers")
        ctx = mp.get_context("spawn")
        start, out = ctx.Event(), ctx.Queue()
        procs = [
            ctx.Process(target=_write, args=(uri, experiment_id, i, args.results, args.metrics, start, out))
            for i in range(args.writers)
        ]
        for p in procs:
            p.start()
        time.sleep(5.0)  # every writer has imported MLflow and created its run
        start.set()
        done = [out.get() for _ in procs]
        for p in procs:
            p.join()
        stored = sum(
            len(client.get_metric_history(run_id, f"copilot/m{j}"))
            for run_id, _, _ in done
            for j in range(args.metrics)
        )
    expected = args.writers * args.results * args.metrics
    failed_calls = sum(f for _, f, _ in done)
    wall = max(w for _, _, w in done)
    print(
        f"command: PYTHONPATH=. python benchmarks/mlflow_writers.py --writers {args.writers} "
        f"--results {args.results} --metrics {args.metrics}"
    )
    print(
        f"{args.writers} writers x {args.results} log_batch calls x {args.metrics} rows into one SQLite store"
    )
    print(
        f"rows expected {expected:,}  stored {stored:,}  lost {expected - stored:,}  "
        f"failed calls {failed_calls}  writers' wall {wall:.1f} s ({expected / wall:,.0f} rows/s)"
    )


if __name__ == "__main__":
    main()
