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

from .actions import N_ACTIONS
from .geometry import N_STATES
from .rng import UniformStream

DRAWS_PER_SUGGESTION = 4


class How(IntEnum):
    """How an action was chosen (recorded with every suggestion)."""

    GREEDY = 0
    EXPLORE = 1
    BIAS = 2
    FIXED = 3


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
    best = np.argmax(q, axis=-1)
    ties = q == q.max(axis=-1, keepdims=True)
    n = np.count_nonzero(ties, axis=-1)
    several = n > 1
    if several.any():  # only tied rows pay for the cumulative count (int16: n <= 88)
        k = np.minimum((u_tie[several] * n[several]).astype(np.int16), n[several] - 1)
        best[several] = np.argmax(np.cumsum(ties[several], -1, dtype=np.int16) > k[..., None], -1)
    return best


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
        self.bias = None if bias is None else _policy_table(bias, n_games)
        self.policy = None if policy is None else _policy_table(policy, n_games)
        self.psi = np.zeros(n_games)
        self._rows = np.arange(n_games)

    def start_round(self, round_index, games=slice(None)) -> None:
        """Reset psi for the games starting a round (algorithm 5, line 4)."""
        self.psi[games] = psi_round_start(self.config, np.asarray(round_index)[games])

    def suggest(self, states: np.ndarray, round_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(actions, how) for every game, drawing DRAWS_PER_SUGGESTION uniforms."""
        u = self.stream.take(DRAWS_PER_SUGGESTION)
        rows = self._rows
        if self.mode == "fixed":
            return self.policy[rows, states], np.full(rows.size, How.FIXED, dtype=np.int8)
        explore = u[:, 1] < epsilon_at(self.config, round_index)
        actions = np.minimum((u[:, 2] * N_ACTIONS).astype(np.int64), N_ACTIONS - 1)
        exploit = rows[~explore]  # only the exploiting games need their Q row
        actions[exploit] = greedy(self.q[exploit, states[exploit]], u[exploit, 3])
        how = np.where(explore, How.EXPLORE, How.GREEDY).astype(np.int8)
        if self.mode == "reuse":
            follow = u[:, 0] < self.psi
            actions = np.where(follow, self.bias[rows, states], actions)
            how = np.where(follow, np.int8(How.BIAS), how)
            self.psi = self.psi * self.config.psi_decay  # algorithm 5, line 9
        return actions, how

    def learn(self, states: np.ndarray, actions: np.ndarray, rewards: np.ndarray, mask: np.ndarray,
              round_index: np.ndarray) -> None:
        """Eq. 5.2 where `mask`; a fixed policy never learns."""
        if self.mode == "fixed" or not mask.any():
            return
        # Flat indices: one gather and one scatter instead of three index arrays.
        cell = (self._rows[mask] * N_STATES + states[mask]) * N_ACTIONS + actions[mask]
        alpha = alpha_at(self.config, round_index)
        alpha = alpha[mask] if np.ndim(alpha) else alpha
        q, counts = self.q.reshape(-1), self.counts.reshape(-1)
        q[cell] = q_update(q[cell], rewards[mask], alpha)
        counts[cell] += 1  # one update per game and step: no repeated index


def _policy_table(policy: np.ndarray, n_games: int) -> np.ndarray:
    table = np.asarray(policy, dtype=np.int64)
    if table.ndim == 1:
        table = np.broadcast_to(table, (n_games, table.size))
    if table.shape != (n_games, N_STATES) or table.min() < 0 or table.max() >= N_ACTIONS:
        raise ValueError(f"a policy is one action code 0..{N_ACTIONS - 1} per state ({N_STATES} states)")
    return table
