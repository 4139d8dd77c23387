"""Benchmarks of the core: agent steps/s with the full semantics and the study's wall time.

Rule: each row stands beside its raw reference measured in the same run, so the
ratio means something on a noisy machine: the full simulator (board,
interpreter, simulated user, learner, reward) against a bare numpy Q-learning
bandit update (23 x 88, no game at all), once as a plain Python loop (how a
per-step RL library runs) and once vectorised over as many learners.
"""

from __future__ import annotations

import time

import numpy as np

from pairplay.core.personas import PERSONAS
from pairplay.core.rng import game_seed
from pairplay.core.simulate import run_games
from pairplay.core.study import train


def bandit_loop(steps: int, seed: int = 0) -> float:
    """Steps/s of a plain Python loop of epsilon-greedy Q-learning on a 23 x 88 bandit."""
    rng = np.random.default_rng(seed)
    q = np.zeros((23, 88))
    states = rng.integers(0, 23, steps)
    u = rng.random((steps, 3))
    t = time.perf_counter()
    for i in range(steps):
        s = states[i]
        a = int(u[i, 1] * 88) if u[i, 0] < 0.1 else int(np.argmax(q[s]))
        q[s, a] += 0.1 * (u[i, 2] - q[s, a])
    return steps / (time.perf_counter() - t)


def bandit_vectorised(learners: int, steps: int, seed: int = 0) -> float:
    """Steps/s of the same bandit, `learners` at once as numpy arrays."""
    rng = np.random.default_rng(seed)
    q = np.zeros((learners, 23, 88))
    rows = np.arange(learners)
    t = time.perf_counter()
    for _ in range(steps):
        s = rng.integers(0, 23, learners)
        u = rng.random((learners, 3))
        a = np.where(u[:, 0] < 0.1, (u[:, 1] * 88).astype(np.int64), np.argmax(q[rows, s], axis=1))
        q[rows, s, a] += 0.1 * (u[:, 2] - q[rows, s, a])
    return learners * steps / (time.perf_counter() - t)


def simulator_steps(games: int, rounds: int, seed: int = 0) -> tuple[float, int]:
    """(agent steps/s, steps) of the full simulator, `games` games of Q-learning at once.

    An agent step is one suggestion: a turn (two picks). The time includes
    building the games' random streams.
    """
    personas = list(PERSONAS.values())
    chosen = [personas[i % len(personas)] for i in range(games)]
    seeds = [game_seed(seed, p.key, i) for i, p in enumerate(chosen)]
    t = time.perf_counter()
    result = run_games(chosen, seeds, rounds)
    wall = time.perf_counter() - t
    steps = int(result.picks.sum()) // 2
    return steps / wall, steps


def bench_rows(quick: bool = False) -> list[dict]:
    rows = []
    loop = bandit_loop(20_000 if quick else 100_000)
    vec = bandit_vectorised(4096, 100 if quick else 400)
    rate, steps = simulator_steps(2048, 8 if quick else 80)
    rows.append(dict(row="agent steps/s, full semantics (2048 games at once)", value=rate, unit="steps/s",
                     reference="bare numpy bandit update, Python loop", reference_value=loop,
                     ratio=rate / loop, goal=">= 1,000,000 steps/s"))
    rows.append(dict(row="agent steps/s, full semantics (2048 games at once)", value=rate, unit="steps/s",
                     reference="bare numpy bandit update, 4096 learners vectorised", reference_value=vec,
                     ratio=rate / vec, goal="(context)"))
    personas = list(PERSONAS.values())
    t = time.perf_counter()
    training = train(personas, 10, 500, 0)
    wall = time.perf_counter() - t
    study_steps = int((training.result.picks.sum()) // 2)
    rows.append(dict(row=f"study training wall time ({len(personas)} personas x 10 games x 500 rounds)",
                     value=wall, unit="s", reference="same agent steps at the bare bandit loop's rate",
                     reference_value=study_steps / loop, ratio=wall / (study_steps / loop), goal="<= 3 s"))
    return rows
