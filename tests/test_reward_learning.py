"""Rewards (4.3, 6.1.3, 7.1.2), the one-step update (5.2), schedules (6.2, 7.2), tie-breaking."""

import numpy as np
import pytest

from pairplay.core.learning import (DRAWS_PER_SUGGESTION, How, Learner, alpha_at, epsilon_at, greedy,
                                    greedy_policy, psi_round_start, q_update)
from pairplay.core.reward import human_reward, simulated_reward
from pairplay.core.rng import UniformStream
from pairplay.schemas.config import LearnerConfig

T, F = True, False


@pytest.mark.parametrize("matched, considered, consistent, size, holds, reward, learn", [
    (T, T, T, 1, T, 2.0, T),  # match with an exact suggestion: +1 + 1/1
    (T, T, T, 4, T, 1.25, T),  # match among four candidates
    (F, T, T, 3, T, -1 + 1 / 3, T),  # miss in a candidate set that held the match
    (F, T, T, 1, F, -1.0, T),  # a precise wrong suggestion: no bonus for pointing away
    (F, T, T, 3, F, -1.0, T),
    (T, T, F, 0, F, -3.0, T),  # inconsistent: -3 alone, whatever the pick
    (F, T, F, 0, F, -3.0, T),
    (T, F, T, 2, T, 0.0, F),  # ignored (by focus or picked from memory): no update
])
def test_simulated_reward(matched, considered, consistent, size, holds, reward, learn):
    r, ok = simulated_reward(np.array([matched]), np.array([considered]), np.array([consistent]), np.array([size]),
                             np.array([holds]))
    assert r[0] == pytest.approx(reward) and ok[0] == learn


@pytest.mark.parametrize("matched, size, holds, reward", [(T, 1, T, 2.0), (F, 3, T, -1 + 1 / 3), (F, 1, F, 0.0),
                                                          (F, 4, F, -0.75)])
def test_spec_literal_reading_pays_the_bonus_on_every_consistent_suggestion(matched, size, holds, reward):
    r, ok = simulated_reward(np.array([matched]), np.array([T]), np.array([T]), np.array([size]), np.array([holds]),
                             bonus="consistent")
    assert r[0] == pytest.approx(reward) and ok[0]


def test_human_reward_ignores_picks_closer_than_1_5_s():
    assert human_reward(True, 2.0) == (1.0, True)
    assert human_reward(False, 1.5) == (-1.0, True)
    assert human_reward(True, 1.49) == (0.0, False)


def test_the_one_step_update():
    assert q_update(0.0, 2.0, 0.5) == 1.0
    assert q_update(1.0, -3.0, 0.25) == 0.0


def test_virtual_study_schedules():
    c = LearnerConfig()
    eps = epsilon_at(c, np.arange(500))
    alpha = alpha_at(c, np.arange(500))
    assert eps[0] == 0.9 and eps[49] == 0.9 and eps[50] == 0.8 and eps[399] == pytest.approx(0.2)
    assert eps[400] == pytest.approx(0.1) and eps[499] == pytest.approx(0.1)
    assert eps.min() == pytest.approx(0.1) and epsilon_at(c, 10_000) == pytest.approx(0.1)
    assert alpha[0] == 0.5 and alpha[50] == 0.45 and alpha[449] == pytest.approx(0.1)
    assert alpha[450] == pytest.approx(0.05) and alpha_at(c, 10_000) == pytest.approx(0.05)


def test_human_study_schedule_loses_a_fifth_of_0_9_each_round():
    c = LearnerConfig.human_phase1(5)
    assert epsilon_at(c, np.arange(5)) == pytest.approx([0.9, 0.72, 0.54, 0.36, 0.18])
    reuse = LearnerConfig.human_phase2(5)
    assert psi_round_start(reuse, 4) == 0.0 and psi_round_start(reuse, 0) == 1.0


def test_ties_are_broken_uniformly_by_the_draw_not_by_index():
    q = np.zeros((1, 88))
    q[0, [5, 40, 77]] = 1.0
    picks = [greedy(q, np.array([u]))[0] for u in (0.0, 0.34, 0.67, 0.999)]
    assert picks == [5, 40, 77, 77]
    many = greedy(np.repeat(q, 3000, 0), np.random.default_rng(0).random(3000))
    counts = np.bincount(many, minlength=88)[[5, 40, 77]]
    assert counts.min() > 900 and counts.sum() == 3000


def test_greedy_policy_is_seeded():
    q = np.zeros((24, 88))
    a = greedy_policy(q, np.random.default_rng(1))
    assert (a == greedy_policy(q, np.random.default_rng(1))).all()
    assert (a != greedy_policy(q, np.random.default_rng(2))).any()


def test_learner_explores_with_epsilon_and_learns_with_alpha():
    stream = UniformStream(range(2000), "agent")
    learner = Learner(2000, stream, LearnerConfig())
    learner.q[:, 3, 10] = 1.0
    actions, how = learner.suggest(np.full(2000, 3), np.zeros(2000, dtype=int))  # epsilon 0.9
    greedy_share = np.mean(how == How.GREEDY)
    assert 0.05 < greedy_share < 0.15 and (actions[how == How.GREEDY] == 10).all()
    assert stream.drawn[0] == DRAWS_PER_SUGGESTION
    states, acts = np.full(2000, 3), np.full(2000, 10)
    learner.learn(states, acts, np.full(2000, 2.0), np.arange(2000) < 1000, np.full(2000, 50))
    assert (learner.q[:1000, 3, 10] == 1.0 + 0.45 * (2.0 - 1.0)).all() and (learner.q[1000:, 3, 10] == 1.0).all()
    assert learner.counts[0, 3, 10] == 1 and learner.counts[1500].sum() == 0


def test_a_fixed_policy_acts_and_never_learns():
    policy = np.arange(24) % 88
    learner = Learner(3, UniformStream([1, 2, 3], "agent"), mode="fixed", policy=policy)
    actions, how = learner.suggest(np.array([0, 5, 23]), np.zeros(3, dtype=int))
    assert actions.tolist() == [0, 5, 23] and (how == How.FIXED).all()
    learner.learn(np.array([0, 5, 23]), actions, np.ones(3), np.ones(3, bool), np.zeros(3, dtype=int))
    assert not learner.q.any()


def test_learner_refuses_a_bad_policy():
    with pytest.raises(ValueError, match="policy"):
        Learner(1, UniformStream([1], "agent"), mode="fixed", policy=np.full(24, 88))
    with pytest.raises(ValueError, match="agent"):
        Learner(1, UniformStream([1], "user"))


@pytest.mark.parametrize("matched, size, reward", [(T, 1, 2.0), (T, 4, 1.25), (F, 1, -1.0), (F, 3, -1.0)])
def test_the_other_reading_pays_the_bonus_on_a_match_only(matched, size, reward):
    r, ok = simulated_reward(np.array([matched]), np.array([T]), np.array([T]), np.array([size]), np.array([T]),
                             bonus="match")
    assert r[0] == pytest.approx(reward) and ok[0]
    r, _ = simulated_reward(np.array([matched]), np.array([T]), np.array([F]), np.array([0]), np.array([F]),
                            bonus="match")
    assert r[0] == -3.0
    with pytest.raises(ValueError, match="bonus"):
        simulated_reward(np.array([T]), np.array([T]), np.array([T]), np.array([1]), np.array([T]), bonus="always")


@pytest.mark.parametrize("bonus", ["correct", "consistent", "match"])
def test_a_turns_reward_alone_is_the_batch_rule(bonus):
    """simulated_reward_one (a live learner's turn) is simulated_reward's rule on every input."""
    from pairplay.core.reward import simulated_reward_one
    for matched, considered, consistent, holds in np.ndindex(2, 2, 2, 2):
        for size in (0, 1, 3, 18):
            r, ok = simulated_reward(np.array([matched]), np.array([considered]), np.array([consistent]),
                                     np.array([size]), np.array([holds]), bonus)
            one = simulated_reward_one(bool(matched), bool(considered), bool(consistent), size, bool(holds), bonus)
            assert one == (float(r[0]), bool(ok[0])) and type(one[0]) is float and type(one[1]) is bool
    with pytest.raises(ValueError):
        simulated_reward_one(True, True, True, 1, True, "nonsense")


@pytest.mark.parametrize("mode", ["q", "reuse"])
def test_a_learner_of_one_game_is_that_game_of_a_batch_across_its_schedule_tables(mode):
    """Learner(1) (the live path: views of its schedule tables, grown past 64 and 128 rounds) and the
    same game in a batch of three (fancy-indexed tables) suggest, learn and decay psi alike, and
    the tables hold the schedules' own values."""
    config = LearnerConfig(psi_start=0.9, psi_decay=0.95)
    bias = np.arange(24) % 88
    one = Learner(1, UniformStream([7], "agent"), config, mode, bias=bias if mode == "reuse" else None)
    three = Learner(3, UniformStream([5, 7, 9], "agent"), config, mode, bias=bias if mode == "reuse" else None)
    rng = np.random.default_rng(0)
    for r in range(0, 300, 3):
        one.start_round(np.array([r]))
        three.start_round(np.array([r, r, r]))
        assert one.psi[0] == three.psi[1] == psi_round_start(config, r)
        assert one.schedule(r) == (float(epsilon_at(config, r)), float(alpha_at(config, r)))
        for _ in range(4):
            s = rng.integers(0, 24, 3)
            a1, h1 = one.suggest(s[1:2], np.array([r]))
            a3, h3 = three.suggest(s, np.array([r, r, r]))
            assert (a1[0], h1[0]) == (a3[1], h3[1])
            reward = rng.normal(size=3)
            one.learn(s[1:2], a1, reward[1:2], np.ones(1, dtype=bool), np.array([r]))
            three.learn(s, a3, reward, np.ones(3, dtype=bool), np.array([r, r, r]))
    assert np.array_equal(one.q[0], three.q[1]) and one.psi[0] == three.psi[1]


@pytest.mark.parametrize("mode", ["q", "reuse", "fixed"])
def test_a_batch_of_one_suggests_and_learns_as_the_batch_does(mode):
    """suggest_one / learn_one (the live learner's path) draw, choose and update exactly as suggest / learn."""
    rng = np.random.default_rng(3)
    table = rng.integers(0, 88, 24)
    kw = dict(bias=table if mode == "reuse" else None, policy=table if mode == "fixed" else None)
    config = LearnerConfig()
    batch, one = (Learner(1, UniformStream([77], "agent"), config, mode, **kw) for _ in range(2))
    for step in range(600):
        r = step // 12
        if step % 12 == 0:
            batch.start_round(np.array([r]))
            one.start_round(np.array([r]))
        s = int(rng.integers(0, 24))
        actions, how = batch.suggest(np.array([s]), np.array([r]))
        assert one.suggest_one(s, r) == (int(actions[0]), int(how[0]))
        reward = float(rng.choice([-3.0, -1.0, 0.5, 2.0]))
        batch.learn(np.array([s]), actions, np.array([reward]), np.array([True]), np.array([r]))
        one.learn_one(s, int(actions[0]), reward, r)
    assert np.array_equal(batch.q, one.q) and np.array_equal(batch.counts, one.counts)
    assert np.array_equal(batch.psi, one.psi) and np.array_equal(batch.stream.positions, one.stream.positions)
    if mode != "fixed":
        assert batch.counts.sum() == 600


def test_batch_of_one_paths_refuse_a_bigger_batch():
    learner = Learner(2, UniformStream([1, 2], "agent"))
    with pytest.raises(ValueError, match="one game"):
        learner.suggest_one(0, 0)
    with pytest.raises(ValueError, match="one game"):
        learner.learn_one(0, 0, 1.0, 0)
