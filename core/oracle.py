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
   E[r] = sum over heard/unheard of P * (-3 if empty else 2/|C| [match in C] - 1 + bonus),
   the bonus 1/|C| times [match in C] (rule "correct"), 1 ("consistent") or
   1/|C| [match in C] (the hit probability, "match"); core/reward.py.
3. Average per state and take the best action (lowest code among exact ties).
Iterate once: situations first from the user alone, then from the first
oracle's own play (the states it visits are those it will be judged on).
"""

from __future__ import annotations

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, Persona

from .actions import ACTION_HEARING, ACTION_VISUAL, HEARING_SMILE, N_ACTIONS, VISUAL_GAZE
from .geometry import N_STATES
from .interpretation import HEAR_SET, VIS_SET, hear_probability, sees
from .reward import INCONSISTENT, check_bonus_rule
from .simulate import run_games

USER_ALONE = np.zeros(N_STATES, dtype=np.int64)


def _value(cand: np.ndarray, match: np.ndarray, bonus: str) -> np.ndarray:
    """Expected reward of a uniform pick in each candidate set (core/reward.py's rule)."""
    size = np.bitwise_count(cand)
    hit = (cand >> match[:, None]) & 1
    safe = np.maximum(size, 1)
    p_hit = hit / safe
    paid = {"correct": hit, "consistent": 1.0, "match": p_hit}[check_bonus_rule(bonus)]
    value = 2.0 * p_hit - 1.0 + paid / safe
    return np.where(size == 0, INCONSISTENT, value)


def expected_rewards(persona: Persona, observed: np.ndarray, match: np.ndarray, nis: np.ndarray,
                     bonus: str = DEFAULT_REWARD_BONUS) -> np.ndarray:
    """E[reward | considered] of every action in every situation: (n, 88)."""
    seen = sees(persona.sight)
    q = hear_probability(persona.hearing)
    h, v = ACTION_HEARING, ACTION_VISUAL
    vis_seen = np.where(v == VISUAL_GAZE, seen[3], (v > VISUAL_GAZE) & seen[2])
    vis = np.where(vis_seen[None], VIS_SET[observed[:, None], match[:, None], v[None]], -1)
    base = nis[:, None] & vis
    unheard = _value(base, match, bonus)
    heard_mask = base & HEAR_SET[observed[:, None], match[:, None], h[None]]
    p_heard = np.where(h == HEARING_SMILE, float(seen[1]), np.where(h > HEARING_SMILE, q, 0.0))
    heard = _value(heard_mask, match, bonus)
    return p_heard * heard + (1 - p_heard) * unheard


def situations(personas, seeds, rounds: int, policies: np.ndarray):
    """Per game of fixed-policy play, its considerable turns: (game, state, observed, match, NIS)."""
    rows = []

    def keep(turn):
        m = turn.active & ~turn.from_memory
        rows.append((np.nonzero(m)[0], turn.states[m], turn.observed[m], turn.match[m], turn.nis[m]))

    run_games(personas, seeds, rounds, mode="fixed", policy=policies, on_turn=keep)
    return tuple(np.concatenate(col) for col in zip(*rows))


def oracle_policies(personas, seeds_per_persona: int, seed: int, rounds: int = 200,
                    iterations: int = 2, seed_of=None, bonus: str = DEFAULT_REWARD_BONUS) -> tuple[np.ndarray, np.ndarray]:
    """(policies (P, 24), expected reward tables (P, 24, 88)) for every persona, in one batch.

    `seed_of(persona_key, i)` names the seed of the i-th situation game.
    """
    from .rng import game_seed
    seed_of = seed_of or (lambda key, i: game_seed(seed, "oracle:" + key, i))
    games = [p for p in personas for _ in range(seeds_per_persona)]
    seeds = [seed_of(p.key, i) for p in personas for i in range(seeds_per_persona)]
    owner = np.repeat(np.arange(len(personas)), seeds_per_persona)
    policies = np.tile(USER_ALONE, (len(personas), 1))
    tables = np.zeros((len(personas), N_STATES, N_ACTIONS))
    for _ in range(iterations):
        game, states, observed, match, nis = situations(games, seeds, rounds, policies[owner])
        for i, persona in enumerate(personas):
            mine = owner[game] == i
            values = expected_rewards(persona, observed[mine], match[mine], nis[mine], bonus)
            sums = np.zeros((N_STATES, N_ACTIONS))
            np.add.at(sums, states[mine], values)
            counts = np.bincount(states[mine], minlength=N_STATES)
            visited = counts > 0
            tables[i] = np.where(visited[:, None], sums / np.maximum(counts, 1)[:, None], tables[i])
            policies[i] = np.where(visited, np.argmax(tables[i], axis=1), policies[i])
    return policies, tables
