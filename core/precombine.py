"""Per-user pre-combination (thesis chapter 8, third future work).

Rule: the thesis represents each user in a combination by ONE of their
policies, picked at random (6.2), and suggests instead "a combination of the
policies learned by the user" (chapter 8). `precombine` merges one user's own
policies with algorithm 4 first: every policy carries the same user
information, so each half of each state is the algebraic sum of the user's
parts (tables 5.1, 5.2) and an Error goes to the part the user's Q-tables
value most, as in `combine`. The pre-combined users are then combined across
users as usual.

`combination_experiment` compares three ways of representing a user, on the
same trained policies and the same evaluation games:
  "one random policy" (the thesis's way), "all policies" (every policy of a
  user enters the N-ary combination as a user of its own, with the user's
  information) and "pre-combined" (precombine, then combine).
Replicates are disjoint groups of each persona's games (10 games, 5
replicates: 2 policies a user, as in the human study's phase 1, thesis 7.2),
so the spread is over independently trained policies, not only over which
policy the seed picks.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import Persona

from .combine import Combined, User, combine, extract_info
from .rng import game_seed
from pairplay.numbers import counted

STRATEGIES = ("one random policy", "all policies", "pre-combined")


def precombine(name: str, policies: np.ndarray, q_tables: np.ndarray) -> User:
    """One user as one merged policy: algorithm 4 over the user's own (n, 24) policies and (n, 24, 88) Q-tables.

    The user's information is algorithm 3 over the same policies (thesis 5.2.1)."""
    policies = np.atleast_2d(np.asarray(policies))
    info = extract_info(policies).info
    own = [User(f"{name}#{i}", policies[i], np.asarray(q_tables[i]), info) for i in range(len(policies))]
    merged = combine(own)
    return User(name, merged.policy, merged.q, info)


def represent_all(personas: Sequence[Persona], policies: dict, q_tables: dict, seed: int,
                  replicate: int) -> dict[str, list[User]]:
    """The users each strategy feeds to `combine`, keyed by strategy.

    `policies[key]` is (n, 24) and `q_tables[key]` (n, 24, 88): one persona's group of games."""
    out: dict[str, list[User]] = {s: [] for s in STRATEGIES}
    for p in personas:
        pol, q = np.asarray(policies[p.key]), np.asarray(q_tables[p.key])
        info = extract_info(pol).info
        pick = int(np.random.default_rng(game_seed(seed, f"precombine:{p.key}", replicate)).integers(len(pol)))
        out["one random policy"].append(User(p.key, pol[pick], q[pick], info))
        out["all policies"] += [User(f"{p.key}#{i}", pol[i], q[i], info) for i in range(len(pol))]
        out["pre-combined"].append(precombine(p.key, pol, q))
    return out


class CombinationExperiment(NamedTuple):
    persona: list[str]
    strategies: tuple[str, ...]
    picks: np.ndarray  # (strategies, replicates, personas): mean picks per round of the merged policy, epsilon 0
    merged: list[list[Combined]]  # [strategy][replicate]
    errors_resolved: np.ndarray  # (strategies, replicates): states whose merge needed an Error -> Q resolution


def combination_experiment(personas: Sequence[Persona], training, seed: int, replicates: int = 5,
                           eval_games: int = 4, eval_rounds: int = 100, progress=None) -> CombinationExperiment:
    """Merge all `personas` three ways per replicate and play each merge on every persona.

    `training` is a core.study.Training with the same number of games per persona,
    at least `replicates`; replicate r takes games r, r + R, r + 2R, ... of each persona.
    The evaluation games are a batch of their own; the study queues them in its
    single batch instead (`add_combination`)."""
    from .study import Evaluations
    batch = Evaluations(seed)
    pending = add_combination(batch, personas, training, seed, replicates, eval_games, eval_rounds)
    batch.play(progress)
    return pending(batch)


def add_combination(batch, personas: Sequence[Persona], training, seed: int, replicates: int = 5,
                    eval_games: int = 4, eval_rounds: int = 100):
    """Merge (see `combination_experiment`) and queue the merges' evaluation games in `batch`
    (a core.study.Evaluations); returns a function of the played batch giving the CombinationExperiment."""
    from .study import add_on_personas
    games = len(training.personas) // len(personas)
    if games < replicates:
        raise ValueError(f"{counted(games, 'game')} per persona cannot make {counted(replicates, 'disjoint replicate')}")
    merged: list[list[Combined]] = [[] for _ in STRATEGIES]
    named: dict[str, np.ndarray] = {}
    for r in range(replicates):
        group_p, group_q = {}, {}
        for p in personas:
            rows = [i for i, q in enumerate(training.personas) if q.key == p.key]
            rows = rows[r::replicates]
            group_p[p.key], group_q[p.key] = training.greedy[rows], training.result.q[rows]
        users = represent_all(personas, group_p, group_q, seed, r)
        for k, strategy in enumerate(STRATEGIES):
            m = combine(users[strategy])
            merged[k].append(m)
            named[f"{k}:{r}"] = m.policy
    pending = add_on_personas(batch, personas, named, eval_games, eval_rounds)

    def result(played) -> CombinationExperiment:
        scores = pending(played)
        picks = np.array([[[scores[(f"{k}:{r}", p.key)] for p in personas] for r in range(replicates)]
                          for k in range(len(STRATEGIES))])
        errors = np.array([[sum(":error->Q" in rule for rule in m.rules) for m in row] for row in merged])
        return CombinationExperiment([p.key for p in personas], STRATEGIES, picks, merged, errors)
    return result
