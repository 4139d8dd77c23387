"""Many Memory games as one Gymnasium vector environment, stepped as arrays on the same core.

Rule: `num_envs` games (core/games.py) step together, one suggestion each per
step: no Python loop over games, no processes. Game i of `reset(seed=s)` is the
game MemoryEnv plays after `reset(seed=s + i)` (Gymnasium's convention), or
seed list[i]. Autoreset is SAME_STEP: a game whose round ends returns the next
round's first observation at once, its terminal observation in
info["final_obs"] (masked by info["_final_obs"]). info also holds per game this
step's "picks", "learned", "matched", "considered", "consistent" (masks all true).
`persona` is one key for every game or one per game.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from pairplay.core.actions import N_ACTIONS
from pairplay.core.games import MemoryGames
from pairplay.core.geometry import NOT_ONE_CARD_STATE
from pairplay.core.reward import check_bonus_rule
from pairplay.schemas.config import DEFAULT_REWARD_BONUS

from . import checks
from .env import observation_space, rich_observations


class MemoryVectorEnv(VectorEnv):
    """`num_envs` games of the task at once; see the module rule."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, persona: str | Sequence[str] = "tatiana",
                 reward_bonus: str = DEFAULT_REWARD_BONUS, observation: str = "state",
                 observed_source: str = "intended"):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.num_envs = num_envs = int(num_envs)
        self.personas = checks.personas(persona, num_envs)
        self.reward_bonus = check_bonus_rule(reward_bonus)
        self.observation = observation
        self.observed_source = observed_source
        self.single_observation_space = observation_space(observation)
        self.single_action_space = spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._games: MemoryGames | None = None
        self._np_random = None

    def _obs(self, states: np.ndarray, turn: dict | None):
        if self.observation == "state":
            return states.astype(np.int64)
        return rich_observations(states, turn)

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None):
        seeds = checks.reset_seeds(seed, self.num_envs)
        new_persona = checks.reset_options(options)
        if new_persona is not None:
            self.personas = [new_persona] * self.num_envs
        if seeds is None:
            if self._np_random is None:
                self._np_random, _ = seeding.np_random(None)
            seeds = [int(s) for s in self._np_random.integers(2 ** 63, size=self.num_envs)]
        elif not isinstance(seed, (list, tuple, np.ndarray)):
            self._np_random, _ = seeding.np_random(seeds[0])
        self._games = MemoryGames(self.personas, seeds, self.observed_source, self.reward_bonus)
        states = self._games.observe()
        return self._obs(states, self._games.turn), {}

    def step(self, actions):
        if self._games is None:
            raise RuntimeError("call reset() first")
        checks.action(self.action_space, actions)
        out = self._games.act(np.asarray(actions, dtype=np.int64))
        ones = np.ones(self.num_envs, dtype=bool)
        info: dict[str, Any] = {}
        for key in ("picks", "learned", "matched", "considered", "consistent"):
            info[key], info["_" + key] = getattr(out, key), ones
        over = out.round_over
        if over.any():
            terminal = np.full(self.num_envs, NOT_ONE_CARD_STATE, dtype=np.int64)
            final = self._obs(terminal, None)
            info["final_obs"], info["_final_obs"] = final, over.copy()
            self._games.new_round(np.nonzero(over)[0])
        states = self._games.observe()
        return (self._obs(states, self._games.turn), out.rewards.astype(np.float64), over.copy(),
                np.zeros(self.num_envs, dtype=bool), info)
