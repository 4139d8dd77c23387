"""Does a recording contradict itself about who published what? The check before a rebuild or a verify.

Rule: the game (the one source that starts and ends a session: schemas/trust.py) numbers its events
1, 2, 3, ... per session (schemas/envelope.py), starts a session once and ends it once, and publishes
nothing after its SessionEnded but its shell's events (ServiceStarted, MessageRejected). (Other
source names may be several publishers': every page of the lab publishes as "board".) Zenoh names no publisher per message (docs/bus.md "Security"),
so another process on the bus can publish an event claiming any source, and a recording made
before the live checks of services/guard.py noticed it (or by an older pairplay) may hold it. A
file where two different events claim the same (session, game, seq), where the game started or
ended the same session twice, or where it published after its SessionEnded, holds at least
one event that was not the game's (two different events of one seq of another source that one
process publishes as, the learner's, the participant's, the robot's, likewise: `ONE_PUBLISHER`):
folding it would take whichever came first (a forged end before any round rebuilt as a session
of 0 rounds, exit 0). `contradiction` names the first
such pair, with both positions (the events' indices in the order given, from 0), so the verb can
refuse the file in one line instead. Identical copies of one event (a copy, a refill) are not a
contradiction. Pure: events in, words out.
"""

from __future__ import annotations

from typing import Iterable

from pairplay.schemas.envelope import Event
from pairplay.schemas.trust import ONCE_PER_SESSION, STARTERS

# the sources one process publishes as, numbering its events 1, 2, 3, ...: two different events of one of them at one
# seq are a contradiction too (a file holding two learner QUpdated of one seq rebuilt, exit 0, a policy the learner
# never had: a new user's trial, trial29 F2); "board" is every lab page's, "recorder" a restarted one's too
ONE_PUBLISHER = frozenset({"game", "learner", "participant", "robot"})
# what a source may publish after its end (its shell), or that is judged on its own (a second start or end)
AFTER_END = frozenset({"ServiceStarted", "MessageRejected"}) | ONCE_PER_SESSION


def _named(e: Event, pos: int) -> str:
    return f"{type(e).__name__} seq {e.seq} (event {pos})"


def contradiction(events: Iterable[Event], one_publisher: frozenset[str] = ONE_PUBLISHER) -> str:
    """The first contradiction among a session's `events` (see rule), in words; "" if none. `one_publisher`: the
    sources whose seqs are checked (STARTERS alone for a file its reader found no two events of one seq in:
    reader.EventLog.differing; the other sources' check was a tenth of a rebuild)."""
    return Contradictions(one_publisher).take(events)


class Contradictions:
    """`contradiction` of events given a batch at a time (a rebuild folds a file's events as they are read): `take`
    each batch in order; `found` is the first contradiction in words ("" so far)."""

    def __init__(self, one_publisher: frozenset[str] = ONE_PUBLISHER) -> None:
        self.judged = one_publisher | STARTERS  # the sources whose events are looked at
        self.found = ""
        self.pos = 0  # the events taken before this batch (a contradiction names both events' positions)
        self.seen: dict[tuple[str, str, int], tuple[int, Event]] = {}
        self.once: dict[tuple[str, str, str], tuple[int, Event]] = {}
        self.ends: dict[tuple[str, str], tuple[int, Event]] = {}

    def take(self, events: Iterable[Event]) -> str:
        """`found` after `events`, the next ones in order (none is looked at once one is found)."""
        if self.found:
            return self.found
        judged, pos = self.judged, self.pos
        for e in events:
            if e.source in judged:
                self.found = self._judge(e, pos)
                if self.found:
                    break
            pos += 1
        self.pos = pos
        return self.found

    def _judge(self, e: Event, pos: int) -> str:
        """The contradiction event `e`, at `pos`, makes with those before it ("" if none)."""
        seen, once, ends = self.seen, self.once, self.ends
        tag = type(e).__name__
        at = (e.session, e.source, e.seq)
        first = seen.get(at)
        if first is not None and first[1] != e:
            return (f"two events claim source {e.source!r} seq {e.seq}: {_named(first[1], first[0])} and "
                    f"{_named(e, pos)}; one of them is not {e.source}'s (forged on the bus?)")
        seen.setdefault(at, (pos, e))
        if e.source not in STARTERS:
            return ""
        if tag in ONCE_PER_SESSION:
            earlier = once.get((e.session, e.source, tag))
            if earlier is not None and earlier[1] != e:
                return (f"two {tag} claim source {e.source!r}: {_named(earlier[1], earlier[0])} and {_named(e, pos)}; "
                        f"one of them is not {e.source}'s (forged on the bus?)")
            once.setdefault((e.session, e.source, tag), (pos, e))
            if tag == "SessionEnded":
                ends.setdefault((e.session, e.source), (pos, e))
            return ""
        end = ends.get((e.session, e.source))
        if end is not None and e.seq > end[1].seq and tag not in AFTER_END:
            return (f"{e.source}'s {_named(end[1], end[0])} is followed by its {_named(e, pos)}: that end was not "
                    f"{e.source}'s (forged on the bus?)")
        return ""
