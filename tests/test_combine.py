"""Algorithms 3 and 4 (thesis 5.2): user information, the action algebra, merged info, order."""

import itertools

import numpy as np
import pytest

from pairplay.core.actions import code_of_parts
from pairplay.core.combine import MATCH_STATE, User, combine, extract_info, merge_info, trained_states
from pairplay.core.geometry import N_STATES
from pairplay.schemas.policy import UserInfo

S = 3  # a spatial state that is not MATCH
NOTHING, EXACT = code_of_parts(0, 0, 0, 0), code_of_parts(2, 0, 0, 0)


def act(speech=0, facial=0, head=0, gaze=0):
    return code_of_parts(speech, facial, head, gaze)


def user(name, action_at_s, speech_err=0.0, head_err=0.0, gaze=True, q_at_s=0.0):
    policy = np.full(N_STATES, NOTHING)
    policy[S] = action_at_s
    q = np.zeros((N_STATES, 88))
    q[S, action_at_s] = q_at_s
    return User(name, policy, q, UserInfo(speech=speech_err, head=head_err, facial=True, gaze=gaze))


def merged(a, b):
    out = combine([a, b])
    return out.policy[S], out.rules[S]


# Table 5.1: hearing suggestions (speech and facial), users with equal speech errors.
@pytest.mark.parametrize("first, second, result", [
    (act(speech=5), act(speech=5), act(speech=5)),  # action i + action i = action i
    (act(), act(speech=3), act(speech=3)),  # nothing + action i = action i
    (act(speech=6), act(), act(speech=6)),
    (act(speech=2), act(speech=4), act(speech=2)),  # exact position + action i = exact position
    (act(facial=1), act(speech=2), act(speech=2)),
    (act(facial=1), act(facial=1), act(facial=1)),
])
def test_table_5_1(first, second, result):
    assert merged(user("a", first), user("b", second))[0] == result


# Table 5.2: visual suggestions (head and gaze), users with equal head errors.
@pytest.mark.parametrize("first, second, both_see_gaze, result", [
    (act(head=3), act(head=3), True, act(head=3)),  # action i + action i
    (act(), act(head=7), True, act(head=7)),  # nothing + action i
    (act(gaze=1), act(head=2), False, act(head=2)),  # gaze + i = i when one user does not perceive gaze
    (act(gaze=1), act(head=2), True, act(gaze=1)),  # gaze + i = gaze when both do
    (act(gaze=1), act(), False, act(gaze=1)),  # nothing + gaze = gaze
    (act(gaze=1), act(gaze=1), False, act(gaze=1)),
])
def test_table_5_2(first, second, both_see_gaze, result):
    a = user("a", first)
    b = user("b", second, gaze=both_see_gaze)
    assert merged(a, b)[0] == result


def test_other_pairs_are_errors_resolved_by_the_users_q_values():
    left, right = act(speech=5), act(speech=6)
    code, rule = merged(user("a", left, q_at_s=0.4), user("b", right, q_at_s=0.9))
    assert code == right and "error->Q" in rule
    code, _ = merged(user("a", left, q_at_s=0.9), user("b", right, q_at_s=0.4))
    assert code == left
    code, rule = merged(user("a", act(head=2), q_at_s=0.1), user("b", act(head=4), q_at_s=0.2))
    assert code == act(head=4) and "visual=sum:error->Q" in rule
    code, _ = merged(user("a", act(facial=1), q_at_s=1.0), user("b", act(speech=3), q_at_s=0.0))
    assert code == act(facial=1)  # smile + "maybe up" is an Error too


def test_the_user_with_fewer_errors_gives_that_half():
    deafish = user("deaf", act(speech=4, head=3), speech_err=1.0, head_err=0.0)
    blindish = user("blind", act(speech=2, head=7), speech_err=0.0, head_err=1.0)
    code, rule = merged(deafish, blindish)
    assert code == act(speech=2, head=3)
    assert rule == "hearing=fewer-errors(blind); visual=fewer-errors(deaf)"


def test_merged_information_is_min_of_errors_and_and_of_booleans():
    a = UserInfo(speech=0.2, head=0.5, facial=True, gaze=False, compared_states=23)
    b = UserInfo(speech=0.4, head=0.1, facial=True, gaze=True, compared_states=23)
    assert merge_info([a, b]) == UserInfo(speech=0.2, head=0.1, facial=True, gaze=False, compared_states=23)
    out = combine([user("a", act(), 0.2, 0.5, gaze=False), user("b", act(), 0.4, 0.1)])
    assert out.info.speech == 0.2 and out.info.head == 0.1 and out.info.gaze is False


def _policies(*actions_at_s, state=S):
    rows = np.full((len(actions_at_s), N_STATES), NOTHING)
    rows[:, state] = actions_at_s
    return rows


def test_algorithm_3_counts_different_parts_as_incompatible():
    prof = extract_info(_policies(act(speech=5), act(speech=6)))
    assert prof.speech_states == [S] and prof.info.speech == pytest.approx(1 / 23)
    prof = extract_info(_policies(act(head=2), act(head=9)))
    assert prof.head_states == [S] and prof.info.head == pytest.approx(1 / 23)


def test_algorithm_3_exceptions_nothing_and_the_exact_card():
    assert extract_info(_policies(act(speech=5), act(), act(speech=2))).speech_states == []  # thesis example
    assert extract_info(_policies(act(head=2), act(), act(gaze=1))).head_states == []
    # "It is the right card" and the nod point at the exact card only where observed = match
    assert extract_info(_policies(act(speech=1), act(speech=5))).speech_states == [S]
    assert extract_info(_policies(act(speech=1), act(speech=5), state=MATCH_STATE)).speech_states == []
    assert extract_info(_policies(act(head=1), act(head=3), state=MATCH_STATE)).head_states == []
    assert extract_info(_policies(act(head=1), act(head=3))).head_states == [S]


def test_algorithm_3_smile_and_gaze_are_present_in_any_policy():
    prof = extract_info(_policies(act(), act(facial=1)))
    assert prof.info.facial and not prof.info.gaze
    prof = extract_info(_policies(act(gaze=1), act()))
    assert prof.info.gaze and not prof.info.facial
    assert prof.info.compared_states == 23
    # The extra state (cards turned != 1) is never compared.
    assert extract_info(_policies(act(speech=5), act(speech=6), state=N_STATES - 1)).speech_states == []


def test_profiles_over_trained_states_leave_out_what_some_policy_seldom_updated():
    policies = _policies(act(speech=5), act(speech=6))  # disagree in state S only
    updates = np.full((2, N_STATES), 80)
    updates[1, S] = 12  # the second policy hardly trained S
    states = trained_states(updates, 50)
    assert S not in states and len(states) == 22 and N_STATES - 1 not in states
    prof = extract_info(policies, states)
    assert prof.speech_states == [] and prof.info.compared_states == 22
    assert extract_info(policies, trained_states(updates, 10)).info.speech == pytest.approx(1 / 23)
    assert trained_states(updates, 81).size == 0
    with pytest.raises(ValueError, match="no states"):
        extract_info(policies, [])


def test_combining_many_users_does_not_depend_on_their_order():
    rng = np.random.default_rng(4)
    users = []
    for i in range(4):
        q = rng.normal(size=(N_STATES, 88))
        users.append(User(f"u{i}", rng.integers(0, 88, N_STATES), q,
                          UserInfo(speech=float(rng.choice([0, 0.1])), head=float(rng.choice([0, 0.2])),
                                   facial=bool(rng.integers(2)), gaze=bool(rng.integers(2)))))
    results = {tuple(combine(list(order)).policy) for order in itertools.permutations(users)}
    assert len(results) == 1
    rules = {tuple(combine(list(order)).rules) for order in itertools.permutations(users)}
    assert len(rules) == 1


def test_two_users_without_errors_equal_any_pairwise_fold_of_three():
    a = user("a", act(speech=2), speech_err=0.1)
    b = user("b", act(head=4))
    c = user("c", act(speech=2, head=4), head_err=0.3)
    three = combine([a, b, c]).policy[S]
    ab = combine([a, b])
    folded = combine([User("ab", ab.policy, ab.q, ab.info), c]).policy[S]
    assert three == folded == act(speech=2, head=4)


def test_combine_needs_a_user():
    with pytest.raises(ValueError):
        combine([])
