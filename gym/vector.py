"""Many Memory games as one Gymnasium vector environment, stepped as arrays on the same core.

Rule: `num_envs` games (core/games.py) step together, one suggestion each per
step: no processes, no Python loop over games (but over the few whose round
ended, to fill a rich final_obs game by game). It is a SyncVectorEnv of
MemoryEnvs with autoreset SAME_STEP (its metadata's), to the info layout:
game i of `reset(seed=s)` is MemoryEnv's `reset(seed=s + i)` (or seed list[i]),
`reset()` deals every game's next round as MemoryEnv's `reset()` does; a game
whose round ends returns its next round's first observation at once, the
ended round's last observation in info["final_obs"] (an object array), its
step info in info["final_info"] and the new round's reset info ("round") at
the top level; a game whose round goes on has its step info ("picks",
"learned", "matched", "considered", "consistent") at the top level; every key
has its mask "_key". New games without a seed draw their seeds from this env's
one generator (SyncVectorEnv: one per game). Input goes through gym/checks.py,
the single env's checks. `persona` is one key for every game or one per game.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from pairplay.core.actions import N_ACTIONS
from pairplay.core.games import MemoryGames, Outcome
from pairplay.core.geometry import NOT_ONE_CARD_STATE
from pairplay.schemas.config import DEFAULT_REWARD_BONUS

from . import checks
from .env import STEP_INFO, observation_space, render_nothing, rich_observations


class MemoryVectorEnv(VectorEnv):
    """`num_envs` games of the task at once; see the module rule."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": list(checks.RENDER_MODES)}

    def __init__(self, num_envs: int = 1, persona: str | Sequence[str] = "tatiana",
                 reward_bonus: str = DEFAULT_REWARD_BONUS, observation: str = "state",
                 observed_source: str = "intended", render_mode: str | None = None):
        self.num_envs = num_envs = checks.num_envs(num_envs)
        checks.env_options(reward_bonus, observation, observed_source, render_mode)
        self.personas = checks.personas(persona, num_envs)
        self.reward_bonus = reward_bonus
        self.render_mode = render_mode
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
        if seeds is not None and not isinstance(seed, (list, tuple, np.ndarray)):
            super().reset(seed=seeds[0])  # Gymnasium's: an int seed seeds the env's own generator
        if new_persona is not None:
            self.personas = [new_persona] * self.num_envs
        if seeds is None and new_persona is None and self._games is not None:
            self._games.new_round(self._games.rows)  # each game's next round, as MemoryEnv's reset() deals it
        else:
            if seeds is None:  # new games: MemoryEnv draws a random game seed, each from its own generator
                seeds = [int(s) for s in self.np_random.integers(2 ** 63, size=self.num_envs)]
            self._games = MemoryGames(self.personas, seeds, self.observed_source, self.reward_bonus)
        states = self._games.observe()
        return self._obs(states, self._games.turn), {"round": self._games.deal_index.copy(),
                                                     "_round": np.ones(self.num_envs, dtype=bool)}

    def step(self, actions):
        if self._games is None:
            raise RuntimeError("call reset() first")
        checks.action(self.action_space, actions)
        out = self._games.act(np.asarray(actions, dtype=np.int64))
        over = out.round_over
        # SyncVectorEnv's layout (SAME_STEP): a game's step info at the top level where its round goes on;
        # where it ended, that info in final_info, its last observation in final_obs and its new round's
        # reset info ("round") at the top level. Each key has its mask "_key"; values outside it are 0.
        info = _masked(out, ~over) if not over.all() else {}
        if over.any():
            ended = np.nonzero(over)[0]
            info["final_obs"], info["_final_obs"] = self._final_obs(ended), over.copy()
            info["final_info"], info["_final_info"] = _masked(out, over), over.copy()
            self._games.new_round(ended)
            info["round"], info["_round"] = np.where(over, self._games.deal_index, 0), over.copy()
        states = self._games.observe()
        return (self._obs(states, self._games.turn), out.rewards.astype(np.float64), over.copy(),
                np.zeros(self.num_envs, dtype=bool), info)

    def render(self) -> None:
        return render_nothing()

    def _final_obs(self, ended: np.ndarray) -> np.ndarray:
        """(num_envs,) object array, Gymnasium's final_obs: each ended game's terminal observation, None elsewhere."""
        final = np.full(self.num_envs, None, dtype=object)
        if self.observation == "state":
            final[ended] = int(NOT_ONE_CARD_STATE)
        else:
            rows = self._obs(np.full(ended.size, NOT_ONE_CARD_STATE, dtype=np.int64), None)
            for game, row in zip(ended, rows):  # one array per game, as the single env's: numpy cannot assign them at once
                final[game] = row
        return final


def _masked(out: Outcome, mask: np.ndarray) -> dict[str, np.ndarray]:
    """MemoryEnv's step info (STEP_INFO) of the games in `mask`, batched as Gymnasium batches infos."""
    info: dict[str, np.ndarray] = {}
    for key, kind in STEP_INFO.items():  # a product, not np.where: a third of the time at 2,048 games
        info[key] = np.multiply(getattr(out, key), mask, dtype=np.int64 if kind is int else np.bool_)
        info["_" + key] = mask.copy()
    return info
