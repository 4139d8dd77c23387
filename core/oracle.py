"""The two reference agents of every comparison: the user alone and an oracle.

The user alone gets no suggestion: a fixed policy of action 0 ("do nothing"
in every part), which leaves the user's candidate set at the NIS, exactly the
unaided choice.

The oracle is, per persona and state, the action with the highest expected
reward given that the suggestion is considered (the quantity Q-learning
estimates, thesis 5.1: ignored turns are not learned from). Method:
1. Monte-Carlo over situations: play `rounds` rounds per seed under a policy
   and record every turn whose suggestion the user could consider (the match
   not remembered): observed card, matching card, NIS.
2. Exact expectation per situation and action: the user's candidate set is
   deterministic given whether the speech is heard (probability q) and what the
   sight level shows, and the pick is uniform in it, so
   E[r] = sum over heard/unheard of P * (-3 if empty else 2/|C| [match in C] - 1 + 1/|C|).
3. Average per state and take the best action (lowest code among exact ties).
Iterate once: situations first from the user alone, then from the first
oracle's own play (the states it visits are those it will be judged on).
"""

from __future__ import annotations

import numpy as np

from pairplay.schemas.config import Persona

from .actions import ACTION_HEARING, ACTION_VISUAL, HEARING_SMILE, N_ACTIONS, VISUAL_GAZE
from .geometry import N_STATES
from .interpretation import HEAR_SET, VIS_SET, hear_probability, sees
from .reward import INCONSISTENT
from .simulate import run_games

USER_ALONE = np.zeros(N_STATES, dtype=np.int64)


def _value(cand: np.ndarray, match: np.ndarray) -> np.ndarray:
    size = np.bitwise_count(cand)
    hit = (cand >> match[:, None]) & 1
    safe = np.maximum(size, 1)
    return np.where(size == 0, INCONSISTENT, 2.0 * hit / safe - 1.0 + 1.0 / safe)


def expected_rewards(persona: Persona, observed: np.ndarray, match: np.ndarray, nis: np.ndarray) -> np.ndarray:
    """E[reward | considered] of every action in every situation: (n, 88)."""
    seen = sees(persona.sight)
    q = hear_probability(persona.hearing)
    h, v = ACTION_HEARING, ACTION_VISUAL
    vis_seen = np.where(v == VISUAL_GAZE, seen[3], (v > VISUAL_GAZE) & seen[2])
    vis = np.where(vis_seen[None], VIS_SET[observed[:, None], match[:, None], v[None]], -1)
    base = nis[:, None] & vis
    unheard = _value(base, match)
    heard_mask = base & HEAR_SET[observed[:, None], match[:, None], h[None]]
    p_heard = np.where(h == HEARING_SMILE, float(seen[1]), np.where(h > HEARING_SMILE, q, 0.0))
    heard = _value(heard_mask, match)
    return p_heard * heard + (1 - p_heard) * unheard


def situations(persona: Persona, seeds, rounds: int, policy: np.ndarray):
    """States and (observed, match, NIS) of the considerable turns of fixed-policy play."""
    rows = []

    def keep(turn):
        m = turn.active & ~turn.from_memory
        rows.append((turn.states[m], turn.observed[m], turn.match[m], turn.nis[m]))

    run_games([persona] * len(seeds), seeds, rounds, mode="fixed", policy=policy, on_turn=keep)
    return tuple(np.concatenate(col) for col in zip(*rows))


def oracle_policy(persona: Persona, seeds, rounds: int = 200, iterations: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(policy (24,), mean expected reward table (24, 88)) of the oracle."""
    policy = USER_ALONE
    table = np.zeros((N_STATES, N_ACTIONS))
    for _ in range(iterations):
        states, observed, match, nis = situations(persona, seeds, rounds, policy)
        values = expected_rewards(persona, observed, match, nis)
        sums = np.zeros((N_STATES, N_ACTIONS))
        np.add.at(sums, states, values)
        counts = np.bincount(states, minlength=N_STATES)
        visited = counts > 0
        table = np.where(visited[:, None], sums / np.maximum(counts, 1)[:, None], table)
        policy = np.where(visited, np.argmax(table, axis=1), policy)
    return policy, table
