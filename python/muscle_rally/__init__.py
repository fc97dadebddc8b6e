"""muscle-rally's musculoskeletal table-tennis environments for Python, stepped in Rust.

    import muscle_rally
    env = muscle_rally.make("SingleServe-v0", method="kmac")           # a gymnasium.Env
    envs = muscle_rally.make_vec("SingleServe-v0", num_envs=64)         # a gymnasium VectorEnv
    rally = muscle_rally.rally.parallel_env(method="kmac")             # a PettingZoo ParallelEnv
    report = muscle_rally.evaluate("mine.json", episodes=1000, seed=7)  # rally eval's numbers

The environments are the ones ``rally train`` steps (same reward, episode ends and controllers; the
same seed gives the same episode). Also registered with gymnasium: ``gymnasium.make("muscle_rally/
SingleServe-v0", method=...)``.
"""

from __future__ import annotations

import json
import os
from typing import Any

import gymnasium as gym
import numpy as np

from . import _core
from ._core import __version__, checkpoint_from_onnx
from .envs import METHODS, SERVES, SingleServeEnv, SingleServeVectorEnv, _integer

def __getattr__(name):
    # The rally needs PettingZoo (pip install muscle-rally[pettingzoo]); imported when asked for.
    if name == "rally":
        import importlib

        return importlib.import_module(".rally", __name__)
    raise AttributeError(name)


__all__ = ["make", "make_vec", "evaluate", "checkpoint_from_onnx", "SingleServeEnv", "SingleServeVectorEnv",
           "METHODS", "SERVES", "__version__"]

_ENVS = {"SingleServe-v0": (SingleServeEnv, SingleServeVectorEnv)}


def _lookup(env_id: str):
    try:
        return _ENVS[env_id]
    except KeyError:
        raise ValueError(f"env_id: '{env_id}': one of {', '.join(_ENVS)}") from None


def make(env_id: str = "SingleServe-v0", **kwargs) -> gym.Env:
    """One environment: ``method`` (kmac, muscle, muscle-pd, dynsyn), ``serve`` (p2, p1, rally, stroke),
    ``model`` (default, myochallenge after ``rally model import myosuite``, or an MJCF file),
    ``config`` (a ``rally train`` configuration file)."""
    return _lookup(env_id)[0](**kwargs)


def make_vec(env_id: str = "SingleServe-v0", num_envs: int = 16, **kwargs):
    """``num_envs`` environments stepped together in Rust (same arguments as ``make``)."""
    return _lookup(env_id)[1](num_envs=num_envs, **kwargs)


if "muscle_rally/SingleServe-v0" not in gym.registry:
    gym.register(id="muscle_rally/SingleServe-v0", entry_point="muscle_rally.envs:SingleServeEnv",
                 vector_entry_point="muscle_rally.envs:SingleServeVectorEnv")


def evaluate(agent: str | os.PathLike, episodes: int = 100, seed: int = 0, serve: str = "p2",
             model: str = "default", mean_action: bool = False, trace: bool = False
             ) -> dict[str, Any]:
    """``rally eval``, from Python (the same Rust function): ``agent`` (a scripted variant, a
    built-in checkpoint's name or a checkpoint file) on ``episodes`` single serves of ``serve`` from
    ``seed``, on every core. Returns ``rally eval --json``'s report (hit and success rates, effort,
    mean activation, each with its 95% interval). With ``trace`` (at most 100 episodes),
    ``report["trace"]`` holds every control step as arrays: ``episode``, ``step``, ``time``, the
    ``observation`` the network was given (before the checkpoint's normalisation), its ``action``
    (the mean, before noise and the controller) and the muscle ``controls``."""
    episodes = _integer("episodes", episodes, 1, 100_001)
    seed = _integer("seed", seed, 0, 2**64)
    text, steps = _core.evaluate(os.fspath(agent), episodes, seed, serve, model, bool(mean_action),
                                 bool(trace))
    report = json.loads(text)
    if trace:
        cols = list(zip(*steps)) if steps else [()] * 6
        report["trace"] = {
            "episode": np.array(cols[0], dtype=np.int64),
            "step": np.array(cols[1], dtype=np.int64),
            "time": np.array(cols[2], dtype=np.float64),
            "observation": np.array(cols[3], dtype=np.float64),
            "action": np.array(cols[4], dtype=np.float64),
            "controls": np.array(cols[5], dtype=np.float64),
        }
    return report
