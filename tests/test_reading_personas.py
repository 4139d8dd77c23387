"""Personas who read suggestion pairs as one whole (future work 1): core/interpretation.py READINGS.

The thesis's personas are untouched (tests/test_study_digests.py pins them bit for
bit); these check the readers' candidate sets against appendix B by hand, through
the same kernel a live participant service uses (core/user.py SimulatedUsers).
"""

import numpy as np
import pytest

from pairplay.core.actions import code_of_parts
from pairplay.core.geometry import ALL_CARDS, card_of
from pairplay.core.interpretation import COMPOUND, reading_code
from pairplay.core.oracle import oracle_policies
from pairplay.core.personas import PERSONAS, READING_PERSONAS, ReadingPersona, parse_personas
from pairplay.core.simulate import run_games
from pairplay.core.user import DRAWS_PER_TURN, SimulatedUsers, reading_codes

from test_user import Script, a, mask

COVERED = ALL_CARDS & ~(1 << 17)
OBSERVED, MATCH_UP_LEFT = card_of(2, 3), card_of(0, 1)  # the match is up and to the left of the observed card
TOP = mask(card_of(0, 3), card_of(1, 3))
LEFT = mask(*(card_of(2, c) for c in range(3)))
TOP_LEFT = mask(*(card_of(r, c) for r in range(2) for c in range(3)))
UP, LEFT_SPEECH = 3, 5  # speech codes
HEAD_LEFT, HEAD_UP, HEAD_UP_LEFT = 2, 4, 6  # head codes


def reader(*reads):
    p = ReadingPersona(key="r", name="R", focus=6, memory=3, hearing=6, sight=6, reads=reads)
    u = SimulatedUsers([p], Script((0, 0, 0.0, 0.0, 0.0)))
    u._u = u.stream.take(DRAWS_PER_TURN)
    return u


def candidates(u, speech, head, gaze=0):
    r = u.respond(a(code_of_parts(speech, 0, head, gaze)), a(OBSERVED), a(MATCH_UP_LEFT), a(OBSERVED), a(False),
                  a(COVERED))
    assert r.considered[0]
    return int(r.candidates[0])


@pytest.mark.parametrize("reads, speech, head, expected", [
    ((), UP, 0, TOP), ((), 0, HEAD_LEFT, LEFT), ((), UP, HEAD_LEFT, 0),  # the thesis's user: parts intersect
    (("together",), UP, 0, COVERED), (("together",), 0, HEAD_LEFT, COVERED),  # alone: not perceived (the NIS)
    (("together",), UP, HEAD_UP, TOP), (("together",), UP, HEAD_LEFT, 0),  # together: as the thesis's user
    (("compound",), UP, HEAD_LEFT, TOP_LEFT), (("compound",), LEFT_SPEECH, HEAD_UP, TOP_LEFT),  # one direction
    (("compound",), UP, 0, TOP), (("compound",), UP, HEAD_UP_LEFT, 0),  # other pairs: as the thesis's user
    (("together", "compound"), UP, HEAD_LEFT, TOP_LEFT), (("together", "compound"), UP, 0, COVERED),
])
def test_a_reader_perceives_pairs_as_its_readings_say(reads, speech, head, expected):
    assert candidates(reader(*reads), speech, head) == expected & COVERED


def test_together_leaves_smile_and_gaze_as_they_were():
    plain, duo = reader(), reader("together")
    assert candidates(duo, 0, 0, gaze=1) == candidates(plain, 0, 0, gaze=1) != COVERED
    assert candidates(duo, UP, 0, gaze=1) == candidates(plain, 0, 0, gaze=1)  # the words without the head: lost


def test_compound_table_pairs_each_straight_word_with_each_perpendicular_turn():
    assert (COMPOUND >= 0).sum() == 8  # {up, down} x {left, right} and {left, right} x {up, down}


def test_the_thesis_personas_read_nothing_as_a_whole_and_unknown_readings_are_refused():
    assert not reading_codes(list(PERSONAS.values())).any()
    assert list(reading_codes([READING_PERSONAS[k] for k in ("plain", "duo", "compass")])) == [0, 1, 2]
    with pytest.raises(ValueError, match="unknown reading 'sideways'"):
        reading_code(["sideways"])
    with pytest.raises(ValueError, match="unknown reading"):
        ReadingPersona(key="x", name="X", focus=6, memory=3, hearing=6, sight=6, reads=("sideways",))
    assert set(READING_PERSONAS).isdisjoint(PERSONAS)  # never in the default study's list


def test_a_reading_persona_file_parses_like_the_default_one():
    text = (b'{"scale": "s", "note": "n", "personas": [{"key": "k", "name": "K", "focus": 6, "memory": 3, '
            b'"hearing": 6, "sight": 6, "reads": ["compound"]}]}')
    from pairplay.core.personas import _ReadingPersonaFile
    assert parse_personas(text, _ReadingPersonaFile)["k"].reads == ("compound",)


def test_in_a_game_a_together_reader_learns_nothing_from_words_alone():
    """Over whole games: "Maybe ..." alone helps the plain user (fewer picks than playing alone) and
    not Duo, who plays it as if unaided; a batch mixing both gives each the picks it gets alone."""
    plain, duo = READING_PERSONAS["plain"], READING_PERSONAS["duo"]
    exact_alone = np.full(24, code_of_parts(2, 0, 0, 0))
    nothing = np.zeros(24, dtype=np.int64)
    res = run_games([plain, duo, plain, duo], [1, 1, 1, 1], 20, mode="fixed",
                    policy=np.stack([exact_alone, exact_alone, nothing, nothing]))
    picks = res.picks.mean(1)
    assert picks[0] < picks[2] - 2  # the words find the card for the plain user
    assert picks[1] == picks[3]  # and are not perceived at all by Duo: the very same game as unaided
    alone = run_games([duo], [1], 20, mode="fixed", policy=exact_alone[None]).picks
    assert (alone[0] == res.picks[1]).all()


def test_the_oracle_refuses_a_reading_persona():
    with pytest.raises(ValueError, match="whole readings"):
        oracle_policies([READING_PERSONAS["duo"]], 1, 0, rounds=1)
