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

from . import kernels, threads
from .actions import N_ACTIONS
from .geometry import N_STATES
from .interpretation import hear_probability, sees
from .reward import BONUS_CODES, check_bonus_rule
from .simulate import run_games
from .user import persona_arrays

USER_ALONE = np.zeros(N_STATES, dtype=np.int64)


def expected_rewards(persona: Persona, observed: np.ndarray, match: np.ndarray, nis: np.ndarray,
                     bonus: str = DEFAULT_REWARD_BONUS) -> np.ndarray:
    """E[reward | considered] of every action in every situation: (n, 88) (core/kernels.py `_expected`)."""
    seen = sees(persona.sight)
    ints = [np.ascontiguousarray(np.asarray(x, dtype=np.int64).reshape(-1)) for x in (observed, match, nis)]
    out = np.empty((ints[0].size, N_ACTIONS))
    kernels.expected_batch(kernels.TABLES, *ints, float(hear_probability(persona.hearing)), bool(seen[1]),
                           bool(seen[2]), bool(seen[3]), BONUS_CODES[check_bonus_rule(bonus)], out)
    return out


def situations(personas, seeds, rounds: int, policies: np.ndarray):
    """The considerable turns of fixed-policy play: a simulate.Trace (`.rows`, in lockstep `.order`)."""
    return run_games(personas, seeds, rounds, mode="fixed", policy=policies, record="considerable").trace


def oracle_policies(personas, seeds_per_persona: int, seed: int, rounds: int = 200,
                    iterations: int = 2, seed_of=None, bonus: str = DEFAULT_REWARD_BONUS) -> tuple[np.ndarray, np.ndarray]:
    """(policies (P, 24), expected reward tables (P, 24, 88)) for every persona, in one batch.

    `seed_of(persona_key, i)` names the seed of the i-th situation game. Each
    situation's 88 expected rewards are summed per persona and state in the
    situations' lockstep order, without an (n, 88) table in memory; the personas are summed
    apart, on the machine's cores (core/threads.py), each in the same order as alone.
    """
    from .rng import game_seed
    from .user import reading_codes
    check_bonus_rule(bonus)
    if reading_codes(personas).any():  # core/kernels.py `_expected` models the thesis's reading only
        raise ValueError("the oracle models the thesis's reading of suggestions, not whole readings "
                         f"({', '.join(p.key for p, r in zip(personas, reading_codes(personas)) if r)})")
    seed_of = seed_of or (lambda key, i: game_seed(seed, "oracle:" + key, i))
    games = [p for p in personas for _ in range(seeds_per_persona)]
    seeds = [seed_of(p.key, i) for p in personas for i in range(seeds_per_persona)]
    owner = np.repeat(np.arange(len(personas)), seeds_per_persona)
    policies = np.tile(USER_ALONE, (len(personas), 1))
    tables = np.zeros((len(personas), N_STATES, N_ACTIONS))
    _, q_hear, _, seen = persona_arrays(personas)
    for _ in range(iterations):
        turns = situations(games, seeds, rounds, policies[owner])
        sums = np.zeros((len(personas), N_STATES, N_ACTIONS))
        counts = np.zeros((len(personas), N_STATES), dtype=np.int64)
        # each persona's sums on its own, in lockstep order: the personas on the machine's cores
        own = owner[turns.rows[turns.order, kernels.T_GAME]]
        by_persona = np.argsort(own, kind="stable")
        pieces = np.split(turns.order[by_persona], np.cumsum(np.bincount(own, minlength=len(personas)))[:-1])
        del own, by_persona
        threads.each(lambda k: kernels.expected_sums(kernels.TABLES, owner, turns.rows, pieces[k], q_hear, seen,
                                                     BONUS_CODES[bonus], sums, counts), len(personas))
        del pieces
        del turns  # before the next iteration's: two recorded tables at once were the study's peak memory
        visited = counts > 0
        tables = np.where(visited[..., None], sums / np.maximum(counts, 1)[..., None], tables)
        policies = np.where(visited, np.argmax(tables, axis=-1), policies)
    return policies, tables
