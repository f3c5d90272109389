import atexit
import os
import shutil
import tempfile

import pytest

from tests import stores

os.environ.setdefault("RAY_AUTH_MODE", "disabled")
# The RRT* reference cache (copilot_ray.planning.path_metrics) of this test session, set before Ray starts
# so that trial workers see it too; never the user's ~/.cache.
os.environ["COPILOT_RAY_CACHE"] = tempfile.mkdtemp(prefix="copilot_ray_test_cache_")
atexit.register(shutil.rmtree, os.environ["COPILOT_RAY_CACHE"], True)
# MLflow's new SQLite stores in this process: copies of one store migrated once (tests/stores.py)
_STORE_TEMPLATE = tempfile.mkdtemp(prefix="copilot_ray_test_mlflow_")
atexit.register(shutil.rmtree, _STORE_TEMPLATE, True)
stores.copy_a_migrated_store_into_new_stores(_STORE_TEMPLATE)


@pytest.fixture(autouse=True)
def _local_logdirs(tmp_path_factory, monkeypatch):
    """An algorithm a test builds outside Tune keeps its folder (the planner's trees) in a temp folder of
    its own, not in the checkout's results/ (test_local_logdir checks the default itself)."""
    from copilot_ray.algorithms import local_logdir

    monkeypatch.setattr(local_logdir, "LOCAL_ROOT", tmp_path_factory.mktemp("rllib"))


@pytest.fixture(scope="session")
def ray_session():
    """One local two-core Ray for the whole test session (ARCHITECTURE.md, "Conventions")."""
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()
