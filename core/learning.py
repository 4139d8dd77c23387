"""The learner: online Q-learning, pi-reuse and fixed policies (thesis 5.1, 5.3).

Rule: after every suggestion the next state is the user's, where the agent does
not act, so Q(s', .) = 0 and both Q-learning and SARSA reduce to the one-step
rule of eq. 5.2, Q(s,a) += alpha * (r - Q(s,a)) (`q_update`, the one expression
every learner, rebuild and replay uses, so their tables agree bit for bit).

Action choice per suggestion, from DRAWS_PER_SUGGESTION uniforms of the "agent"
stream (always drawn, in this order: psi, epsilon, random action, tie):
- pi-reuse (algorithm 5, eq. 5.3): with probability psi the bias policy's action;
- otherwise epsilon-greedy (algorithm 1): a uniform random action with
  probability epsilon, else the greedy action, ties broken uniformly at random
  by the tie draw (never by index order alone);
- a fixed policy (the oracle, a merged policy, the user alone) just acts.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from pairplay.schemas.config import LearnerConfig

from . import kernels
from .actions import N_ACTIONS
from .geometry import N_STATES
from .rng import UniformStream

DRAWS_PER_SUGGESTION = kernels.DRAWS_PER_SUGGESTION
_INT64, _INT8 = np.dtype(np.int64), np.dtype(np.int8)  # dtype objects: np.empty converts a type each call
EPSILON, ALPHA, PSI = 0, 1, 2  # the order of schedule_tables' tables
MODES = {"q": kernels.MODE_Q, "reuse": kernels.MODE_REUSE, "fixed": kernels.MODE_FIXED}


class How(IntEnum):
    """How an action was chosen (recorded with every suggestion)."""

    GREEDY = kernels.HOW_GREEDY
    EXPLORE = kernels.HOW_EXPLORE
    BIAS = kernels.HOW_BIAS
    FIXED = kernels.HOW_FIXED


def q_update(q: np.ndarray | float, reward: np.ndarray | float, alpha: np.ndarray | float):
    """Eq. 5.2: Q + alpha * (r - Q)."""
    return q + alpha * (reward - q)


def epsilon_at(config: LearnerConfig, round_index):
    steps = np.asarray(round_index) // config.epsilon_every
    return np.maximum(config.epsilon_min, np.round(config.epsilon_start - config.epsilon_step * steps, 12))


def alpha_at(config: LearnerConfig, round_index):
    steps = np.asarray(round_index) // config.alpha_every
    return np.maximum(config.alpha_min, np.round(config.alpha_start - config.alpha_step * steps, 12))


def psi_round_start(config: LearnerConfig, round_index):
    """psi at the first suggestion of a round (algorithm 5, line 4)."""
    r = np.asarray(round_index)
    psi = config.psi_start * config.psi_round_decay ** r
    if config.reuse_rounds is not None:
        psi = np.where(r >= config.reuse_rounds, 0.0, psi)
    return psi


def greedy(q: np.ndarray, u_tie: np.ndarray) -> np.ndarray:
    """argmax over the last axis, ties broken by the draw: the floor(u*n)-th tied action."""
    q = np.asarray(q, dtype=np.float64)
    rows = np.ascontiguousarray(q.reshape(-1, 1, q.shape[-1]))
    u = np.ascontiguousarray(np.broadcast_to(np.asarray(u_tie, dtype=np.float64), q.shape[:-1])).reshape(-1)
    out = np.empty(rows.shape[0], dtype=np.int64)
    kernels.greedy_batch(rows, u, out)
    return out.reshape(q.shape[:-1])


def schedule_tables(config: LearnerConfig, rounds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(epsilon, alpha, psi at a round's start) for rounds 0..rounds-1: the schedules, computed once."""
    r = np.arange(max(rounds, 1))
    return (np.asarray(epsilon_at(config, r), dtype=np.float64), np.asarray(alpha_at(config, r), dtype=np.float64),
            np.asarray(psi_round_start(config, r), dtype=np.float64))


def greedy_policy(q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The policy a Q-table stands for: the greedy action of every state (..., S, A), ties by `rng`."""
    return greedy(q, rng.random(q.shape[:-1]))


class Learner:
    """A batch of learners, one per game.

    mode "q": Q-learning; "reuse": pi-reuse on `bias` (B, S) then Q-learning;
    "fixed": act by `policy` (B, S) and never learn.
    """

    def __init__(self, n_games: int, stream: UniformStream, config: LearnerConfig = LearnerConfig(),
                 mode: str = "q", bias: np.ndarray | None = None, policy: np.ndarray | None = None):
        if stream.role != "agent" or stream.n_games != n_games:
            raise ValueError("Learner needs an 'agent' stream with one game per learner")
        if mode not in ("q", "reuse", "fixed"):
            raise ValueError(f"unknown learner mode {mode!r}")
        if mode == "reuse" and bias is None:
            raise ValueError("pi-reuse needs a bias policy")
        if mode == "fixed" and policy is None:
            raise ValueError("a fixed learner needs a policy")
        self.stream, self.config, self.mode = stream, config, mode
        self.q = np.zeros((n_games, N_STATES, N_ACTIONS))
        self.counts = np.zeros((n_games, N_STATES, N_ACTIONS), dtype=np.int32)  # updates per (s, a)
        self.bias = None if bias is None else policy_table(bias, n_games)
        self.policy = None if policy is None else policy_table(policy, n_games)
        self.psi = np.zeros(n_games)
        self._n = n_games
        table = self.bias if mode == "reuse" else self.policy  # the action a bias or fixed policy takes
        self._table = np.zeros((n_games, N_STATES), dtype=np.int64) if table is None else np.ascontiguousarray(table)
        self._mode, self._psi_decay = MODES[mode], float(config.psi_decay)
        self._schedule = schedule_tables(config, 64)  # (epsilon, alpha, psi at a round's start): _per_round
        self._round_of_views, self._views = -1, ()
        # a batch of one's arguments and results (suggest_one, learn_one), filled in place per call
        self._one_state, self._one_action, self._one_round = (np.zeros(1, dtype=np.int64) for _ in range(3))
        self._one_how, self._one_reward, self._one_learn = np.zeros(1, _INT8), np.zeros(1), np.ones(1, dtype=bool)
        # the stream's arrays, which its draws advance in place (core/rng.py), read once for suggest_one
        self._stream_keys, self._stream_positions = stream.keys, stream.positions

    def start_round(self, round_index, games=slice(None)) -> None:
        """Reset psi for the games starting a round (algorithm 5, line 4)."""
        if isinstance(games, slice) and games == slice(None):
            self.psi[:] = self._per_round(PSI, round_index)
        else:
            self.psi[games] = psi_round_start(self.config, np.asarray(round_index)[games])

    def schedule(self, round_index: int) -> tuple[float, float]:
        """(epsilon, alpha) of round `round_index` (0-based), from the learner's tables (see `_per_round`)."""
        eps, alpha, _ = self._schedule
        r = int(round_index)
        if not 0 <= r < len(eps):
            return float(epsilon_at(self.config, r)), float(alpha_at(self.config, r))
        return float(eps[r]), float(alpha[r])

    def _per_round(self, which: int, round_index) -> np.ndarray:
        """Schedule `which` (EPSILON, ALPHA, PSI: psi at the round's start) at each game's round.

        The tables are computed once for rounds 0..R-1 (R doubling when a later
        round comes): a live learner asks every turn, and computing a schedule
        costs more than the suggestion itself (the values are the same floats).
        """
        if self._n == 1 and type(round_index) is np.ndarray and round_index.shape == (1,):
            r = round_index.item()  # a batch of one: views of the tables at its round, made once a round
            if r != self._round_of_views and 0 <= r < len(self._schedule[0]):
                self._round_of_views, self._views = r, tuple(t[r:r + 1] for t in self._schedule)
            if r == self._round_of_views:
                return self._views[which]
        table = self._schedule[which]
        r = kernels.as_batch(round_index, self._n, np.int64)
        if r.size and r.min() < 0:  # not a round of a game: the schedule's own formula
            return kernels.as_batch((epsilon_at, alpha_at, psi_round_start)[which](self.config, r), self._n,
                                    np.float64)
        if r.size and r.max() >= len(table):
            self._schedule = schedule_tables(self.config, max(2 * len(table), int(r.max()) + 1))
            table = self._schedule[which]
        return table[r]

    def suggest(self, states: np.ndarray, round_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(actions, how) for every game, drawing DRAWS_PER_SUGGESTION uniforms of its stream."""
        n = self._n
        actions, how = np.empty(n, _INT64), np.empty(n, _INT8)
        kernels.learners_suggest(self.q, kernels.as_batch(states, n, np.int64), self.stream.keys,
                                 self.stream.positions, self._per_round(EPSILON, round_index), self._mode,
                                 self.psi, self._psi_decay, self._table, actions, how)
        return actions, how

    def suggest_one(self, state: int, round_index: int) -> tuple[int, int]:
        """`suggest` of a batch of one (a live session): (action, how) of state `state` (0..23) in round
        `round_index`, as Python ints. The same kernel on arrays the learner keeps, so a live suggestion
        builds no array (an array built or checked per call cost more than the kernel)."""
        if self._n != 1:
            raise ValueError("suggest_one is for a learner of one game")
        self._one_state[0], self._one_round[0] = state, round_index
        # this round's schedule views, made by _per_round at the round's first suggestion; its checks and
        # calls cost ~6 us on a pick after an idle turn (issue 16)
        epsilon = self._views[EPSILON] if round_index == self._round_of_views else \
            self._per_round(EPSILON, self._one_round)
        kernels.learners_suggest(self.q, self._one_state, self._stream_keys, self._stream_positions, epsilon,
                                 self._mode, self.psi, self._psi_decay, self._table, self._one_action, self._one_how)
        return int(self._one_action[0]), int(self._one_how[0])

    def learn_one(self, state: int, action: int, reward: float, round_index: int) -> None:
        """`learn` of a batch of one (see `suggest_one`): eq. 5.2 for (state, action) with `reward`."""
        if self._n != 1:
            raise ValueError("learn_one is for a learner of one game")
        s, a, r = self._one_state, self._one_action, self._one_round
        s[0], a[0], self._one_reward[0], r[0] = state, action, reward, round_index
        if type(self).learn is not Learner.learn:  # another rule (core/lspi.py): its own learn
            self.learn(s, a, self._one_reward, self._one_learn, r)
        elif self.mode != "fixed":
            kernels.learners_learn(self.q, self.counts, s, a, self._one_reward, self._one_learn,
                                   self._per_round(ALPHA, r))

    def learn(self, states: np.ndarray, actions: np.ndarray, rewards: np.ndarray, mask: np.ndarray,
              round_index: np.ndarray) -> None:
        """Eq. 5.2 where `mask`; a fixed policy never learns."""
        if self.mode == "fixed":
            return
        n, b = self._n, kernels.as_batch
        kernels.learners_learn(self.q, self.counts, b(states, n, np.int64), b(actions, n, np.int64),
                               b(rewards, n, np.float64), b(mask, n, bool), self._per_round(ALPHA, round_index))


def policy_table(policy: np.ndarray, n_games: int) -> np.ndarray:
    table = np.asarray(policy, dtype=np.int64)
    if table.ndim == 1:
        table = np.broadcast_to(table, (n_games, table.size))
    if table.shape != (n_games, N_STATES) or table.min() < 0 or table.max() >= N_ACTIONS:
        raise ValueError(f"a policy is one action code 0..{N_ACTIONS - 1} per state ({N_STATES} states)")
    return table
