"""The gymnasium faces of the Rust environments: one robot returning serves (``SingleServeEnv``) and
many of them stepped together in Rust (``SingleServeVectorEnv``).

Both sit on ``muscle_rally._core.VecEnv``: the environments ``rally train`` steps (its reward, its
episode ends, its controllers), built from a method and a ``rally train`` configuration file. An
episode seeded ``s`` here is the episode ``rally train`` plays from seed ``s``.
"""

from __future__ import annotations

import operator
from typing import Any, Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv

from ._core import VecEnv as _Core

METHODS = ("kmac", "muscle", "muscle-pd", "dynsyn")
SERVES = ("p2", "p1", "rally", "stroke")
_SEED_SPAN = 2**63


def _integer(name: str, x: Any, lo: int, hi: int) -> int:
    """``x`` as an int in [lo, hi) (numpy integers too), else a ValueError naming ``name``."""
    try:
        v = operator.index(x)
    except TypeError:
        raise ValueError(f"{name}: {x!r}: an integer") from None
    if not lo <= v < hi:
        raise ValueError(f"{name}: {x!r}: {lo} <= {name} < {hi}")
    return v


def _core(method: str, num_envs: int, model: str, config, serve: str, env: str) -> _Core:
    if method not in METHODS:
        raise ValueError(f"method: '{method}': one of {', '.join(METHODS)}")
    if serve not in SERVES:
        raise ValueError(f"serve: '{serve}': one of {', '.join(SERVES)}")
    num_envs = _integer("num_envs", num_envs, 1, 2**20)
    return _Core(method, num_envs, model, None if config is None else str(config), serve, env)


class _Buffers:
    """The arrays the Rust side writes into, allocated once."""

    def __init__(self, core: _Core):
        rows = core.num_envs * core.agents
        self.obs = np.zeros((rows, core.obs_dim), dtype=np.float64)
        self.rewards = np.zeros(rows, dtype=np.float64)
        self.terminated = np.zeros(rows, dtype=np.bool_)
        self.truncated = np.zeros(rows, dtype=np.bool_)
        self.hit = np.zeros(rows, dtype=np.bool_)
        self.success = np.zeros(rows, dtype=np.bool_)
        self.term_names = list(core.reward_term_names)
        self.terms = np.zeros((rows, len(self.term_names)), dtype=np.float64)

    def step(self, core: _Core, actions: np.ndarray) -> None:
        core.step(actions, self.obs, self.rewards, self.terminated, self.truncated, self.hit,
                  self.success, self.terms)

    def reward_terms(self, row: int) -> dict[str, float]:
        """What each reward term added to row ``row``'s reward (they sum to it)."""
        return {n: float(x) for n, x in zip(self.term_names, self.terms[row])}


def _actions(action: Any, rows: int, width: int) -> np.ndarray:
    a = np.ascontiguousarray(action, dtype=np.float64)
    if a.size != rows * width:
        raise ValueError(f"action: {a.shape} given; {rows} x {width} entries expected")
    return a.reshape(rows, width)


class SingleServeEnv(gym.Env):
    """One robot, one serve, one stroke: the paper's single-serve task (its §IV-B).

    Observation: ``obs_dim`` float64 entries named by ``observation_names`` (joint angles and
    velocities, activations, muscle lengths, ball, paddle, the planner's command); not normalised.
    Action: ``act_dim`` entries in [-1, 1] named by ``action_names``, turned into muscle controls by
    the method's controller (K-MAC: joint targets; Muscle-PPO: every muscle's control; Muscle-PD:
    muscle-length targets; DynSyn: synergy weights; Muscle-PPO and Muscle-PD also drive the two
    pelvis servos). ``info``: ``hit`` and ``success`` (so far in the episode) and
    ``reward_terms``, what each of the reward's terms (``reward_term_names``, the ``[reward]`` keys
    of a ``rally train`` configuration) added to the step's reward, weighted: they sum to it.
    """

    metadata = {"render_modes": []}

    def __init__(self, method: str = "kmac", serve: str = "p2", model: str = "default",
                 config: Optional[str] = None):
        self._core = _core(method, 1, model, config, serve, "single")
        self._buf = _Buffers(self._core)
        self.observation_space = spaces.Box(-np.inf, np.inf, (self._core.obs_dim,), np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, (self._core.act_dim,), np.float64)
        self.observation_names = list(self._core.observation_names)
        self.action_names = list(self._core.action_names)
        self.reward_term_names = list(self._core.reward_term_names)
        self.method, self.model = self._core.method, self._core.model
        self._started = False

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            seed = _integer("seed", seed, 0, 2**64)
        super().reset(seed=seed)
        episode = seed if seed is not None else int(self.np_random.integers(_SEED_SPAN))
        self._core.reset(0, episode, self._buf.obs)
        self._started = True
        return self._buf.obs[0].copy(), {"seed": episode}

    def step(self, action):
        if not self._started:
            raise ResetNeeded("step: call reset() first")
        self._buf.step(self._core, _actions(action, 1, self._core.act_dim))
        b = self._buf
        info = {"hit": bool(b.hit[0]), "success": bool(b.success[0]),
                "reward_terms": b.reward_terms(0)}
        return (b.obs[0].copy(), float(b.rewards[0]), bool(b.terminated[0]),
                bool(b.truncated[0]), info)


class SingleServeVectorEnv(VectorEnv):
    """``num_envs`` single-serve environments stepped together in Rust, on every core, with the GIL
    released. Autoreset in the same step (gymnasium's ``AutoresetMode.SAME_STEP``): an episode that
    ends is followed at once by the next, whose first observation is returned; the last one is in
    ``infos["final_obs"]`` (rows where ``infos["_final_obs"]`` is true). Episode seeds: ``seed + i``
    for environment ``i`` at ``reset(seed=...)``, then drawn from the vector's own generator.
    ``infos``: ``hit`` and ``success`` (arrays; for an environment that just started again, its new
    episode's), ``reward_terms`` (an array per term name: what it added to each environment's
    returned reward); for the episodes that ended, ``final_obs`` and ``final_info`` (their last
    ``hit`` and ``success``), gymnasium's ``_``-prefixed masks saying which rows hold them.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, method: str = "kmac", num_envs: int = 16, serve: str = "p2",
                 model: str = "default", config: Optional[str] = None):
        self._core = _core(method, num_envs, model, config, serve, "single")
        self._buf = _Buffers(self._core)
        self.num_envs = self._core.num_envs
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (self._core.obs_dim,),
                                                   np.float64)
        self.single_action_space = spaces.Box(-1.0, 1.0, (self._core.act_dim,), np.float64)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space,
                                                              self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)
        self.observation_names = list(self._core.observation_names)
        self.action_names = list(self._core.action_names)
        self.reward_term_names = list(self._core.reward_term_names)
        self._rng = np.random.default_rng()
        self._started = False

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            seed = _integer("seed", seed, 0, 2**64 - self.num_envs + 1)
            self._rng = np.random.default_rng(seed)
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = [int(s) for s in self._rng.integers(_SEED_SPAN, size=self.num_envs)]
        for i, s in enumerate(seeds):
            self._core.reset(i, s, self._buf.obs[i:i + 1])
        self._started = True
        return self._buf.obs.copy(), {"seed": np.array(seeds, dtype=np.uint64)}

    def step(self, actions):
        if not self._started:
            raise ResetNeeded("step: call reset() first")
        b = self._buf
        b.step(self._core, _actions(actions, self.num_envs, self._core.act_dim))
        obs, hit, success = b.obs.copy(), b.hit.copy(), b.success.copy()
        every = np.ones(self.num_envs, dtype=np.bool_)
        infos: dict[str, Any] = {
            "hit": hit, "_hit": every, "success": success, "_success": every,
            "reward_terms": {n: b.terms[:, k].copy() for k, n in enumerate(b.term_names)},
            "_reward_terms": every,
        }
        done = b.terminated | b.truncated
        if done.any():
            infos["final_obs"] = np.where(done[:, None], obs, 0.0)
            infos["_final_obs"] = done.copy()
            infos["final_info"] = {"hit": hit & done, "_hit": done.copy(),
                                   "success": success & done, "_success": done.copy()}
            infos["_final_info"] = done.copy()
            infos["hit"], infos["success"] = hit & ~done, success & ~done
            for i in np.flatnonzero(done):
                self._core.reset(int(i), int(self._rng.integers(_SEED_SPAN)),
                                 b.obs[i:i + 1])
                obs[i] = b.obs[i]
        return obs, b.rewards.copy(), b.terminated.copy(), b.truncated.copy(), infos
