"""The dual-robot rally as a PettingZoo ``ParallelEnv``: robots ``"a"`` and ``"b"`` face each other
across the table, each observing in its own frame and acting in [-1, 1] through the method's
controller; the paper's rally task (its §IV-C). The environment is ``rally train --env rally``'s:
a rally serve, the rules, the rally reward for each robot. ``infos[agent]``: ``hit`` (this robot
has touched the ball in the rally's current exchange) and ``success`` (a legal return by this robot
in this step) and ``reward_terms`` (what each reward term added to its reward).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from pettingzoo import ParallelEnv

from .envs import _actions, _Buffers, _core, _integer, _SEED_SPAN


class RallyParallelEnv(ParallelEnv):
    metadata = {"render_modes": [], "name": "muscle_rally_rally_v0"}

    def __init__(self, method: str = "kmac", model: str = "default", config: Optional[str] = None):
        self._core = _core(method, 1, model, config, "rally", "rally")
        self._buf = _Buffers(self._core)
        self.possible_agents = ["a", "b"]
        self.agents = []
        obs = spaces.Box(-np.inf, np.inf, (self._core.obs_dim,), np.float64)
        act = spaces.Box(-1.0, 1.0, (self._core.act_dim,), np.float64)
        self.observation_spaces = {a: obs for a in self.possible_agents}
        self.action_spaces = {a: act for a in self.possible_agents}
        self.observation_names = list(self._core.observation_names)
        self.action_names = list(self._core.action_names)
        self.reward_term_names = list(self._core.reward_term_names)
        self._rng = np.random.default_rng()

    def observation_space(self, agent):
        return self.observation_spaces[agent]

    def action_space(self, agent):
        return self.action_spaces[agent]

    def reset(self, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            episode = _integer("seed", seed, 0, 2**64)
            self._rng = np.random.default_rng(episode)
        else:
            episode = int(self._rng.integers(_SEED_SPAN))
        self._core.reset(0, episode, self._buf.obs)
        self.agents = list(self.possible_agents)
        obs = {a: self._buf.obs[i].copy() for i, a in enumerate(self.possible_agents)}
        return obs, {a: {"seed": episode} for a in self.possible_agents}

    def step(self, actions):
        if not self.agents:
            raise ResetNeeded("step: the rally is over (or not started); call reset()")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions: no action for {', '.join(missing)}")
        rows = np.stack([_actions(actions[a], 1, self._core.act_dim)[0]
                         for a in self.possible_agents])
        b = self._buf
        b.step(self._core, rows)
        names = self.possible_agents
        obs = {a: b.obs[i].copy() for i, a in enumerate(names)}
        rewards = {a: float(b.rewards[i]) for i, a in enumerate(names)}
        terms = {a: bool(b.terminated[i]) for i, a in enumerate(names)}
        truncs = {a: bool(b.truncated[i]) for i, a in enumerate(names)}
        infos = {a: {"hit": bool(b.hit[i]), "success": bool(b.success[i]),
                     "reward_terms": b.reward_terms(i)}
                 for i, a in enumerate(names)}
        if any(terms.values()) or any(truncs.values()):
            self.agents = []
        return obs, rewards, terms, truncs, infos


def parallel_env(**kwargs) -> RallyParallelEnv:
    """The rally (same arguments as ``muscle_rally.make``, less ``serve``)."""
    return RallyParallelEnv(**kwargs)
