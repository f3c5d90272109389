"""An algorithm built outside Tune (the Python API, train) keeps its folder under the working
directory's results/, made only when something is written there; nothing goes to ~/ray_results."""

from __future__ import annotations

from pathlib import Path

from ray.train.constants import DEFAULT_STORAGE_PATH
from ray.tune import Trainable

from copilot_ray.algorithms import local_logdir
from copilot_ray.algorithms.local_logdir import LocalLogdir

SHIPPED = local_logdir.LOCAL_ROOT  # read at collection, before conftest's fixture moves it for a test


class _Tiny(LocalLogdir, Trainable):
    def step(self):
        return {}


def test_outside_tune_the_folder_is_under_results_and_made_only_when_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert SHIPPED == Path("results") / "rllib"  # relative: under the working directory of the build
    monkeypatch.setattr(local_logdir, "LOCAL_ROOT", SHIPPED)
    home_results = Path(DEFAULT_STORAGE_PATH)
    before = set(home_results.iterdir()) if home_results.is_dir() else set()
    first, second = _Tiny(), _Tiny()  # two builds in one second: two folders
    for built in (first, second):
        folder = Path(built.logdir)
        assert folder.parent == tmp_path / SHIPPED and folder.name.startswith("_Tiny-")
        assert not folder.exists()  # nothing written yet, nothing made
    assert first.logdir != second.logdir
    assert not (tmp_path / "results").exists()
    assert (set(home_results.iterdir()) if home_results.is_dir() else set()) == before
    first.log_to("run")  # train: the run's own folder
    assert first.logdir == str(tmp_path / "run")


def test_the_project_s_rllib_algorithms_use_it():
    from copilot_ray.algorithms.ppo.algorithm import GoalPPO
    from copilot_ray.algorithms.sac.algorithm import GoalSAC

    assert issubclass(GoalSAC, LocalLogdir) and issubclass(GoalPPO, LocalLogdir)
