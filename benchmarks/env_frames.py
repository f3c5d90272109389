"""Frames of the MuJoCo Ant maze and the three stump-track walkers, for the docs (off-screen rendering).

    MUJOCO_GL=egl PYTHONPATH=. python benchmarks/env_frames.py [--out docs/frames]

Writes `ant_maze.png` (the U-maze from above: the Ant at a test task's start, the goal and a path of
sub-goals as markers) and `walkers.png` (the short-, default- and long-legged walkers at the start of
one stump track, with sub-goals along it). MuJoCo needs an OpenGL backend chosen before it is imported:
MUJOCO_GL=egl (set here when unset) or osmesa; pygame draws the walkers off-screen.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from copilot_ray.envs import make  # noqa: E402
from copilot_ray.envs.stump_tracks import START_X, Track  # noqa: E402


def ant_frame(out: Path) -> Path:
    env = make("ant-maze", render_mode="rgb_array", render_size=480)
    starts, goals = env.tasks("test")
    # the test task whose straight line crosses the U's middle wall, with a path round it
    task = int(np.flatnonzero(env.segments_collide(starts, goals))[0])
    start, goal = starts[task].astype(np.float64), goals[task].astype(np.float64)
    env.reset(options={"start": start, "goal": goal})
    bend = np.array([4.0, np.sign(start[1]) * 4.0]), np.array([4.0, np.sign(goal[1]) * 4.0])
    corners = np.stack([start, *bend, goal])
    path = np.concatenate(
        [np.linspace(a, b, 5, endpoint=False) for a, b in zip(corners[:-1], corners[1:], strict=True)]
    )
    env.set_render_path(np.concatenate([path[1:], goal[None]]))
    frame = env.render()
    env.close()
    path_out = out / "ant_maze.png"
    plt.imsave(path_out, frame)
    return path_out


def walker_frames(out: Path) -> Path:
    fig, axes = plt.subplots(3, 1, figsize=(5.5, 7.5))
    track = Track(stump_height=1.0, spacing=2.0, seed=0)
    for ax, legs in zip(axes, ("short", "default", "long"), strict=True):
        env = make("walker-stumps", legs=legs, render_mode="rgb_array")
        env.reset(seed=0, options={"start": [START_X], "goal": [40.0], "track": track})
        env.set_render_path(np.array([[10.0], [15.0], [20.0]]))
        ax.imshow(env.render())
        ax.set_title(f"legs: {legs}", fontsize=10)
        ax.axis("off")
        env.close()
    fig.suptitle("walker-stumps: one track (stump height 1.0, spacing 2.0), sub-goals in orange", fontsize=10)
    fig.tight_layout()
    path_out = out / "walkers.png"
    fig.savefig(path_out, dpi=100)
    plt.close(fig)
    return path_out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/frames"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for path in (ant_frame(args.out), walker_frames(args.out)):
        print(path)


if __name__ == "__main__":
    main()
