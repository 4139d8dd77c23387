"""State encoding (thesis 4.1) on hand-made boards: every cell, every level, borders."""

import numpy as np
import pytest

from pairplay.core import geometry as G

ALL = G.ALL_CARDS


def card(row, col):
    return G.card_of(row, col)


def only(*cards):
    m = 0
    for c in cards:
        m |= 1 << c
    return m


def test_the_enumeration_gives_23_spatial_states_plus_one():
    assert G.N_STATES == 24
    assert G.STATE_NAMES[-1] == "NOT_ONE_CARD"
    missing = {(c, lv) for c in range(9) for lv in range(3)} - set(G.SPATIAL_STATES)
    names = {(G.CELL_NAMES[c], lv) for c, lv in missing}
    assert names == {("TOP", 2), ("BOTTOM", 2), ("MATCH", 1), ("MATCH", 2)}
    # The thesis calls state 12 "Right Level 0" (section 6.4).
    assert G.STATE_NAMES[12] == "RIGHT_L0"


@pytest.mark.parametrize("target, cell", [
    ((0, 1), "TOP_LEFT"), ((0, 3), "TOP"), ((0, 5), "TOP_RIGHT"),
    ((1, 0), "LEFT"), ((1, 3), "MATCH"), ((1, 4), "RIGHT"),
    ((2, 2), "BOTTOM_LEFT"), ((2, 3), "BOTTOM"), ((2, 4), "BOTTOM_RIGHT"),
])
def test_every_cell_around_a_middle_card(target, cell):
    observed = card(1, 3)
    assert G.CELL_NAMES[G.cell_of(observed, card(*target))] == cell


def test_border_cells_extend_to_the_edge_of_the_board():
    observed = card(2, 5)  # bottom-right corner
    top_left = G.CELL_MASK[observed, G.CELL_INDEX["TOP_LEFT"]]
    assert int(top_left).bit_count() == 10  # rows 0-1, columns 0-4
    assert int(G.CELL_MASK[observed, G.CELL_INDEX["TOP"]]) == only(card(0, 5), card(1, 5))
    assert int(G.CELL_MASK[observed, G.CELL_INDEX["LEFT"]]) == only(*[card(2, c) for c in range(5)])
    for empty in ("RIGHT", "BOTTOM", "BOTTOM_RIGHT", "TOP_RIGHT", "BOTTOM_LEFT"):
        assert int(G.CELL_MASK[observed, G.CELL_INDEX[empty]]) == 0
    # Every card of the board is in exactly one cell of any observed card.
    for obs in range(18):
        masks = [int(m) for m in G.CELL_MASK[obs]]
        assert sum(masks) == ALL and all(a & b == 0 for i, a in enumerate(masks) for b in masks[i + 1:])


def test_levels_count_covered_cards_in_the_cell():
    observed, match = card(2, 5), card(0, 0)  # TOP_LEFT of the bottom-right corner
    cell = [card(r, c) for r in range(2) for c in range(5)]
    covered = ALL & ~(1 << card(1, 1))  # the first card is face up, elsewhere in the cell
    assert G.STATE_NAMES[G.state_of(observed, match, covered)] == "TOP_LEFT_L2"
    assert G.STATE_NAMES[G.state_of(observed, match, only(observed, match, cell[1], cell[2]))] == "TOP_LEFT_L1"
    assert G.STATE_NAMES[G.state_of(observed, match, only(observed, match, cell[1]))] == "TOP_LEFT_L1"
    assert G.STATE_NAMES[G.state_of(observed, match, only(observed, match))] == "TOP_LEFT_L0"
    assert G.STATE_NAMES[G.state_of(observed, match, only(observed, match, *cell[1:4]))] == "TOP_LEFT_L2"


def test_cards_outside_the_cell_do_not_count():
    observed, match = card(1, 0), card(1, 1)  # RIGHT, the cell is row 1 columns 1-5
    covered = only(observed, match, card(0, 1), card(2, 2), card(0, 5))
    assert G.STATE_NAMES[G.state_of(observed, match, covered)] == "RIGHT_L0"
    covered |= only(card(1, 4), card(1, 5))
    assert G.STATE_NAMES[G.state_of(observed, match, covered)] == "RIGHT_L1"
    covered |= only(card(1, 3))
    assert G.STATE_NAMES[G.state_of(observed, match, covered)] == "RIGHT_L2"


def test_top_and_bottom_have_two_levels_and_match_one():
    assert G.STATE_NAMES[G.state_of(card(2, 2), card(0, 2), ALL)] == "TOP_L1"
    assert G.STATE_NAMES[G.state_of(card(2, 2), card(0, 2), only(card(2, 2), card(0, 2)))] == "TOP_L0"
    assert G.STATE_NAMES[G.state_of(card(0, 4), card(1, 4), ALL)] == "BOTTOM_L1"
    assert G.STATE_NAMES[G.state_of(card(1, 4), card(2, 4), ALL)] == "BOTTOM_L0"
    assert G.STATE_NAMES[G.state_of(card(1, 1), card(1, 1), ALL)] == "MATCH_L0"


def test_the_matching_card_must_be_covered():
    with pytest.raises(ValueError, match="covered"):
        G.state_of(card(0, 0), card(0, 1), only(card(0, 0)))


def test_batched_states_agree_with_the_scalar_rule():
    rng = np.random.default_rng(3)
    obs = rng.integers(0, 18, 2000)
    match = rng.integers(0, 18, 2000)
    covered = rng.integers(0, 1 << 18, 2000) | (1 << match) | (1 << obs)
    batched = G.states_of(obs, match, covered)
    assert [G.state_of(int(o), int(m), int(c)) for o, m, c in zip(obs, match, covered)] == batched.tolist()


def test_the_scalar_rules_tables_agree_with_the_formula_for_every_observed_match_and_count():
    """state_of reads tables of Python ints (a live pick's speed); the formula of thesis 4.1 is the truth:
    for every observed card, matching card and number of covered cards in the match's cell."""
    for observed in range(G.N_CARDS):
        for match in range(G.N_CARDS):
            cell = G.cell_of(observed, match)
            in_cell = [c for c in G.bits_of(int(G.CELL_MASK[observed, cell])) if c != match]
            for extra in range(len(in_cell) + 1):
                covered = only(match, *in_cell[:extra])
                n = extra + 1
                assert G.state_of(observed, match, covered) == int(G.STATE_INDEX[cell, G.level_of_count(n)])
                # cards outside the cell never count
                assert G.state_of(observed, match, covered | (G.ALL_CARDS & ~int(G.CELL_MASK[observed, cell]))) \
                    == int(G.STATE_INDEX[cell, G.level_of_count(n)])
