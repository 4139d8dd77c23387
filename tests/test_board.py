"""The board's rules: picks, matches, misses, rounds, and every illegal pick refused."""

import numpy as np
import pytest

from pairplay.core.board import Board, IllegalPick, Outcome, deal
from pairplay.core.geometry import ALL_CARDS

FACES = [0, 1, 2, 3, 4, 5, 6, 7, 8, 0, 1, 2, 3, 4, 5, 6, 7, 8]  # card c and c + 9 are a pair


def test_a_match_stays_up_and_a_miss_turns_back():
    board = Board.from_faces(FACES)
    board, outcome = board.pick(0)
    assert outcome is Outcome.FIRST and board.covered == ALL_CARDS & ~1
    board, outcome = board.pick(9)
    assert outcome is Outcome.SECOND
    board, res = board.resolve()
    assert res.matched and board.matched == (1 | 1 << 9) and board.up == ()
    board, _ = board.pick(1)
    board, _ = board.pick(2)
    board, res = board.resolve()
    assert not res.matched and board.matched == (1 | 1 << 9)
    assert board.covered == ALL_CARDS & ~(1 | 1 << 9)


def test_the_round_is_over_when_every_pair_is_matched():
    board = Board.from_faces(FACES)
    for c in range(9):
        board, _ = board.pick(c)
        board, _ = board.pick(c + 9)
        board, res = board.resolve()
    assert res.round_over and board.round_over
    with pytest.raises(IllegalPick, match="round is over"):
        board.pick(0)


@pytest.mark.parametrize("card, reason", [(-1, "off the board"), (18, "off the board"),
                                          ("3", "off the board"), (2.0, "off the board")])
def test_cards_off_the_board_are_refused(card, reason):
    board = Board.from_faces(FACES)
    with pytest.raises(IllegalPick, match=reason):
        board.pick(card)


def test_face_up_matched_and_third_cards_are_refused_and_change_nothing():
    board = Board.from_faces(FACES)
    board, _ = board.pick(0)
    board, _ = board.pick(9)
    board, _ = board.resolve()
    board, _ = board.pick(4)
    before = board
    with pytest.raises(IllegalPick, match="already face up"):
        board.pick(4)
    with pytest.raises(IllegalPick, match="already matched"):
        board.pick(9)
    assert board == before
    board, _ = board.pick(5)
    with pytest.raises(IllegalPick, match="third card"):
        board.pick(6)
    with pytest.raises(IllegalPick, match="after two picks"):
        Board.from_faces(FACES).resolve()


def test_a_deal_must_hold_nine_pairs():
    with pytest.raises(ValueError, match="exactly twice"):
        Board.from_faces([0] * 18)
    with pytest.raises(ValueError, match="exactly twice"):
        Board.from_faces(FACES[:-1])


def test_deal_is_a_uniform_permutation_of_nine_pairs_with_partners():
    u = np.random.default_rng(1).random((500, 18))
    faces, partner = deal(u)
    assert all(sorted(f) == sorted(FACES) for f in faces)
    rows = np.arange(500)[:, None]
    assert (faces[rows, partner] == faces).all() and (partner != np.arange(18)).all()
    # Each card position gets each face about equally often.
    counts = np.stack([(faces == k).sum(0) for k in range(9)])
    assert counts.min() > 500 * 2 / 18 * 0.5
    single, _ = deal(u[0])
    assert (single[0] == faces[0]).all()


def test_partner_on_the_board_is_the_other_card_of_the_face():
    board = Board.from_faces(FACES)
    assert board.partner(3) == 12 and board.partner(12) == 3
