"""The env registry: ids, errors and Ray registration (with a stand-in ray module: no ray import)."""

import sys
import types

import gymnasium as gym
import pytest

from copilot_ray import envs


def test_make_known_id():
    env = envs.make("maze-point", layout="empty")
    assert isinstance(env, gym.Env)
    assert "maze-point" in envs.env_ids()


def test_unknown_id_names_it_and_the_known_ones():
    with pytest.raises(envs.UnknownEnvError) as err:
        envs.make("maze-pointy")
    assert isinstance(err.value, ValueError)
    assert "'maze-pointy'" in str(err.value) and "maze-point" in str(err.value).split("known ids:")[1]


def test_register_with_ray(monkeypatch):
    registered = {}
    registry = types.ModuleType("ray.tune.registry")
    registry.register_env = lambda name, creator: registered.__setitem__(name, creator)
    ray, tune = types.ModuleType("ray"), types.ModuleType("ray.tune")
    ray.tune, tune.registry = tune, registry
    monkeypatch.setitem(sys.modules, "ray", ray)
    monkeypatch.setitem(sys.modules, "ray.tune", tune)
    monkeypatch.setitem(sys.modules, "ray.tune.registry", registry)

    envs.register_with_ray()
    assert set(registered) == set(envs.env_ids())

    class EnvContext(dict):
        worker_index = 1

    env = registered["maze-point"](EnvContext(layout="u-maze"))
    assert env.unwrapped.layout.name == "u-maze"
    assert registered["maze-point"]({}).unwrapped.layout.name == "four-rooms"
