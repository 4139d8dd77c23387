"""pi-reuse (algorithm 5): the bias policy is followed with psi, psi decays by v and resets each round."""

import numpy as np
import pytest

from pairplay.core.learning import How, Learner
from pairplay.core.rng import UniformStream
from pairplay.schemas.config import LearnerConfig

N = 20_000


def reuse_learner(**config):
    bias = np.full(24, 7)
    return Learner(N, UniformStream(range(N), "agent"), LearnerConfig(**config), mode="reuse", bias=bias)


def bias_share(learner, round_index=0):
    actions, how = learner.suggest(np.zeros(N, dtype=np.int64), np.full(N, round_index))
    assert (actions[how == How.BIAS] == 7).all()
    return np.mean(how == How.BIAS)


def test_psi_decays_by_v_every_suggestion_and_resets_every_round():
    learner = reuse_learner(psi_start=0.8, psi_decay=0.5)
    learner.start_round(np.zeros(N, dtype=np.int64))
    shares = [bias_share(learner) for _ in range(4)]
    assert shares == pytest.approx([0.8, 0.4, 0.2, 0.1], abs=0.015)
    learner.start_round(np.ones(N, dtype=np.int64))
    assert bias_share(learner, 1) == pytest.approx(0.8, abs=0.015)


def test_the_rest_is_epsilon_greedy_on_the_new_q():
    learner = reuse_learner(psi_start=0.5, psi_decay=1.0, epsilon_start=0.4, epsilon_step=0.0)
    learner.q[:, 0, 30] = 1.0
    learner.start_round(np.zeros(N, dtype=np.int64))
    _, how = learner.suggest(np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.int64))
    assert np.mean(how == How.BIAS) == pytest.approx(0.5, abs=0.015)
    assert np.mean(how == How.EXPLORE) == pytest.approx(0.5 * 0.4, abs=0.015)
    assert np.mean(how == How.GREEDY) == pytest.approx(0.5 * 0.6, abs=0.015)


def test_the_last_rounds_use_the_new_policy_alone():
    learner = reuse_learner(psi_start=1.0, psi_decay=1.0, reuse_rounds=3)
    learner.start_round(np.full(N, 2))
    assert bias_share(learner, 2) == 1.0
    learner.start_round(np.full(N, 3))
    assert bias_share(learner, 3) == 0.0


def test_psi_can_also_fall_round_after_round_as_in_the_human_study():
    config = LearnerConfig.human_phase2(5)
    learner = Learner(N, UniformStream(range(N), "agent"), config, mode="reuse", bias=np.full(24, 7))
    starts = []
    for r in range(5):
        learner.start_round(np.full(N, r))
        starts.append(bias_share(learner, r))
    assert starts == pytest.approx([1.0, 0.8, 0.64, 0.512, 0.0], abs=0.015)


def test_reuse_needs_a_bias_policy():
    with pytest.raises(ValueError, match="bias"):
        Learner(1, UniformStream([1], "agent"), mode="reuse")
