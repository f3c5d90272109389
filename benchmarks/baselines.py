"""The RL baselines' own targets: each learns a problem it should solve, and HER's relabelling does not
slow the learner down.

    PYTHONPATH=. .venv/bin/python benchmarks/baselines.py demo    [--seeds 0 1]
    PYTHONPATH=. .venv/bin/python benchmarks/baselines.py speed   [--updates 512 --repeats 5]
    PYTHONPATH=. .venv/bin/python benchmarks/baselines.py search  --checkpoint TRIAL_DIR/checkpoint_N

search: SoRB's search on a trained HER (or SAC) checkpoint (e.g. the last one of a `her` trial of
`sweeps/baselines_maze.yaml`): the same agent and replay, the test tasks followed with the graph's
waypoints and alone, for several graph sizes and edge cutoffs (`--graph-sizes`, `--cutoffs`).

demo: SAC, HER, SoRB and PPO on the demo's open maze (`sweeps/demo.yaml`'s env: no walls, speed 0.05,
success radius 0.1, 40 steps per task), each for its own env-step budget (the off-policy agents 4k, as
the demo's CO-PILOT; PPO, on-policy, 60k), test success on 50 held-out tasks after every evaluation.
Targets: HER and SoRB >= 0.8, PPO > 0.3 at the end of their budgets. Prints one line per evaluation and
a table.

speed: gradient steps per second of the learner behind SAC (CO-PILOT's flat buffer), HER and SoRB
(the relabelling buffer), each on its own algorithm's replay after the same two iterations of sampling
on four-rooms, the same `updates_per_call` path; repeats are interleaved and the medians compared.
Target: HER and SoRB within 10 % of SAC.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

import numpy as np  # noqa: E402

from copilot_ray import keys  # noqa: E402

OPEN_MAZE = {"layout": "empty", "speed": 0.05, "success_radius": 0.1}
AGENT = {"tau_max": 40, "eval_num_tasks": 50}


def _off_policy(kind: str, seed: int, eval_interval: int):
    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig, HERConfig
    from copilot_ray.algorithms.sorb.algorithm import SoRBConfig

    cls = {"sac": GoalSACConfig, "her": HERConfig, "sorb": SoRBConfig}[kind]
    config = (
        cls()
        .environment("maze-point", env_config=OPEN_MAZE)
        .agent(task_batch_size=8, eval_interval=eval_interval, **AGENT)
        .training(num_steps_sampled_before_learning_starts=500)
        .debugging(seed=seed)
    )
    if kind == "sorb":
        config.search(pretrain_env_steps=1000, graph_size=300, max_edge_steps=5, waypoint_steps=10)
    return config


def _ppo(seed: int, eval_interval: int):
    from copilot_ray.algorithms.ppo.algorithm import GoalPPOConfig

    return (
        GoalPPOConfig()
        .environment("maze-point", env_config=OPEN_MAZE)
        .goal_task(eval_interval=eval_interval, **AGENT)
        .debugging(seed=seed)
    )


def demo(seeds: list[int]) -> None:
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    budgets = {"sac": 4000, "her": 4000, "sorb": 4000, "ppo": 60_000}
    rows = []
    for kind, budget in budgets.items():
        for seed in seeds:
            config = _ppo(seed, 2) if kind == "ppo" else _off_policy(kind, seed, 2)
            algo = config.build_algo()
            t0, steps, curve = time.perf_counter(), 0, []
            while steps < budget:
                result = algo.train()
                steps = int(keys.result_value(result, keys.ENV_STEPS, 0))
                success = keys.result_value(result, keys.EVAL_SUCCESS, float("nan"))
                if not np.isnan(success):
                    curve.append((steps, success))
                    print(f"{kind:5s} seed {seed}  env steps {steps:6d}  success {success:.2f}", flush=True)
            algo.stop()
            first_08 = next((s for s, v in curve if v >= 0.8), None)
            rows.append(
                (
                    kind,
                    seed,
                    steps,
                    curve[-1][1] if curve else float("nan"),
                    first_08,
                    time.perf_counter() - t0,
                )
            )
    ray.shutdown()
    print("\n| method | seed | env steps | final success | first >= 0.8 at | wall |")
    print("|---|---|---|---|---|---|")
    for kind, seed, steps, final, first, wall in rows:
        print(f"| {kind} | {seed} | {steps:,} | {final:.2f} | {first if first else 'never'} | {wall:.0f} s |")


def speed(updates: int, repeats: int) -> None:
    import ray
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    algos = {}
    for kind in ("sac", "her", "sorb"):
        config = _off_policy(kind, 0, 0).environment("maze-point", env_config={"layout": "four-rooms"})
        # Sampling only: the updates are timed below (learning would start after 10^9 steps).
        config.agent(tau_max=800, task_batch_size=4).training(num_steps_sampled_before_learning_starts=10**9)
        algo = config.build_algo()
        for _ in range(2):
            algo.train()
        algos[kind] = algo
        print(
            f"{kind}: {len(algo.agent_updater.buffer)} transitions in {type(algo.agent_updater.buffer).__name__}"
        )
    timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: 0}
    rates: dict[str, list[float]] = {kind: [] for kind in algos}
    for algo in algos.values():  # warm-up
        algo.agent_updater.update(64, timesteps)
    for r in range(repeats):
        for kind, algo in algos.items():
            t0 = time.perf_counter()
            algo.agent_updater.update(updates, timesteps)
            rates[kind].append(updates / (time.perf_counter() - t0))
        print(f"repeat {r}: " + "  ".join(f"{k} {v[-1]:.0f}/s" for k, v in rates.items()), flush=True)
    # The buffers alone: one learner call's sample (16 gradient steps x 256 rows), relabelling included.
    sample_ms = {}
    for kind, algo in algos.items():
        rng = np.random.default_rng(0)
        t0 = time.perf_counter()
        for _ in range(200):
            algo.agent_updater.buffer.sample(16 * 256, rng)
        sample_ms[kind] = (time.perf_counter() - t0) / 200 * 1e3
    for algo in algos.values():
        algo.stop()
    ray.shutdown()
    print("\nsample of 4096 transitions: " + ", ".join(f"{k} {v:.2f} ms" for k, v in sample_ms.items()))
    base = statistics.median(rates["sac"])
    print("\n| learner | updates/s (median) | vs SAC |")
    print("|---|---|---|")
    for kind, values in rates.items():
        print(f"| {kind} | {statistics.median(values):.0f} | {statistics.median(values) / base:.3f} |")


def search(
    checkpoint: str, graph_sizes: list[int], cutoffs: list[int], waypoint_steps: int, tasks: int
) -> None:
    """SoRB's search on a trained HER (or SAC, SoRB) checkpoint: the same agent, replay and test tasks,
    followed with and without the graph, for several graph sizes and edge cutoffs."""
    import ray

    from copilot_ray.algorithms.sorb.algorithm import SoRBConfig
    from copilot_ray.evaluation import ModulePolicy, evaluate_copilot

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    # The trial's own config (env, settings) as it ran, rebuilt as SoRB's.
    from ray.rllib.algorithms.algorithm import Algorithm

    trained = Algorithm.from_checkpoint(checkpoint)
    old = trained.config
    config = SoRBConfig().environment(old.goal_env, env_config=old.goal_env_config)
    config.agent(**{k: getattr(old, k) for k in ("tau_max", "agent_input", "reward_scale")})
    config.training(gamma=old.gamma).debugging(seed=old.seed)
    state = trained.get_state()
    trained.stop()
    algo = config.build_algo()
    algo.set_state(state)
    n = min(tasks, len(algo.test_starts))
    policy = {"deterministic": ModulePolicy(algo.get_module())}
    print(
        f"{checkpoint}: {len(algo.agent_updater.buffer)} transitions, {n} test tasks, tau_max {config.tau_max}"
    )
    print(
        "| graph size | max edge steps | edges | waypoints | success with search (reached) "
        "| agent alone (reached) | paths touching no wall | graph s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for size in graph_sizes:
        for cutoff in cutoffs:
            # The built config is frozen; its search settings are a dict read at each evaluation.
            algo.config.sorb.update(
                pretrain_env_steps=0, graph_size=size, max_edge_steps=cutoff, waypoint_steps=waypoint_steps
            )
            t0 = time.perf_counter()
            plan = algo._evaluation_plan(n)
            graph_s = time.perf_counter() - t0
            result = evaluate_copilot(
                goal_env_id=algo.config.goal_env,
                goal_env_config=algo.config.goal_env_config,
                policies=policy,
                starts=algo.test_starts[:n],
                goals=algo.test_goals[:n],
                depth=0,
                tau_max=config.tau_max,
                with_delta=config.agent_input == "state_goal_delta",
                **plan,
            )
            r = result.by_action["deterministic"]
            print(
                f"| {size} | {cutoff} | {plan['planner'].graph.num_edges} | {plan['planner'].mean_waypoints:.1f} | "
                f"{r['success_planned']:.2f} ({r['reached_planned']:.2f}) | "
                f"{r['success_direct']:.2f} ({r['reached_direct']:.2f}) | {result.plan_collision_free:.2f} | "
                f"{graph_s:.1f} |",
                flush=True,
            )
    algo.stop()
    ray.shutdown()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="part", required=True)
    d = sub.add_parser("demo", help="each baseline on the open maze of the demo")
    d.add_argument("--seeds", type=int, nargs="+", default=[0])
    s = sub.add_parser("speed", help="learner updates/s: SAC vs HER vs SoRB")
    s.add_argument("--updates", type=int, default=512)
    s.add_argument("--repeats", type=int, default=5)
    c = sub.add_parser("search", help="SoRB's search on a trained checkpoint, for several graphs")
    c.add_argument("--checkpoint", required=True)
    c.add_argument("--graph-sizes", type=int, nargs="+", default=[500])
    c.add_argument("--cutoffs", type=int, nargs="+", default=[25, 50, 100])
    c.add_argument("--waypoint-steps", type=int, default=100)
    c.add_argument("--tasks", type=int, default=100)
    args = parser.parse_args(argv)
    if args.part == "demo":
        demo(args.seeds)
    elif args.part == "speed":
        speed(args.updates, args.repeats)
    else:
        search(args.checkpoint, args.graph_sizes, args.cutoffs, args.waypoint_steps, args.tasks)


if __name__ == "__main__":
    main()
