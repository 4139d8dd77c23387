"""The reference agents: the user alone and the oracle's exact expected rewards."""

import numpy as np
import pytest

from pairplay.core.actions import code_of_parts
from pairplay.core.geometry import ALL_CARDS, card_of
from pairplay.core.oracle import USER_ALONE, expected_rewards, oracle_policies
from pairplay.schemas.config import Persona


def persona(hearing=6, sight=6):
    return Persona(key=f"h{hearing}s{sight}", name="X", focus=6, memory=3, hearing=hearing, sight=sight)


OBS, MATCH = card_of(1, 2), card_of(1, 4)  # MATCH is RIGHT of OBS
NIS = ALL_CARDS & ~(1 << card_of(0, 0))
EXACT = code_of_parts(2, 0, 0, 0)
NOTHING = code_of_parts(0, 0, 0, 0)
WRONG_WAY = code_of_parts(0, 0, 2, 0)  # head left: the match is right
RIGHT_CELL = code_of_parts(6, 0, 0, 0)  # "Maybe right": (1,3) (1,4) (1,5)


def value(size, hit):
    """A uniform pick in `size` cards, `hit` of them the match; the default bonus rule ("correct")."""
    return 2.0 * hit / size - 1 + hit / size


def e(p, action, bonus="correct"):
    return expected_rewards(p, np.array([OBS]), np.array([MATCH]), np.array([NIS]), bonus)[0, action]


def test_a_user_who_hears_gets_the_exact_position_for_sure():
    assert e(persona(), EXACT) == pytest.approx(2.0)
    assert e(persona(), RIGHT_CELL) == pytest.approx(value(3, 1))


def test_speech_counts_with_the_probability_of_hearing_it():
    nis = value(17, 1)
    assert e(persona(hearing=1), EXACT) == pytest.approx(nis)
    assert e(persona(hearing=4), EXACT) == pytest.approx(0.6 * 2.0 + 0.4 * nis)
    assert e(persona(), NOTHING) == pytest.approx(nis)


def test_a_visual_part_the_user_cannot_see_changes_nothing():
    assert e(persona(), WRONG_WAY) == pytest.approx(value(2, 0))  # (1,0) (1,1): a sure miss, two candidates
    assert e(persona(sight=1), WRONG_WAY) == pytest.approx(value(17, 1))
    inconsistent = code_of_parts(2, 0, 2, 0)  # exact position + head left
    assert e(persona(), inconsistent) == pytest.approx(-3.0)
    assert e(persona(hearing=1), inconsistent) == pytest.approx(value(2, 0))  # only the head is read


def test_the_oracle_of_a_user_who_hears_is_worth_a_sure_match_everywhere():
    policies, tables = oracle_policies([persona(), persona(hearing=1, sight=1)], 4, 0, rounds=20)
    visited = tables[0].any(axis=1)
    assert tables[0][visited].max(axis=1) == pytest.approx(2.0)
    assert tables[0][visited, EXACT] == pytest.approx(2.0)  # saying the position is one of the best
    chosen = tables[0][np.arange(24), policies[0]]
    assert chosen[visited] == pytest.approx(2.0)
    assert (USER_ALONE == NOTHING).all()
    # Blind and deaf: nothing can be perceived, every action is worth the NIS.
    row = tables[1][tables[1].any(axis=1)]
    assert np.allclose(row, row[:, :1])


def test_each_bonus_rule_values_a_sure_miss_and_an_honest_hint():
    wrong_card = code_of_parts(1, 0, 0, 0)  # "It is the right card" while the match is elsewhere
    assert e(persona(), wrong_card) == pytest.approx(-1.0)  # correct: no bonus for pointing away
    assert e(persona(), wrong_card, "consistent") == pytest.approx(0.0)  # SPEC: -1 + 1/1
    assert e(persona(), wrong_card, "match") == pytest.approx(-1.0)
    assert e(persona(), RIGHT_CELL) == e(persona(), RIGHT_CELL, "consistent") == pytest.approx(2 / 3 - 1 + 1 / 3)
    assert e(persona(), RIGHT_CELL, "match") == pytest.approx(2 / 3 - 1 + (1 / 3) / 3)
    for bonus in ("correct", "consistent", "match"):
        assert e(persona(), EXACT, bonus) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="bonus"):
        e(persona(), EXACT, "always")


def test_policy_gaps_name_the_states_where_learned_policies_lose_expected_reward():
    from pairplay.core import study
    from pairplay.core.personas import PERSONAS
    deaf = PERSONAS["deaf"]
    training = study.train([deaf], games=2, rounds=20, seed=3)
    cmp = study.compare([deaf], training, eval_rounds=2, seed=3, oracle_rounds=20, oracle_games=4)
    gaps = study.policy_gaps(cmp, training, 0, top=4)
    assert 0 < len(gaps) <= 4 and [g[-1] for g in gaps] == sorted((g[-1] for g in gaps), reverse=True)
    for state, modal, v_modal, best, v_best, loss in gaps:
        assert v_best == cmp.oracle_values[0, state].max() >= v_modal and loss >= 0
