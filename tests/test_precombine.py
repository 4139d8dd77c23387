"""Per-user pre-combination (thesis ch. 8, future work 3): a user's own policies merged first."""

import numpy as np

from pairplay.core import study
from pairplay.core.actions import code_of
from pairplay.core.combine import combine, extract_info
from pairplay.core.personas import persona
from pairplay.core.precombine import STRATEGIES, combination_experiment, precombine, represent_all


def test_a_user_whose_policies_agree_is_that_policy():
    rng = np.random.default_rng(1)
    policy = rng.integers(0, 88, 24)
    q = rng.normal(size=(3, 24, 88))
    user = precombine("u", np.stack([policy] * 3), q)
    assert np.array_equal(user.policy, policy)
    assert user.info == extract_info(np.stack([policy] * 3)).info


def test_parts_that_say_nothing_give_way_to_the_parts_that_say_something():
    # policy 0: "Maybe left" and no visual part; policy 1: nothing heard, head left (state 0)
    a = np.full(24, code_of(0, 0))
    b = np.full(24, code_of(0, 0))
    a[0], b[0] = code_of(5, 0), code_of(0, 4)
    user = precombine("u", np.stack([a, b]), np.zeros((2, 24, 88)))
    assert user.policy[0] == code_of(5, 4)


def test_the_experiment_merges_three_ways_on_disjoint_games_and_is_deterministic():
    personas = [persona("blind"), persona("deaf")]
    training = study.train(personas, 4, 60, 7)
    one = combination_experiment(personas, training, 7, replicates=2, eval_games=2, eval_rounds=20)
    two = combination_experiment(personas, training, 7, replicates=2, eval_games=2, eval_rounds=20)
    assert one.strategies == STRATEGIES and one.picks.shape == (3, 2, 2)
    assert np.array_equal(one.picks, two.picks)
    assert (one.picks >= 18).all()
    users = represent_all(personas, {p.key: training.greedy[i * 4:(i + 1) * 4:2] for i, p in enumerate(personas)},
                          {p.key: training.result.q[i * 4:(i + 1) * 4:2] for i, p in enumerate(personas)}, 7, 0)
    assert [len(users[s]) for s in STRATEGIES] == [2, 4, 2]
    assert np.array_equal(combine(users["pre-combined"]).policy, one.merged[2][0].policy)
