"""The virtual study's game loop (thesis 6.1-6.2), many games stepped together.

Rule: every game plays `rounds` rounds; a round is every turn until the board is
clear, each round on a new deal. A turn: the user's first pick; the card the
user observes (its intended card, thesis 6.1.3, or the first pick as in the human
study); the state (4.1); the learner's suggestion; the user's second pick; the
reward (4.3, 6.1.3) and the Q update (5.2); the user's memory. Games are
independent, so they are stepped in lockstep as arrays: a game that finishes
its rounds early keeps stepping with its results frozen. Each role (deal,
agent, user) draws from its own per-game stream, so a game run here equals the
same game run alone over the bus.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona

from .board import deal
from .geometry import ALL_CARDS, N_CARDS, states_of
from .learning import Learner, greedy
from .lspi import LSPILearner
from .reward import simulated_reward
from .rng import UniformStream
from .user import SimulatedUsers

_BIT = np.int64(1) << np.arange(N_CARDS, dtype=np.int64)
OBSERVED_SOURCES = ("intended", "first-pick")


class Turn(NamedTuple):
    """What one lockstep step decided, for observers (`on_turn`)."""

    active: np.ndarray  # games still inside their rounds
    round_index: np.ndarray
    first: np.ndarray
    observed: np.ndarray
    match: np.ndarray
    covered: np.ndarray  # face-down cards at the suggestion (first card excluded)
    nis: np.ndarray  # the user's no-information set at the suggestion
    from_memory: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    second: np.ndarray
    considered: np.ndarray
    consistent: np.ndarray
    rewards: np.ndarray


class SimResult(NamedTuple):
    q: np.ndarray  # (B, 24, 88) final Q-tables
    counts: np.ndarray  # (B, 24, 88) Q updates per state and action
    picks: np.ndarray  # (B, rounds) picks per round
    inconsistent: np.ndarray  # (B, rounds) inconsistent suggestions per round
    turns: int  # lockstep steps taken
    snapshots: np.ndarray | None  # (B, rounds // k, 24) greedy policy after every k rounds


def run_games(personas: Sequence[Persona], seeds: Sequence[int], rounds: int,
              config: LearnerConfig = LearnerConfig(), mode: str = "q",
              bias: np.ndarray | None = None, policy: np.ndarray | None = None,
              observed_source: str = "intended", progress=None, on_turn=None,
              snapshot_every: int | None = None, reward_bonus: str = DEFAULT_REWARD_BONUS,
              lspi: LSPIConfig | None = None) -> SimResult:
    """Play one game per (persona, seed) pair; see the module rule.

    `progress(done_rounds)` is called with the rounds completed so far (summed
    over games) whenever some game finishes a round; `on_turn(Turn)` after every
    lockstep step. With `snapshot_every=k` the greedy policy of every learner is
    kept after rounds k, 2k, ... (ties broken by the game's "snapshot" stream),
    to measure how fast a policy becomes good. `reward_bonus` chooses when the
    1/|candidate set| bonus is paid (core/reward.py). `mode="lspi"` learns by
    online LSPI (core/lspi.py, configured by `lspi`) instead of Q-learning.
    """
    if observed_source not in OBSERVED_SOURCES:
        raise ValueError(f"observed source must be one of {OBSERVED_SOURCES}")
    n = len(personas)
    if len(seeds) != n:
        raise ValueError("one seed per game")
    deals = UniformStream(seeds, "deal")
    users = SimulatedUsers(personas, UniformStream(seeds, "user"))
    if mode == "lspi":
        learner = LSPILearner(n, UniformStream(seeds, "agent"), config, lspi or LSPIConfig())
    else:
        learner = Learner(n, UniformStream(seeds, "agent"), config, mode, bias=bias, policy=policy)
    rows = np.arange(n)

    picks_log = np.zeros((n, rounds), dtype=np.int32)
    inconsistent_log = np.zeros((n, rounds), dtype=np.int32)
    round_index = np.zeros(n, dtype=np.int64)
    picks = np.zeros(n, dtype=np.int32)
    inconsistent = np.zeros(n, dtype=np.int32)
    done = np.zeros(n, dtype=bool)
    _, partner = deal(deals.take(N_CARDS))
    matched = np.zeros(n, dtype=np.int64)
    learner.start_round(round_index)
    snapshots = snap_stream = None
    if snapshot_every:
        snapshots = np.zeros((n, rounds // snapshot_every, learner.q.shape[1]), dtype=np.int64)
        snap_stream = UniformStream(seeds, "snapshot")
    steps = 0
    while not done.all():
        steps += 1
        covered = ALL_CARDS & ~matched
        first = users.first_pick(covered, partner)
        covered = covered & ~_BIT[first]
        match = partner[rows, first]
        intended, from_memory = users.intend(first, match, covered)
        observed = intended if observed_source == "intended" else first
        states = states_of(observed, match, covered)
        actions, _ = learner.suggest(states, round_index)
        nis = users.nis(covered) if on_turn is not None else None  # before the turn changes memory
        resp = users.respond(actions, observed, match, intended, from_memory, covered)
        hit = resp.second == match
        users.end_turn(first, resp.second, hit)
        rewards, learn = simulated_reward(hit, resp.considered, resp.consistent, np.bitwise_count(resp.candidates),
                                          (resp.candidates >> match) & 1 == 1, reward_bonus)
        learner.learn(states, actions, rewards, learn & ~done, round_index)
        if on_turn is not None:
            on_turn(Turn(~done, round_index.copy(), first, observed, match, covered, nis,
                         from_memory, states, actions, resp.second, resp.considered, resp.consistent, rewards))
        matched |= np.where(hit, _BIT[first] | _BIT[resp.second], 0)
        picks += 2
        inconsistent += resp.considered & ~resp.consistent
        over = matched == ALL_CARDS
        if over.any():
            g = rows[over & ~done]
            picks_log[g, round_index[g]] = picks[g]
            inconsistent_log[g, round_index[g]] = inconsistent[g]
            round_index[over] += 1
            picks[over] = 0
            inconsistent[over] = 0
            done |= round_index >= rounds
            if snapshots is not None:
                due = g[(round_index[g] % snapshot_every == 0) & (round_index[g] <= snapshots.shape[1] * snapshot_every)]
                if due.size:
                    u = snap_stream.take(learner.q.shape[1], due)
                    snapshots[due, round_index[due] // snapshot_every - 1] = greedy(learner.q[due], u)
            g = rows[over]
            partner[g] = deal(deals.take(N_CARDS, g))[1]
            matched[g] = 0
            users.new_round(g)
            learner.start_round(round_index, g)
            if progress is not None:
                progress(int(np.minimum(round_index, rounds).sum()))
    return SimResult(learner.q, learner.counts, picks_log, inconsistent_log, steps, snapshots)
