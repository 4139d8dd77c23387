"""The virtual study of thesis 6.2, as pure functions over arrays.

Rule: every persona plays `games` games of `rounds` rounds with online
Q-learning; game g of persona P is seeded by game_seed(seed, P, g), so adding a
persona or a game never changes the others. Each game yields one policy: the
greedy action of its final Q-table, ties broken by a generator seeded from the
game's seed. Evaluation plays every policy with epsilon 0 (a fixed policy) on
games seeded apart from training, beside the two references (user alone,
oracle); all of it batched into as few lockstep runs as possible.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import LearnerConfig, Persona

from .learning import greedy_policy
from .oracle import USER_ALONE, oracle_policies
from .rng import game_seed
from .simulate import SimResult, run_games

EVAL_GAME_OFFSET = 1_000_000  # evaluation games are seeded apart from training games


class Training(NamedTuple):
    personas: list[Persona]  # one per game, persona-major
    game_index: np.ndarray  # game number within its persona
    seeds: list[int]
    result: SimResult
    greedy: np.ndarray  # (B, 24)


def train(personas: Sequence[Persona], games: int, rounds: int, seed: int,
          config: LearnerConfig = LearnerConfig(), progress=None, mode: str = "q",
          bias: np.ndarray | None = None) -> Training:
    flat = [p for p in personas for _ in range(games)]
    index = np.tile(np.arange(games), len(personas))
    seeds = [game_seed(seed, p.key, int(g)) for p, g in zip(flat, index)]
    result = run_games(flat, seeds, rounds, config, mode=mode, bias=bias, progress=progress)
    greedy = np.stack([greedy_policy(q, np.random.default_rng(s)) for q, s in zip(result.q, seeds)])
    return Training(flat, index, seeds, result, greedy)


def evaluate(personas: Sequence[Persona], policies: np.ndarray, rounds: int, seed: int,
             game_index: Sequence[int] | None = None, progress=None) -> np.ndarray:
    """Mean picks per round of each (persona, policy) row, epsilon 0, `rounds` rounds each.

    Row i plays evaluation game `game_index[i]` (default i) of its persona: rows
    with the same persona and index play the very same deals and user draws.
    """
    index = range(len(personas)) if game_index is None else game_index
    seeds = [game_seed(seed, p.key, EVAL_GAME_OFFSET + int(i)) for p, i in zip(personas, index)]
    return run_games(list(personas), seeds, rounds, mode="fixed", policy=policies,
                     progress=progress).picks.mean(axis=1)


class Comparison(NamedTuple):
    persona: list[str]
    alone: np.ndarray  # mean picks per round, per persona
    learned: np.ndarray
    learned_spread: np.ndarray  # std over the persona's policies
    oracle: np.ndarray
    oracle_policy: np.ndarray  # (P, 24)
    learned_per_policy: np.ndarray  # (P, games)


def compare(personas: Sequence[Persona], training: Training, eval_rounds: int, seed: int,
            oracle_rounds: int = 200, oracle_games: int = 20, progress=None) -> Comparison:
    """User alone, learned greedy policies and the oracle, per persona, on the same games.

    Each learned policy plays `eval_rounds` rounds; the oracle and the user alone
    play the very same evaluation games beside it (one lockstep batch).
    """
    oracle, _ = oracle_policies(personas, oracle_games, seed, oracle_rounds)
    n_p, games = len(personas), len(training.personas) // len(personas)
    owner = np.repeat(np.arange(n_p), games)
    policies = np.concatenate([training.greedy, oracle[owner], np.tile(USER_ALONE, (n_p * games, 1))])
    picks = evaluate(list(training.personas) * 3, policies, eval_rounds, seed,
                     np.tile(training.game_index, 3), progress)
    learned, oracle_picks, alone = picks.reshape(3, n_p, games)
    return Comparison([p.key for p in personas], alone.mean(1), learned.mean(1), learned.std(1),
                      oracle_picks.mean(1), oracle, learned)
