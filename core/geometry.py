"""Board geometry and the state space of thesis section 4.1 (SPEC "States").

Rule: the state of a suggestion is the spatial cell of the matching card relative
to the observed card (sign of the row difference x sign of the column difference:
9 cells, border cells extended to the board's edge) and a level, the number of
covered cards in that cell (0: one card, 1: two or three, 2: more than three),
plus one state for "the number of cards turned this turn is not 1".

The reachable (cell, level) pairs are enumerated from the geometry, not typed in.
On the 3 x 6 board that gives 23 spatial states + 1 = 24, where the thesis's
equation 4.1 says 9*3 + 1 - 5 = 23. The thesis names only four impossible pairs
(TOP and BOTTOM level 2: at most two cards above or below; MATCH levels 1 and 2:
the cell is the observed card alone), i.e. it subtracts one pair too many. Our
order (cells row by row as in figure 4.4, levels ascending) puts RIGHT level 0 at
index 12, the index the thesis gives that state (section 6.4), which it could not
be if any pair before it were missing: this is the evidence that the thesis's
implementation had these 24 states and only its count is off by one.
"""

from __future__ import annotations

import numpy as np

ROWS, COLS = 3, 6
N_CARDS = ROWS * COLS
N_PAIRS = N_CARDS // 2
ALL_CARDS = (1 << N_CARDS) - 1  # bit mask of the whole board
# The one unit of performance everywhere (study, session, rebuild): cards picked to
# clear the board, 2 per turn; perfect play finds each pair with its first 2 picks.
PERFECT_PICKS = N_CARDS
PICKS_UNIT = f"picks per round ({PERFECT_PICKS} = perfect)"

# The nine cells of figure 4.4, read row by row. (row sign, column sign) of the
# matching card relative to the observed card: -1 up/left, 0 same, +1 down/right.
CELLS: tuple[tuple[str, int, int], ...] = (
    ("TOP_LEFT", -1, -1), ("TOP", -1, 0), ("TOP_RIGHT", -1, 1),
    ("LEFT", 0, -1), ("MATCH", 0, 0), ("RIGHT", 0, 1),
    ("BOTTOM_LEFT", 1, -1), ("BOTTOM", 1, 0), ("BOTTOM_RIGHT", 1, 1),
)
CELL_NAMES = tuple(name for name, _, _ in CELLS)
CELL_INDEX = {name: i for i, name in enumerate(CELL_NAMES)}
N_LEVELS = 3
NOT_ONE_CARD = "NOT_ONE_CARD"  # the extra state: cards turned this turn != 1


def card_row(card: int) -> int:
    return card // COLS


def card_col(card: int) -> int:
    return card % COLS


def card_of(row: int, col: int) -> int:
    return row * COLS + col


def level_of_count(n_covered: int) -> int:
    """Level of a cell holding `n_covered` covered cards (n >= 1)."""
    return 0 if n_covered <= 1 else (1 if n_covered <= 3 else 2)


def _sign(x: int) -> int:
    return (x > 0) - (x < 0)


def cell_of(observed: int, target: int) -> int:
    """Index into CELLS of `target` seen from `observed`."""
    dr = _sign(card_row(target) - card_row(observed))
    dc = _sign(card_col(target) - card_col(observed))
    return (dr + 1) * 3 + (dc + 1)


def _cell_masks() -> np.ndarray:
    """CELL_MASK[observed, cell]: bit mask of the board cards in that cell."""
    masks = np.zeros((N_CARDS, len(CELLS)), dtype=np.uint32)
    for obs in range(N_CARDS):
        for card in range(N_CARDS):
            masks[obs, cell_of(obs, card)] |= np.uint32(1 << card)
    return masks


CELL_MASK = _cell_masks()
# CELL_OF[observed, target] as a table for the batched simulator.
CELL_OF = np.array([[cell_of(o, t) for t in range(N_CARDS)] for o in range(N_CARDS)], dtype=np.int8)


def _reachable_states() -> list[tuple[int, int]]:
    """Every (cell, level) that some observed card on an empty-enough board can give.

    The largest count a cell can hold is its size on a fully covered board; every
    count from 1 up to that is reachable (cover or uncover cards in the cell), so
    the reachable levels of a cell are those of 1..max size over observed cards.
    """
    biggest = [0] * len(CELLS)
    for obs in range(N_CARDS):
        for cell in range(len(CELLS)):
            biggest[cell] = max(biggest[cell], int(CELL_MASK[obs, cell]).bit_count())
    pairs = []
    for cell in range(len(CELLS)):
        levels = sorted({level_of_count(n) for n in range(1, biggest[cell] + 1)})
        pairs.extend((cell, level) for level in levels)
    return pairs


SPATIAL_STATES: tuple[tuple[int, int], ...] = tuple(_reachable_states())
N_STATES = len(SPATIAL_STATES) + 1
NOT_ONE_CARD_STATE = N_STATES - 1

# STATE_INDEX[cell, level] -> state index, -1 where unreachable.
STATE_INDEX = np.full((len(CELLS), N_LEVELS), -1, dtype=np.int16)
for _i, (_cell, _level) in enumerate(SPATIAL_STATES):
    STATE_INDEX[_cell, _level] = _i

STATE_NAMES: tuple[str, ...] = tuple(
    f"{CELL_NAMES[c]}_L{lv}" for c, lv in SPATIAL_STATES
) + (NOT_ONE_CARD,)

# LEVEL_OF_COUNT[n] for n covered cards in a cell (n = 0 never happens: the
# matching card itself is covered and in its own cell).
LEVEL_OF_COUNT = np.array([0] + [level_of_count(n) for n in range(1, N_CARDS + 1)], dtype=np.int8)


# The same tables as Python ints for `state_of`, a live session's one state per request: on a pick after an
# idle turn, each numpy scalar index and helper call of the formula cost microseconds cold (issue 16).
_CELL_MASK_OF: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(CELL_MASK[o, cell_of(o, t)]) for t in range(N_CARDS)) for o in range(N_CARDS))
_STATE_OF_COUNT: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(STATE_INDEX[cell_of(o, t), level_of_count(n)]) if n else -1 for n in range(N_CARDS + 1))
    for o in range(N_CARDS) for t in range(N_CARDS))


def state_of(observed: int, match: int, covered_mask: int) -> int:
    """State index of a suggestion (thesis 4.1).

    `covered_mask` is the bit mask of face-down cards at the moment of the
    suggestion (the first card of the turn is face up, so it is not in it).
    The formula (cell_of, the cell's covered count, level_of_count, STATE_INDEX),
    read from tables of Python ints built from it (tests/test_states.py checks
    every observed, match and cell count against the formula).
    """
    n = (_CELL_MASK_OF[observed][match] & covered_mask).bit_count()
    if n < 1:
        raise ValueError("the matching card must be covered when a suggestion is asked")
    return _STATE_OF_COUNT[observed * N_CARDS + match][n]


def neighbours_mask(card: int) -> int:
    """The card plus its up, down, left and right neighbours that exist."""
    r, c = card_row(card), card_col(card)
    mask = 1 << card
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        rr, cc = r + dr, c + dc
        if 0 <= rr < ROWS and 0 <= cc < COLS:
            mask |= 1 << card_of(rr, cc)
    return mask


def bits_of(mask: int) -> list[int]:
    """Card indices in a bit mask, ascending."""
    return [i for i in range(N_CARDS) if mask >> i & 1]


def states_of(observed: np.ndarray, match: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """`state_of` for a batch of games (arrays of equal shape)."""
    cell = CELL_OF[observed, match]
    n = np.bitwise_count(CELL_MASK[observed, cell].astype(np.int64) & covered)
    return STATE_INDEX[cell, LEVEL_OF_COUNT[n]].astype(np.int64)
