"""The sweep spec: a small YAML file, validated before anything starts, and the trial plan built from it.

    name: depth_k                       # required; also the folder under `tracking.storage`
    experiment: copilot-depth-k         # MLflow experiment (default: name)
    description: Fig. 2b, K = 1..6
    env: {id: maze-point, config: {layout: four-rooms}}
    algorithm: copilot                  # copilot | sac | her | sorb | ppo | rrt_star | sgt_pg (the registry)
    config:                             # fixed settings: flat, dotted keys (the algorithm's SETTINGS)
      repetitions: 5
      planner.std: 0.05
      alpha_schedule: paper_per_task    # a preset name or a mapping
    variants:                           # optional, grid only: named fixed overrides of `config`, one
      paper: {preset: paper_literal}    #   configuration each (an ablation: one reading per variant)
      restart: {after_failure: restart}
    search:                             # parameter -> one domain (same dotted keys as `config`)
      tree_depth: {grid: [1, 2, 3, 4, 5, 6]}
    seeds: [0, 1, 2]                    # every configuration runs once per seed
    seeds_per_trial: 3                  # optional (default 1): seeds trained together in one trial (grid,
                                        #   num_env_runners 0; the SAC-agent methods), their SAC updates
                                        #   stacked into one on every device; each seed its own MLflow run
    searcher: {type: grid}              # or {type: optuna, sampler: tpe, metric: ..., mode: max, ...}
    scheduler: {type: asha, max_t: 200000, grace_period: 20000, reduction_factor: 3}   # optional
    stop: {env_steps: 200000}           # and/or iterations
    resources: {max_concurrent_trials: 2, num_env_runners: 0}   # cpus_per_trial >= 1 + num_env_runners;
                                        # gpus_per_trial (default 0; 0.25 shares a GPU): the RLlib learner's
    fault_tolerance: {checkpoint_every: 1, max_failures: 2}   # optional: checkpoints, retries of a trial
    tracking: {storage: results/}       # uri default: sqlite:///<abs storage>/<name>/mlflow.db

Stacked seeds (``seeds_per_trial`` > 1): ``seeds`` is cut into consecutive groups of that size, one Tune
trial per group and configuration (``copilot_ray.algorithms.sac.trial``). The seeds step in one loop:
one batched forward pass per env step and one stacked SAC update per round, on every device, and each
seed trains exactly as its one-seed trial. Each seed's figures, MLflow run, tags, checkpoint folder and
failure are its own, so ``stages``, ``best_of``, ``progress``, ``carry`` and the report read a stacked
sweep as an unstacked one. What Tune's scheduler and a stop criterion see of a stacked trial: the mean
over its live seeds of every metric (NaN while none has measured it, as a one-seed trial reports a
figure before its first evaluation), except env steps, the fewest of any seed still running. A seed whose
iteration raises stops alone (its run FAILED with the error) and is not retried.

``env.id`` may be a list: every configuration runs on each env (trial param ``env.id``, grid only). A file
may hold several specs as YAML documents separated by ``---`` (``load_specs``), each complete and with its
own ``name``: the sweep runner validates them all, then runs them one after another. That is how one file
compares algorithms (a Tune experiment runs one algorithm); give them one ``experiment`` so that MLflow
and the analysis see them side by side.

Search domains: ``{grid: [...]}``, ``{int: [low, high], log: false, step: 1}`` (both ends inclusive),
``{float: [low, high], log: false}`` (``step`` allowed when not log), ``{categorical: [...]}``. A
categorical domain may carry ``when: {choice: {param: domain, ...}}``: those parameters exist only in
trials that drew ``choice`` (they may nest). The alpha schedule is searched that way::

    alpha_schedule.kind:
      categorical: [constant, linear, exponential]
      when:
        constant: {alpha_schedule.alpha: {float: [0.0, 1.0]}}
        linear: {alpha_schedule.start: {float: [0.5, 1.0]}, alpha_schedule.end: {float: [0.0, 0.5]}}

Decisions:

* Strict types, no coercion: ``"5"`` is never an int, ``5.0`` is not an int, ``true`` is not a number;
  an int is accepted where a float is expected. YAML 1.1 reads ``1e-3`` as a *string*; the loader here
  resolves it as a float, as a reader expects. Duplicate YAML keys are an error (PyYAML silently keeps
  the last one).
* ``searcher: grid`` needs every domain to be ``grid``; ``optuna`` rejects ``grid`` (use
  ``categorical``): Tune's OptunaSearch cannot take ``tune.grid_search`` and a silent translation would
  hide that the sweep is no longer exhaustive. ``when`` is only allowed on ``categorical``, so grid sweeps
  stay a plain cartesian product (search whole ``alpha_schedule`` values to grid over schedules).
* Alpha schedule keys: ``alpha_schedule`` is a preset name or a full mapping; ``alpha_schedule.<field>``
  sets one field (the fields of ``copilot_ray.planning.alpha_schedule.AlphaSchedule``: kind, clock,
  alpha, start, end, duration, decay, boundaries, values). When ``alpha_schedule.kind`` is set (fixed or
  sampled), the schedule is built from the dotted fields alone; otherwise the dotted fields override
  ``alpha_schedule`` (or CoPilotConfig's default ``paper_per_task``). Setting both ``alpha_schedule`` and
  ``alpha_schedule.kind`` is rejected.
* ``variants`` are a grid axis of their own (trial param ``variant``): every variant runs every grid
  point and seed; a variant's keys override ``config`` and may not be searched. They exist because a
  cartesian grid cannot say "the defaults, and each reading back to the paper's one at a time".
* The searched space stays flat (ray issue 28753): a trial's parameters are a flat dict of dotted keys
  plus ``seed``; ``build_algorithm_config(flat, spec)`` turns it into the RLlib config.
* Optuna and seeds: Tune's searchers cannot repeat one sampled configuration over seeds, so an optuna
  sweep is ``len(seeds)`` studies of ``num_samples`` trials each (the sweep runner runs one Tuner per
  seed, sampler seed = ``searcher.seed + index``); ``trial_plan()`` returns placeholders for them.
* Nothing here imports Ray at module level; ``ray.tune`` is imported inside the ``to_tune_*`` functions
  only, and the algorithm's config class in ``build_algorithm_config``. A
  rejected spec has imported no Ray. Validation builds the env once (``copilot_ray.envs.make``), which imports numpy/torch.
* Relative ``tracking.storage`` is resolved against the working directory at load time (the default
  store lives in the working directory).

Modules: ``errors`` (what a failed validation says), ``yaml_loader``, ``models`` (the schema and its
checks, ``build_algorithm_config``), ``plan`` (``--check``'s text), ``tune_translation`` (Tune and Optuna
objects).
"""

from copilot_ray.sweep_spec.errors import SpecError
from copilot_ray.sweep_spec.loading import load_spec, load_specs, parse_spec
from copilot_ray.sweep_spec.models import SweepSpec, build_algorithm_config, metric_known
from copilot_ray.sweep_spec.plan import default_point, format_plan
from copilot_ray.sweep_spec.sections import ParamSearch
from copilot_ray.sweep_spec.tune_translation import (
    optuna_define_by_run,
    to_tune_scheduler,
    to_tune_search_space,
    tune_stop,
)
from copilot_ray.sweep_spec.yaml_loader import SpecLoader, load_yaml_value, read_yaml_file

__all__ = [
    "ParamSearch",
    "SpecError",
    "SpecLoader",
    "SweepSpec",
    "build_algorithm_config",
    "default_point",
    "format_plan",
    "load_spec",
    "load_specs",
    "load_yaml_value",
    "metric_known",
    "optuna_define_by_run",
    "parse_spec",
    "read_yaml_file",
    "to_tune_scheduler",
    "to_tune_search_space",
    "tune_stop",
]
