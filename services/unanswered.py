"""A session's one line about a suggestion that does not come (trial28 F19).

Rule: the learner answers the game's SuggestionRequested at once (milliseconds). A request
unanswered for `SAY_AFTER_S` is said once, in one line naming the request and asking whether
the learner runs: a learner in another process that hung, or a liveliness token with no learner
behind it (the token is all a session checks of an --external learner before it starts: one
forged token started a session that then waited for ever without a word). The session goes on
waiting (a learner that comes late still answers; Ctrl-C stops it). Zenoh's threads only note
numbers here; the session's watch loop asks for the line (services/session.py watch_services).
"""

from __future__ import annotations

import time

from pairplay.schemas.events import SuggestionMade, SuggestionRequested, decode_event
from pairplay.schemas.keys import event_key

SAY_AFTER_S = 30.0  # a request unanswered this long is said (the learner answers in milliseconds)


class RequestWatch:
    """The newest SuggestionRequested the game published and the newest one the learner answered."""

    def __init__(self, bus, session: str, after_s: float | None = None, clock=time.monotonic):
        self.after_s = SAY_AFTER_S if after_s is None else after_s
        self.clock = clock
        self.asked: tuple[int, float] = (0, 0.0)  # seq of the newest request, when it was seen
        self.answered = 0  # the newest request seq a SuggestionMade answered
        self.said = 0  # the request already said (once each)
        self.subscribers = [bus.subscribe(event_key(session, "game", "SuggestionRequested"), self._asked),
                            bus.subscribe(event_key(session, "learner", "SuggestionMade"), self._answered)]

    def _asked(self, _key: str, payload: bytes) -> None:
        e = _decoded(payload)
        if isinstance(e, SuggestionRequested) and e.seq > self.asked[0]:
            self.asked = (e.seq, self.clock())

    def _answered(self, _key: str, payload: bytes) -> None:
        e = _decoded(payload)
        if isinstance(e, SuggestionMade) and e.request_seq > self.answered:
            self.answered = e.request_seq

    def line(self) -> str:
        """The line to say now ("" if none): once per request unanswered for `after_s`."""
        seq, since = self.asked
        waited = self.clock() - since
        if seq <= self.answered or seq == self.said or waited < self.after_s:
            return ""
        self.said = seq
        return (f"waiting {waited:.0f} s for the learner's SuggestionMade to SuggestionRequested seq {seq}; "
                "is the learner running?")


def _decoded(payload: bytes):
    """The event, or None: a malformed message is the guards' to refuse and record, not this watch's."""
    try:
        return decode_event(payload)
    except Exception:
        return None
