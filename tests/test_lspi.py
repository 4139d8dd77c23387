"""Online LSPI (core/lspi.py): exact ridge weights, block Sherman-Morrison, batch-independent bits, convergence."""

import numpy as np
import pytest

from pairplay.core import lspi
from pairplay.core.actions import N_ACTIONS
from pairplay.core.geometry import N_STATES
from pairplay.core.oracle import oracle_policies
from pairplay.core.personas import PERSONAS
from pairplay.core.rng import UniformStream, game_seed
from pairplay.core.simulate import run_games
from pairplay.core.study import evaluate
from pairplay.schemas.config import LSPIConfig


def test_the_features_separate_every_state_and_the_thesis_features_do_not():
    ours = lspi.tile_features()
    phi = lspi.feature_matrix(ours)
    assert phi.shape == (N_STATES, ours.size) and np.linalg.matrix_rank(phi) == N_STATES
    assert (phi.sum(1) == ours.active.shape[1]).all()  # one active tile per tiling
    # the coarse tilings alone generalise: fewer features than states' worth of distinctions
    assert np.linalg.matrix_rank(lspi.feature_matrix(lspi.tile_features(4, 2.0, exact=False))) < N_STATES
    # thesis 5.1.2/6.4: 32 tilings of 4x4 written into 32 indices per action, then 3
    assert lspi.THESIS_RANK < N_STATES
    assert np.linalg.matrix_rank(lspi.feature_matrix(lspi.thesis_features(3, 4, 3))) <= 3


def test_sutton_offsets_displace_each_tiling_asymmetrically():
    f = lspi.tile_features(tilings=2, tile_width=2.0, exact=False)
    # tiling 0 groups grid values {0,1}|{2}; tiling 1 (offset 1, 3, 5 steps x 2/2 mod 2) groups {0}|{1,2} in dim 0
    points = lspi.state_points()
    a, b = (points[:, 0] == 0) & (points[:, 1] == 0) & (points[:, 2] == 0), (points[:, 0] == 1) & (points[:, 1] == 0) & (points[:, 2] == 0)
    sa, sb = np.nonzero(a)[0][0], np.nonzero(b)[0][0]
    assert f.active[sa, 0] == f.active[sb, 0] and f.active[sa, 1] != f.active[sb, 1]


def test_weights_are_the_ridge_regression_of_the_rewards_per_action_block():
    rng = np.random.default_rng(1)
    cfg = LSPIConfig(ridge=0.5, improve_every=7)
    learner = lspi.LSPILearner(1, UniformStream([3], "agent"), lspi=cfg)
    states = rng.integers(0, N_STATES, 700)
    actions = rng.integers(0, 4, 700)  # few actions: blocks with many samples
    rewards = rng.normal(size=700)
    for s, a, r in zip(states, actions, rewards):
        learner.learn(np.array([s]), np.array([a]), np.array([r]), np.array([True]))
    assert learner.samples[0] == 700 and learner.improvements[0] == 100
    phi = lspi.feature_matrix(learner.features)
    for a in range(4):
        x = phi[states[actions == a]]
        gamma = cfg.ridge * np.eye(phi.shape[1]) + x.T @ x
        theta = np.linalg.solve(gamma, x.T @ rewards[actions == a])
        assert np.allclose(learner.inverse[0, a], np.linalg.inv(gamma), atol=1e-9)
        assert np.allclose(learner.theta[0, a], theta, atol=1e-9)
        assert np.allclose(learner.q[0, :, a], phi @ theta, atol=1e-9)
    assert (learner.q[0, :, 4:] == 0).all() and (learner.inverse[0, 4] == np.eye(phi.shape[1]) / cfg.ridge).all()


def test_the_policy_changes_only_every_k_samples():
    learner = lspi.LSPILearner(1, UniformStream([3], "agent"), lspi=LSPIConfig(improve_every=3))
    seen = []
    for k in range(7):
        learner.learn(np.array([k % 5]), np.array([k]), np.array([1.0]), np.array([True]))
        seen.append(learner.q.copy())
    assert (seen[0] == 0).all() and (seen[1] == 0).all() and (seen[2] != 0).any()
    assert (seen[3] == seen[2]).all() and (seen[4] == seen[2]).all() and (seen[5] != seen[4]).any()


def test_a_game_alone_learns_the_same_bits_as_in_a_batch():
    deaf, vincent = PERSONAS["deaf"], PERSONAS["vincent"]
    s = [game_seed(3, "deaf", 0), game_seed(3, "vincent", 0), game_seed(3, "deaf", 1)]
    batch = run_games([deaf, vincent, deaf], s, 25, mode="lspi")
    alone = run_games([vincent], s[1:2], 25, mode="lspi")
    assert (batch.q[1] == alone.q[0]).all() and (batch.picks[1] == alone.picks[0]).all()
    assert (batch.counts[1] == alone.counts[0]).all() and alone.counts.sum() > 100


def test_lspi_config_refuses_what_cannot_run():
    for bad in (dict(ridge=0), dict(improve_every=0), dict(gamma=1.0), dict(tilings=0, exact=False),
                dict(tile_width=0.5)):
        with pytest.raises(ValueError, match="lspi"):
            LSPIConfig(**bad)


def test_the_dense_reference_update_is_the_inverse_of_the_rank_one_sum():
    rng = np.random.default_rng(0)
    a = np.eye(6) * 2.0
    inv = np.linalg.inv(a)
    for _ in range(5):
        u = rng.normal(size=6)
        a = a + np.outer(u, u)
        inv = lspi.dense_sherman_morrison(inv, u, u)
    assert np.allclose(inv, np.linalg.inv(a))


def test_lspi_greedy_policies_reach_the_oracle_within_1_10x_in_80_rounds():
    """The must-show in small (the study report has the full one): focus >= 5, 80 rounds of LSPI, mean over 3 games."""
    personas = [PERSONAS["tatiana"], PERSONAS["blind"]]
    games = [p for p in personas for _ in range(3)]
    seeds = [game_seed(0, p.key, g) for p in personas for g in range(3)]
    res = run_games(games, seeds, 80, mode="lspi")
    greedy = np.argmax(res.q, -1)  # ties (untrained states) go to code 0, "do nothing"
    oracle, _ = oracle_policies(personas, 10, 0, 100)
    learned = evaluate(games, greedy, 60, 0).reshape(2, 3)
    best = evaluate(personas, oracle, 60, 0)
    assert (learned.mean(1) <= 1.10 * best).all(), (learned, best)
    assert res.q.shape == (6, N_STATES, N_ACTIONS)


def test_an_lspi_batch_refuses_what_only_the_compiled_runner_does():
    deaf = PERSONAS["deaf"]
    with pytest.raises(ValueError, match="trace"):
        run_games([deaf], [1], 2, mode="lspi", record="all")
    with pytest.raises(ValueError, match="one rounds count"):
        run_games([deaf, deaf], [1, 2], [2, 3], mode="lspi")
    empty = run_games([deaf], [1], 0, mode="lspi")
    assert empty.picks.shape == (1, 0) and empty.turns == 0
