"""muscle-rally's musculoskeletal table-tennis environments for Python, stepped in Rust.

    import muscle_rally
    env = muscle_rally.make("SingleServe-v0", method="kmac")           # a gymnasium.Env
    envs = muscle_rally.make_vec("SingleServe-v0", num_envs=64)         # a gymnasium VectorEnv
    rally = muscle_rally.rally.parallel_env(method="kmac")             # a PettingZoo ParallelEnv

The environments are the ones ``rally train`` steps (same reward, episode ends and controllers; the
same seed gives the same episode). Also registered with gymnasium: ``gymnasium.make("muscle_rally/
SingleServe-v0", method=...)``.
"""

from __future__ import annotations

import gymnasium as gym

from ._core import __version__, checkpoint_from_onnx
from .envs import METHODS, SERVES, SingleServeEnv, SingleServeVectorEnv

def __getattr__(name):
    # The rally needs PettingZoo (pip install muscle-rally[pettingzoo]); imported when asked for.
    if name == "rally":
        import importlib

        return importlib.import_module(".rally", __name__)
    raise AttributeError(name)


__all__ = ["make", "make_vec", "checkpoint_from_onnx", "SingleServeEnv", "SingleServeVectorEnv",
           "METHODS", "SERVES", "__version__"]

_ENVS = {"SingleServe-v0": (SingleServeEnv, SingleServeVectorEnv)}


def _lookup(env_id: str):
    try:
        return _ENVS[env_id]
    except KeyError:
        raise ValueError(f"env_id: '{env_id}': one of {', '.join(_ENVS)}") from None


def make(env_id: str = "SingleServe-v0", **kwargs) -> gym.Env:
    """One environment: ``method`` (kmac, muscle, muscle-pd, dynsyn), ``serve`` (p2, rally, stroke),
    ``model`` (default, myochallenge after ``rally model import myosuite``, or an MJCF file),
    ``config`` (a ``rally train`` configuration file)."""
    return _lookup(env_id)[0](**kwargs)


def make_vec(env_id: str = "SingleServe-v0", num_envs: int = 16, **kwargs):
    """``num_envs`` environments stepped together in Rust (same arguments as ``make``)."""
    return _lookup(env_id)[1](num_envs=num_envs, **kwargs)


if "muscle_rally/SingleServe-v0" not in gym.registry:
    gym.register(id="muscle_rally/SingleServe-v0", entry_point="muscle_rally.envs:SingleServeEnv")
