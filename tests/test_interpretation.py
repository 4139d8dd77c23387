"""Appendix B row by row, and perception by sight (table 6.1) and hearing (eq. 6.3)."""

import pytest

from pairplay.core import interpretation as I
from pairplay.core.actions import code_of_parts, HEARING_PARTS, VISUAL_PARTS
from pairplay.core.geometry import ALL_CARDS, card_of

OBS = card_of(1, 2)  # the observed card, in the middle row
MATCH = card_of(0, 4)  # the matching card: TOP_RIGHT of it


def cards(*rc):
    m = 0
    for r, c in rc:
        m |= 1 << card_of(r, c)
    return m


def hear(speech, facial=0):
    return int(I.HEAR_SET[OBS, MATCH, HEARING_PARTS.index((speech, facial))])


def see(head, gaze=0):
    return int(I.VIS_SET[OBS, MATCH, VISUAL_PARTS.index((head, gaze))])


def test_table_b1_speech():
    assert hear(0) == ALL_CARDS  # say nothing: no information
    assert hear(1) == cards((1, 2))  # "It is the right card": the observed card
    assert hear(2) == cards((0, 4))  # "Try at row x and column y": the matching card
    assert hear(3) == cards((0, 2))  # "Maybe up": same column, above
    assert hear(4) == cards((2, 2))  # "Maybe down"
    assert hear(5) == cards((1, 0), (1, 1))  # "Maybe left": same row, left
    assert hear(6) == cards((1, 3), (1, 4), (1, 5))  # "Maybe right"


def test_table_b2_facial():
    assert hear(0, 1) == cards((1, 2))  # smile: the observed card


def test_table_b3_head():
    assert see(0) == ALL_CARDS
    assert see(1) == cards((1, 2))  # nod: the observed card
    assert see(2) == cards((1, 0), (1, 1))  # left
    assert see(3) == cards((1, 3), (1, 4), (1, 5))  # right
    assert see(4) == cards((0, 2))  # up
    assert see(5) == cards((2, 2))  # down
    assert see(6) == cards((0, 0), (0, 1))  # up-left
    assert see(7) == cards((0, 3), (0, 4), (0, 5))  # up-right
    assert see(8) == cards((2, 0), (2, 1))  # down-left
    assert see(9) == cards((2, 3), (2, 4), (2, 5))  # down-right


def test_table_b4_gaze_and_its_border_note():
    assert see(0, 1) == cards((0, 4), (1, 4), (0, 3), (0, 5))  # top row: no card above
    corner = int(I.VIS_SET[OBS, card_of(2, 0), VISUAL_PARTS.index((0, 1))])
    assert corner == cards((2, 0), (1, 0), (2, 1))
    middle = int(I.VIS_SET[OBS, card_of(1, 3), VISUAL_PARTS.index((0, 1))])
    assert middle == cards((1, 3), (0, 3), (2, 3), (1, 2), (1, 4))


def test_candidate_set_is_the_nis_intersected_with_the_perceived_parts():
    nis = ALL_CARDS & ~(1 << card_of(0, 3))
    h, v = HEARING_PARTS.index((6, 0)), VISUAL_PARTS.index((7, 0))  # "Maybe right" + up-right
    assert I.candidate_set(nis, OBS, MATCH, h, v, False, False) == nis
    assert I.candidate_set(nis, OBS, MATCH, h, v, True, False) == cards((1, 3), (1, 4), (1, 5))
    assert I.candidate_set(nis, OBS, MATCH, h, v, False, True) == cards((0, 4), (0, 5))
    assert I.candidate_set(nis, OBS, MATCH, h, v, True, True) == 0  # inconsistent


@pytest.mark.parametrize("sight, seen", [
    (6, {"head", "smile", "gaze"}), (5, {"head", "smile", "gaze"}),
    (4, {"head", "smile"}), (3, {"head", "smile"}), (2, {"head"}), (1, set()),
])
def test_table_6_1_sight(sight, seen):
    flags = I.sees(sight)
    assert {ch for ch, f in zip(I.CHANNELS, flags) if f} == seen


def test_skill_translation():
    assert [I.consider_probability(f) for f in range(1, 7)] == pytest.approx([0, .2, .4, .6, .8, 1])
    assert [I.hear_probability(h) for h in range(1, 7)] == pytest.approx([0, .2, .4, .6, .8, 1])
    assert [I.memory_capacity(m) for m in range(1, 7)] == [2, 3, 4, 5, 6, 7]
    with pytest.raises(ValueError):
        I.sees(0)


def test_every_action_decodes_to_its_parts_meanings():
    for code in range(88):
        h, v = divmod(code, 11)
        meaning_h, channel_h = I.hearing_meaning(h)
        meaning_v, channel_v = I.visual_meaning(v)
        assert (meaning_h is None) == (channel_h is None) and (meaning_v is None) == (channel_v is None)
    assert I.visual_meaning(VISUAL_PARTS.index((0, 1))) == ("cross", "gaze")
    assert code_of_parts(2, 0, 0, 1) == 34
