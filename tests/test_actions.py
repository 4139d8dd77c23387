"""The 88 composite actions keep the thesis's codes (section 4.2, figure 6.6)."""

import pytest

from pairplay.core import actions as A


def test_there_are_88_actions_and_codes_round_trip():
    assert A.N_ACTIONS == 88
    for act in A.ACTIONS:
        assert A.code_of_parts(act.speech, act.facial, act.head, act.gaze) == act.code


def test_exact_position_speech_is_codes_33_to_43():
    exact = [a.code for a in A.ACTIONS if a.speech == A.SPEECH_EXACT]
    assert exact == list(range(33, 44))


def test_exclusions_hold_for_every_action():
    for act in A.ACTIONS:
        assert not (act.speech and act.facial), act
        assert not (act.head and act.gaze), act


def test_some_codes_by_name():
    assert A.action(0).name == "do nothing"
    assert A.action(1).gaze == 1 and A.action(1).head == 0
    assert A.action(11).facial == 1 and A.action(11).speech == 0
    assert A.action(22).speech == 1  # "It is the right card"
    assert A.action(2).head == 1  # nod
    assert A.action(87) == A.Action(87, 6, 0, 9, 0)  # maybe right + turn down-right


def test_impossible_combinations_are_refused():
    with pytest.raises(ValueError, match="exclude each other"):
        A.code_of_parts(3, 1, 0, 0)
    with pytest.raises(ValueError, match="exclude each other"):
        A.code_of_parts(0, 0, 4, 1)
    with pytest.raises(ValueError):
        A.action(88)
