"""What a recording lacks of its write-ahead journal (replay/wal.py), decided by the live checks.

Rule: the recording's events are what the live recorder took; each journal
record (in the order it was received) that is one of them, byte for byte, is
skipped (a copy counted once per copy). Every other record is one the recorder
never got to, or one it refused: it goes through a Guard (services/guard.py)
that has first noted every event of the recording, exactly as the live recorder
would have checked it then. Taken, it is added with the journal's receipt time;
refused, the refusal is added as the recorder's MessageRejected (at the live
rate, counts beyond it: guard.Refusals), unless the recording holds that very
refusal already (same key and sequence number, one by one) or counted it (a
count of its kind, from the same source, not used up by earlier records: the
live recorder records 20 a second one by one and counts the rest, which were
refused again, a flood's refusals counted nearly twice). So a forged or
malformed message in the journal stays refused and is recorded as refused, a
repeat of a recorded event is a refusal as it would have been live, and the
recorder's own messages (delivered back to it) are skipped as live. Used by
`pairplay recover` (replay/recover.py, given as its `admit`) and by a restarted
recorder continuing a session (services/recorder.py `_continue`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Iterable

import msgspec

from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.schemas.keys import event_key
from pairplay.services.guard import OTHER_KIND, Guard, Refusals

RECORDER = "recorder"  # the recorder's source name (services/recorder.py Recorder.name)


@dataclass
class Admitted:
    """What to add to a recording: (key, payload, log_time_ns, seq) in order, and counts."""

    items: list[tuple[str, bytes, int, int]] = field(default_factory=list)
    taken: int = 0  # journal records added as events
    refused: int = 0  # journal records refused (their refusals are among `items`, or counted there)
    present: int = 0  # journal records the recording holds already


def admit(session: str, recorded: Iterable[tuple[str, bytes]], journal: Iterable[tuple[str, bytes, int]]) -> Admitted:
    """The events and refusals to add to a recording of `session` whose events are `recorded`
    ((key, payload) in file order) from its journal's records ((key, payload, taken_ns)); see rule."""
    guard = Guard(session, own=RECORDER)
    present: Counter = Counter()
    refusals_recorded: Counter = Counter()
    counts_recorded: Counter = Counter()  # (source, kind) -> refusals the live recorder only counted
    own_seq = 0
    for key, payload in recorded:
        try:
            event = decode_event(payload)
        except (msgspec.DecodeError, msgspec.ValidationError):
            continue
        if event.source == RECORDER:
            own_seq = max(own_seq, event.seq)
            if type(event).__name__ == "MessageRejected":
                counted = Refusals.counted(event)
                if counted is not None:
                    counts_recorded[counted[0]] += counted[1]
                elif event.key:
                    refusals_recorded[(event.key, event.offending_seq)] += 1
            continue
        guard.note(key, event)
        present[(key, payload)] += 1
    out = Admitted()
    refusals = Refusals()
    last_ns = 0

    def record_refusals(rejections, now_ns: int) -> None:
        nonlocal own_seq
        for r in rejections:
            own_seq += 1
            r = stamped(r, session=session, source=RECORDER, seq=own_seq, time_ns=now_ns)
            out.items.append((event_key(session, RECORDER, type(r).__name__), encode_event(r), now_ns, own_seq))

    for key, payload, taken_ns in journal:
        last_ns = max(last_ns, taken_ns)
        if present[(key, payload)] > 0:
            present[(key, payload)] -= 1
            out.present += 1
            continue
        verdict = guard.check(key, payload)
        if verdict.quiet:
            continue
        event = verdict.event
        if verdict.reason is None:
            out.items.append((key, payload, taken_ns, event.seq))
            out.taken += 1
            continue
        out.refused += 1
        seq = getattr(event, "seq", 0)
        if refusals_recorded[(key, seq)] > 0:  # refused live, and that refusal is in the file
            refusals_recorded[(key, seq)] -= 1
            continue
        kind = Refusals.kind(getattr(event, "source", ""), verdict.reason)
        kind = kind if counts_recorded[kind] > 0 else OTHER_KIND
        if counts_recorded[kind] > 0:  # refused live beyond the rate: counted in the file already
            counts_recorded[kind] -= 1
            continue
        record_refusals(refusals.refuse(taken_ns, verdict.reason, key, getattr(event, "source", ""), seq, payload),
                        taken_ns)
    if refusals.pending():
        record_refusals(refusals.tick(last_ns, force=True), last_ns)
    return out
