"""One Memory game as a Gymnasium environment (core/games.py underneath).

Rule: an episode is one round (thesis 6.1: every turn until the board is
clear, on a new deal); a step is one suggestion. The observation is the state
the learner sees (thesis 4.1: Discrete(24)), or with `observation="rich"` a
Box of 78 values in [0, 1]: the state one-hot (24), the observed card (18),
the matching card (18) and the covered cards (18). The action is one of the
88 composite codes (thesis 4.2). The reward is the study's (4.3, 6.1.3) under
`reward_bonus`; an ignored suggestion pays 0 and says so in info["learned"].
A round ends with `terminated` and the terminal state NOT_ONE_CARD (no card is
turned). Seeding: `reset(seed=s)` starts a new game whose deal and user streams
are those of the study's game seeded s (core.rng.game_seed gives the study's
seeds), so a fixed policy played here for R episodes picks what the study's
run_games picks for that seed; `reset()` deals the next round of the same game.
The persona (appendix A) is a constructor option or `reset(options={"persona": key})`
(which starts a new game). Every option is checked when the env is made
(gym/checks.py, shared with the vector env). reset's info["round"] is the
index of the round's deal in its game, from 0 as RoundStarted.round counts (a
round abandoned by reset() counts). render_mode None is the only one: render()
draws nothing and returns None. `gymnasium.make` gives it under `EnvChecker`,
Gymnasium's passive env checker marking a check done only when the call it
checks succeeded: Gymnasium 1.4's marks the first reset checked before it
runs, so after a refused first reset (a bad seed or option) the next valid
reset skipped its checks and the first step raised a TypeError (its data-reuse
check compared against a reset it never saw): the env stayed broken.
"""

from __future__ import annotations

import copy
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from pairplay.core.actions import N_ACTIONS
from pairplay.core.games import MemoryGames
from pairplay.core.geometry import N_CARDS, N_STATES, NOT_ONE_CARD_STATE
from pairplay.schemas.config import DEFAULT_REWARD_BONUS

from . import checks

ENV_ID = "pairplay/Memory-v0"
RICH_SIZE = N_STATES + 3 * N_CARDS
# a step's info: core.games.Outcome's fields by these names, as these types (the vector env batches them)
STEP_INFO = {"picks": int, "learned": bool, "matched": bool, "considered": bool, "consistent": bool}


def observation_space(kind: str) -> spaces.Space:
    if checks.observation(kind) == "state":
        return spaces.Discrete(N_STATES)
    return spaces.Box(0.0, 1.0, (RICH_SIZE,), dtype=np.float32)


class EnvChecker(gymnasium.wrappers.PassiveEnvChecker):
    """Gymnasium's passive env checker, its first reset's and first step's checks run on the first such call
    that succeeds (module rule): a call the env refuses leaves them to the next one."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        checked = self.checked_reset
        try:
            return super().reset(seed=seed, options=options)
        except BaseException:
            self.checked_reset = checked
            raise

    def step(self, action):
        checked = self.checked_step
        try:
            return super().step(action)
        except BaseException:
            self.checked_step = checked
            raise

    @property
    def spec(self):
        """The env's spec, Gymnasium's checker off: this one stands in for it (Gymnasium's checker marks it
        on), so an env made again from `env.spec` is this one again, not under Gymnasium's too."""
        spec = self.env.spec
        if spec is None:
            return None
        spec = copy.deepcopy(spec)
        spec.disable_env_checker = True
        return spec


def checked_env(**kwargs) -> gymnasium.Env:
    """The registered entry point: a MemoryEnv under EnvChecker (the id is registered with Gymnasium's own
    checker off: this one stands in for it)."""
    return EnvChecker(MemoryEnv(**kwargs))


def render_nothing() -> None:
    """render() under render_mode None, Gymnasium's convention: nothing is drawn, None returned, and a
    warning says so (it raised NotImplementedError without a word)."""
    gymnasium.logger.warn("render() draws nothing: pairplay/Memory-v0's one render_mode is None (the board is "
                          "in the observation with observation='rich'); it returns None")


def rich_observations(states: np.ndarray, turn: dict | None) -> np.ndarray:
    """(B, 78) float32: state one-hot, observed card, matching card, covered cards; the terminal
    state alone where `turn` is None."""
    out = np.zeros((states.size, RICH_SIZE), dtype=np.float32)
    rows = np.arange(states.size)
    out[rows, states] = 1.0
    if turn is not None:
        out[rows, N_STATES + turn["observed"]] = 1.0
        out[rows, N_STATES + N_CARDS + turn["match"]] = 1.0
        bits = (turn["covered"][:, None] >> np.arange(N_CARDS)) & 1
        out[:, N_STATES + 2 * N_CARDS:] = bits
    return out


class MemoryEnv(gymnasium.Env):
    """The task for one simulated user; see the module rule."""

    metadata = {"render_modes": list(checks.RENDER_MODES)}

    def __init__(self, persona: str = "tatiana", reward_bonus: str = DEFAULT_REWARD_BONUS,
                 observation: str = "state", observed_source: str = "intended", render_mode: str | None = None):
        checks.env_options(reward_bonus, observation, observed_source, render_mode)
        self.persona = checks.persona(persona)
        self.reward_bonus = reward_bonus
        self.render_mode = render_mode
        self.observation = observation
        self.observed_source = observed_source
        self.observation_space = observation_space(observation)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self._games: MemoryGames | None = None
        self._open = False

    def _obs(self, state: int, terminal: bool = False):
        if self.observation == "state":
            return int(state)
        turn = None if terminal else self._games.turn
        return rich_observations(np.array([state]), turn)[0]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        seed = checks.reset_seed(seed)  # before Gymnasium's, which takes any int >= 0
        new_persona = checks.reset_options(options)
        super().reset(seed=seed)
        if new_persona is not None:
            self.persona = new_persona
        if seed is not None or self._games is None or new_persona is not None:
            game_seed = int(seed) if seed is not None else int(self.np_random.integers(2 ** 63))
            self._games = MemoryGames([self.persona], [game_seed], self.observed_source, self.reward_bonus)
        else:
            self._games.new_round(np.array([0]))
        state = int(self._games.observe()[0])
        self._open = True
        return self._obs(state), {"round": int(self._games.deal_index[0])}

    def render(self) -> None:
        return render_nothing()

    def step(self, action):
        if not self._open:
            raise RuntimeError("the round is over (or never started): call reset()")
        checks.action(self.action_space, action)
        out = self._games.act(np.array([int(action)]))
        info = {key: kind(getattr(out, key)[0]) for key, kind in STEP_INFO.items()}
        terminated = bool(out.round_over[0])
        if terminated:
            self._open = False
            obs = self._obs(NOT_ONE_CARD_STATE, terminal=True)
        else:
            obs = self._obs(int(self._games.observe()[0]))
        return obs, float(out.rewards[0]), terminated, False, info
