"""Memory games stepped one suggestion at a time, for an agent outside the loop (pairplay.gym).

Rule: the same turn as core/simulate.py's study loop (thesis 6.1-6.2), split at
the suggestion: `observe()` plays the user's first pick and intended card and
returns the state the agent must act in; `act(actions)` plays the user's
response, the reward (4.3, 6.1.3) and the memory update, and says which games
cleared their board (a round: an episode). `new_round(games)` deals again.
Each game draws from the study's own per-game "deal" and "user" streams, the
same number of draws per turn and per round, so game g seeded s played here
for R rounds with a fixed policy picks exactly what run_games picks for seed s
(tests/test_gym.py checks it); the agent's own randomness is its business.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, Persona

from .board import deal
from .geometry import ALL_CARDS, N_CARDS, states_of
from .reward import check_bonus_rule, simulated_reward
from .rng import UniformStream
from .user import SimulatedUsers

_BIT = np.int64(1) << np.arange(N_CARDS, dtype=np.int64)
OBSERVED_SOURCES = ("intended", "first-pick")


def check_observed_source(source: str) -> str:
    """`source` if it is one of OBSERVED_SOURCES (the card a suggestion is read against), else ValueError."""
    if source not in OBSERVED_SOURCES:
        raise ValueError(f"observed source {source!r} is not one of {OBSERVED_SOURCES}")
    return source


class Outcome(NamedTuple):
    """What one suggestion led to, per game."""

    rewards: np.ndarray  # float64: the configured reward (0 where ignored)
    learned: np.ndarray  # bool: the turn would update a learner (considered, not from memory)
    matched: np.ndarray  # bool
    considered: np.ndarray
    consistent: np.ndarray
    round_over: np.ndarray  # bool: the board is clear (episode end)
    picks: np.ndarray  # int32: picks of the round so far (the round's total where round_over)


class MemoryGames:
    """A batch of games, one per (persona, seed); see the module rule."""

    def __init__(self, personas: Sequence[Persona], seeds: Sequence[int], observed_source: str = "intended",
                 reward_bonus: str = DEFAULT_REWARD_BONUS):
        check_observed_source(observed_source)
        if len(personas) != len(seeds):
            raise ValueError("one seed per game")
        self.bonus = check_bonus_rule(reward_bonus)
        self.observed_source = observed_source
        n = len(seeds)
        self.rows = np.arange(n)
        self.deals = UniformStream(seeds, "deal")
        self.users = SimulatedUsers(personas, UniformStream(seeds, "user"))
        self.partner = deal(self.deals.take(N_CARDS))[1]
        self.matched = np.zeros(n, dtype=np.int64)
        self.picks = np.zeros(n, dtype=np.int32)
        self.round_index = np.zeros(n, dtype=np.int64)  # rounds cleared
        self.deal_index = np.zeros(n, dtype=np.int64)  # the current deal's index: a round abandoned counts too
        self._turn = None

    def new_round(self, games: np.ndarray) -> None:
        """A fresh deal for `games` (an index array); their users forget the old board."""
        games = np.asarray(games)
        if games.size:
            self.partner[games] = deal(self.deals.take(N_CARDS, games))[1]
            self.matched[games] = 0
            self.picks[games] = 0
            self.deal_index[games] += 1
            self.users.new_round(games)

    def observe(self) -> np.ndarray:
        """Every game's first pick and observed card; returns the states (B,) the agent acts in."""
        covered = ALL_CARDS & ~self.matched
        first = self.users.first_pick(covered, self.partner)
        covered = covered & ~_BIT[first]
        match = self.partner[self.rows, first]
        intended, from_memory = self.users.intend(first, match, covered)
        observed = intended if self.observed_source == "intended" else first
        states = states_of(observed, match, covered)
        self._turn = (first, covered, match, intended, from_memory, observed, states)
        return states

    @property
    def turn(self) -> dict[str, np.ndarray]:
        """The open turn (after observe): first pick, observed and matching card, covered cards (masks)."""
        first, covered, match, _, _, observed, states = self._turn
        return {"first": first, "observed": observed, "match": match, "covered": covered, "states": states}

    def act(self, actions: np.ndarray) -> Outcome:
        """The user's response to every game's suggestion (action codes 0..87)."""
        if self._turn is None:
            raise RuntimeError("act() before observe()")
        first, covered, match, intended, from_memory, observed, _ = self._turn
        self._turn = None
        resp = self.users.respond(np.asarray(actions, dtype=np.int64), observed, match, intended, from_memory, covered)
        hit = resp.second == match
        self.users.end_turn(first, resp.second, hit)
        rewards, learn = simulated_reward(hit, resp.considered, resp.consistent, np.bitwise_count(resp.candidates),
                                          (resp.candidates >> match) & 1 == 1, self.bonus)
        self.matched |= np.where(hit, _BIT[first] | _BIT[resp.second], 0)
        self.picks += 2
        over = self.matched == ALL_CARDS
        self.round_index += over
        return Outcome(rewards, learn, hit, resp.considered, resp.consistent, over, self.picks.copy())
