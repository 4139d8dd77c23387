"""Board calibration: where each card is in the robot's frame, and the board's axes.

Rule: a calibration file lists the 18 card centres in metres in the robot's frame
(x to the robot's left, y up, z forward) in card order (row * 6 + col, rows and
columns as the participant sees them) and a rest point (the participant's face).
The board's "down" and "right" directions are measured from the card centres
themselves (mean step between neighbouring rows and columns), so a head turn
"left" always points towards column 0 whatever way the board faces the robot.
A file that cannot be used is refused with the reason; nothing is guessed.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import msgspec

from pairplay.core.geometry import COLS, N_CARDS, ROWS, card_of
from pairplay.inputs import refusal
from pairplay.schemas.jsonfile import a_folder, empty, in_words, without_bom
from pairplay.schemas.robot import BoardCalibration, Point
from pairplay.schemas.nesting import json_decode

DEFAULT_FILE = "calibration_default.json"
MAX_DISTANCE_M = 10.0  # a card farther than this from the robot is a unit mistake
MIN_STEP_M = 0.005  # neighbouring cards closer than this: the axes are undefined


class CalibrationError(ValueError):
    """A calibration file or struct that cannot be used, with the reason."""


def load_calibration(path: str | Path | None = None) -> BoardCalibration:
    """Read and check a calibration file; None reads the packaged default."""
    if path is None:
        raw = resources.files("pairplay.services.robot").joinpath(DEFAULT_FILE).read_bytes()
        where = f"packaged {DEFAULT_FILE}"
    else:
        if said := refusal(path):  # before opening: a pipe blocked (pairplay/inputs.py)
            raise CalibrationError(f"calibration {path}: {said}")
        try:
            raw = Path(path).read_bytes()
        except IsADirectoryError:
            raise CalibrationError(a_folder(path, "calibration file", "its JSON file")) from None
        except OSError as exc:
            raise CalibrationError(f"cannot read calibration {path}: {exc}") from exc
        where = str(path)
        if empty(raw):
            raise CalibrationError(f"calibration {where}: {empty(raw)}")
    try:
        calibration = json_decode(without_bom(raw), type=BoardCalibration)
    except msgspec.DecodeError as exc:  # ValidationError is a subclass
        raise CalibrationError(f"calibration {where} is not valid: "
                               f"{in_words(exc, BoardCalibration, without_bom(raw))}") from exc
    check_calibration(calibration, where)
    return calibration


def _vector(p: Point) -> tuple[float, float, float]:
    return (p.x, p.y, p.z)


def _norm(v: tuple[float, float, float]) -> float:
    return math.sqrt(sum(c * c for c in v))


def check_calibration(calibration: BoardCalibration, where: str = "calibration") -> None:
    if len(calibration.cards) != N_CARDS:
        raise CalibrationError(f"{where}: needs {N_CARDS} card positions, has {len(calibration.cards)}")
    for index, point in enumerate([*calibration.cards, calibration.rest]):
        label = f"card {index}" if index < N_CARDS else "rest"
        if not all(math.isfinite(c) for c in _vector(point)):
            raise CalibrationError(f"{where}: {label} has a non-finite coordinate {_vector(point)}")
        if _norm(_vector(point)) > MAX_DISTANCE_M:
            raise CalibrationError(f"{where}: {label} is {_norm(_vector(point)):.1f} m away; positions are metres")
    axes = BoardAxes(calibration)
    if _norm(axes.down) < MIN_STEP_M or _norm(axes.right) < MIN_STEP_M:
        raise CalibrationError(f"{where}: rows or columns do not spread out; cannot tell the board's directions")


class BoardAxes:
    """Unit steps of the board in the robot's frame: `down` (row +1), `right` (column +1)."""

    def __init__(self, calibration: BoardCalibration) -> None:
        cards = [_vector(p) for p in calibration.cards]
        self.down = _mean_step(cards, [(card_of(r, c), card_of(r + 1, c)) for r in range(ROWS - 1) for c in range(COLS)])
        self.right = _mean_step(cards, [(card_of(r, c), card_of(r, c + 1)) for r in range(ROWS) for c in range(COLS - 1)])


def _mean_step(cards, pairs) -> tuple[float, float, float]:
    n = len(pairs)
    return tuple(sum(cards[b][k] - cards[a][k] for a, b in pairs) / n for k in range(3))  # type: ignore[return-value]


class Board:
    """A checked calibration with the look-ups the renderer needs."""

    def __init__(self, calibration: BoardCalibration) -> None:
        check_calibration(calibration)
        self.calibration = calibration
        axes = BoardAxes(calibration)
        self._down = _unit(axes.down)
        self._right = _unit(axes.right)

    @property
    def rest(self) -> Point:
        return self.calibration.rest

    def card(self, card: int) -> Point:
        if not 0 <= card < N_CARDS:
            raise ValueError(f"card {card} is off the board (0..{N_CARDS - 1})")
        return self.calibration.cards[card]

    def beside(self, card: int, rows: int, cols: int, distance_m: float) -> Point:
        """The point `distance_m` from a card towards (rows, cols) on the board plane.

        rows -1 is up (towards row 0), cols -1 is left (towards column 0); a
        diagonal is normalised so every head turn travels the same distance.
        """
        direction = tuple(rows * d + cols * r for d, r in zip(self._down, self._right))
        length = _norm(direction)  # type: ignore[arg-type]
        if length == 0:
            return self.card(card)
        p = self.card(card)
        scale = distance_m / length
        return Point(p.x + direction[0] * scale, p.y + direction[1] * scale, p.z + direction[2] * scale)


def _unit(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = _norm(v)
    return (v[0] / n, v[1] / n, v[2] / n)
