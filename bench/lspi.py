"""Benchmarks of online LSPI and of pairplay.gym, each beside its reference measured in the same run.

Rule: LSPI's cost per sample is timed on the study's own samples (recorded
from a Q-learning run, so both learners see the same stream) and amortised over
its policy improvements; beside it, a dense Sherman-Morrison update of the same
feature count (88 x F, what algorithm 2 costs without the block structure) and
of the thesis's 2816. The vector environment's steps/s at 2,048 games stands
beside the core simulator playing the same fixed policy on the same games.
Times are this process's CPU time (time.process_time): on the shared 2-core VM
other jobs stretch wall time several-fold; the LSPI row gives the wall time too.
"""

from __future__ import annotations

import time

import numpy as np

from pairplay.core import kernels
from pairplay.core.actions import N_ACTIONS
from pairplay.core.lspi import LSPILearner, dense_sherman_morrison, features_of
from pairplay.core.personas import PERSONAS
from pairplay.core.rng import UniformStream, game_seed, stream_keys
from pairplay.core.simulate import run_games
from pairplay.schemas.config import LSPIConfig


def _samples(games: int, rounds: int):
    """(states, actions, rewards, learn) per lockstep step of a Q-learning run: (steps, games) each.

    From the run's recorded trace (core/simulate.py `record="all"`); a game past its
    last turn has learn False."""
    personas = list(PERSONAS.values())
    chosen = [personas[i % len(personas)] for i in range(games)]
    seeds = [game_seed(0, p.key, i) for i, p in enumerate(chosen)]
    trace = run_games(chosen, seeds, rounds, record="all").trace
    steps = int(trace["step"].max()) + 1
    cols = [np.zeros((steps, games), dtype=np.int64), np.zeros((steps, games), dtype=np.int64),
            np.zeros((steps, games)), np.zeros((steps, games), dtype=bool)]
    at = (trace["step"], trace["game"])
    cols[0][at], cols[1][at], cols[2][at] = trace["state"], trace["action"], trace["reward"]
    cols[3][at] = (trace["considered"] == 1) & (trace["from_memory"] == 0)
    return cols


def lspi_per_sample(games: int, rounds: int, config: LSPIConfig = LSPIConfig()) -> tuple[float, float, int]:
    """(CPU us, wall us per learned sample, samples): LSPILearner.learn over the recorded steps, `games` at once."""
    states, actions, rewards, learn = _samples(games, rounds)
    learner = LSPILearner(games, UniformStream(list(range(games)), "agent"), lspi=config)
    t, w = time.process_time(), time.perf_counter()
    for s, a, r, m in zip(states, actions, rewards, learn):
        learner.learn(s, a, r, m)
    cpu, wall = time.process_time() - t, time.perf_counter() - w
    n = int(learner.samples.sum())
    return 1e6 * cpu / n, 1e6 * wall / n, n


def dense_per_sample(n_features: int, samples: int = 5, seed: int = 0) -> float:
    """us per dense Sherman-Morrison update of an n x n inverse (binary phi, one block active)."""
    rng = np.random.default_rng(seed)
    inverse = np.eye(n_features)
    t = time.process_time()
    for _ in range(samples):
        u = np.zeros(n_features)
        u[rng.choice(n_features, 5, replace=False)] = 1.0
        inverse = dense_sherman_morrison(inverse, u, u)
    return 1e6 * (time.process_time() - t) / samples


def dense_solve(n_features: int, repeats: int = 2, seed: int = 0) -> float:
    """us per dense solve of line 12 (an n x n SPD system): the thesis's K = 0 paid one per sample."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n_features, n_features))
    a = x @ x.T + np.eye(n_features)
    b = rng.normal(size=n_features)
    t = time.process_time()
    for _ in range(repeats):
        np.linalg.solve(a, b)
    return 1e6 * (time.process_time() - t) / repeats


def env_and_core_rates(games: int = 2048, rounds: int = 3) -> tuple[float, float]:
    """(vector env steps/s, core simulator steps/s): the same fixed policy on the same 2,048 games."""
    from pairplay.gym import MemoryVectorEnv
    keys = list(PERSONAS)
    personas = [keys[i % len(keys)] for i in range(games)]
    seeds = [game_seed(0, k, i) for i, k in enumerate(personas)]
    policy = np.full(24, 35, dtype=np.int64)  # "try row x column y" + gaze: one suggestion everywhere
    kernels.warm_up()  # both sides run compiled kernels: compile (or cache load) before either is timed
    stream_keys(seeds)  # and derive the games' stream keys (~20 us each, then cached) for neither side to pay
    warm = MemoryVectorEnv(2, persona=personas[:2])
    warm_obs, _ = warm.reset(seed=[1, 2])
    warm.step(policy[warm_obs])
    t = time.process_time()
    core = run_games([PERSONAS[k] for k in personas], seeds, rounds, mode="fixed", policy=policy)
    core_rate = int(core.picks.sum()) // 2 / (time.process_time() - t)
    env = MemoryVectorEnv(games, persona=personas)
    t = time.process_time()
    obs, _ = env.reset(seed=seeds)
    steps = 0
    target = int(core.picks.sum()) // 2
    while steps < target:
        obs, _, _, _, _ = env.step(policy[obs])
        steps += games
    env_rate = steps / (time.process_time() - t)
    return env_rate, core_rate


def bench_rows(quick: bool = False) -> list[dict]:
    rows = []
    config = LSPIConfig()
    f = features_of(config).size
    per, wall, n = lspi_per_sample(80, 20 if quick else 100, config)
    dense = dense_per_sample(N_ACTIONS * f, 2 if quick else 5)
    rows.append(dict(row=f"online LSPI, amortised CPU per sample (80 games at once, {N_ACTIONS} blocks x {f} features, "
                         f"K={config.improve_every}; {n:,} samples; wall {wall:.0f} us)", value=per, unit="us",
                     reference=f"dense Sherman-Morrison update, n = {N_ACTIONS * f}", reference_value=dense,
                     ratio=per / dense, goal="lspi_sample"))
    one, _, _ = lspi_per_sample(1, 10 if quick else 40, config)
    thesis = dense_per_sample(2816, 3 if quick else 10)
    rows.append(dict(row="online LSPI, amortised per sample (one game: a live session)", value=one, unit="us",
                     reference="dense Sherman-Morrison update, n = 2816 (the thesis's)", reference_value=thesis,
                     ratio=one / thesis))
    solve = dense_solve(2816, 1 if quick else 3)
    rows.append(dict(row="algorithm 2 as the thesis ran it: one dense solve of line 12 per sample (K=0, n=2816)",
                     value=solve, unit="us", reference="online LSPI here, amortised per sample (80 games)",
                     reference_value=per, ratio=solve / per))  # context: why it took days
    env_rate, core_rate = env_and_core_rates(2048, 1 if quick else 3)
    rows.append(dict(row="pairplay.gym vector env, 2,048 games (fixed policy)", value=env_rate, unit="steps/s",
                     reference="core simulator, same games and policy", reference_value=core_rate,
                     ratio=env_rate / core_rate, goal="gym_vector"))
    return rows
