"""Shared pieces of the robot tests: a fast config and a RobotActed collector."""

from __future__ import annotations

import threading

from pairplay.core.actions import code_of_parts
from pairplay.core.geometry import card_of
from pairplay.schemas.robot import RobotActed, RobotConfig
from pairplay.services.robot import Suggestion

# Short holds and backoff so a test takes milliseconds; the protocol is unchanged. The time limits that
# decide an outcome stay long (a reply or a reconnect can take seconds on a loaded VM): a test about a
# limit sets its own short one, and every other test ends by the robot's replies, never by a limit.
FAST = RobotConfig(head_turn_lead_s=0.01, head_turn_hold_s=0.01, ack_timeout_s=10.0, give_up_s=10.0,
                   reconnect_min_s=0.01, reconnect_max_s=0.1)
# How long a test waits for what must happen: a bound, never a measure (it costs nothing when things
# go right, and a loaded 2-core VM has been seen 20x slower than a quiet one).
PATIENCE_S = 30.0

OBSERVED, TARGET = card_of(1, 1), card_of(1, 4)
# One action per suggestion family (thesis tables 4.1-4.4).
FAMILIES = {
    "exact speech": code_of_parts(2, 0, 0, 0),
    "direction speech": code_of_parts(6, 0, 0, 0),
    "smile": code_of_parts(0, 1, 0, 0),
    "nod": code_of_parts(0, 0, 1, 0),
    "head turn": code_of_parts(0, 0, 3, 0),
    "gaze": code_of_parts(0, 0, 0, 1),
}


def suggestion(code: int, attempt: int = 0, turn: int = 0, seq: int = 0) -> Suggestion:
    return Suggestion("test", 0, turn, attempt, code, OBSERVED, TARGET, suggestion_seq=seq)


class Collector:
    """Collects RobotActed events and rejected robot frames from a driver's thread."""

    def __init__(self) -> None:
        self.acted: list[RobotActed] = []
        self.rejected: list[tuple[str, str]] = []
        self._changed = threading.Condition()

    def on_acted(self, event: RobotActed) -> None:
        with self._changed:
            self.acted.append(event)
            self._changed.notify_all()

    def on_rejected(self, reason: str, excerpt: str) -> None:
        with self._changed:
            self.rejected.append((reason, excerpt))
            self._changed.notify_all()

    def wait_for(self, predicate, timeout: float = PATIENCE_S) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self), timeout)

    def by_seq(self) -> dict[int, RobotActed]:
        return {a.suggestion_seq: a for a in self.acted}
