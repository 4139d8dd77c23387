"""Whether the session's recorder holds what a service published: asked before the service leaves the bus.

Rule: a service whose recorder is another process (`pairplay run <service>`, `pairplay robot`, the services
of `pairplay session --external recorder`) does not leave the bus once its session has ended until the
recorder holds every event it published (`until_recorded`), answering the recorder's refill (`sent?after=`)
meanwhile, for at most RECORDED_WAIT_S. It asks `.../_query/recorder/held?upto=<source>:<seq>,...`; the
recorder answers, after everything it took before the question, with the last seq of each source up to
which it holds every event, and the holes it has (`Held`). A source asked for twice while the recorder
still lacks its events makes the recorder refill at once (services/recorder.py). Not held in time: the
service says so, one warning, and keeps it for its owner (`lacking`); the session's process says every
hole of the recording the same way (`recording_lacks`, services/session.py) and exits 1.

Why: events lost on the bus with a link's close come back only by the refill, from the publishers' own
records (services/bus.py `Outbox.sent`), which die with the process. In the four-host test the recorder
host's link came back 5 s after a cut, the game (held meanwhile) played its last rounds in 0.9 s, and the
refill 1 s after the link's return found the game, the learner and the participant gone: their 2-4
events each lost with the link were a hole in the file, and the session exited 0 saying nothing.
A recorder not on the bus when a service asks (its token) left after the game's end (before, the game's hold
covers a recorder gone) and before that service had its answer: the service says so (`_left`), and the session's
process with it. One gone when the session asks last (`recording_lacks`) may have left rightly, once every service
had its answer: not said.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

import msgspec

from pairplay.numbers import counted
from pairplay.schemas.keys import alive_key, query_key
from pairplay.schemas.nesting import msgpack_decode
from pairplay.services.answers import one_answer
from pairplay.services.bus import Bus

log = logging.getLogger("pairplay.recorded")
HELD_QUERY = "held"
RECORDED_WAIT_S = 10.0  # a service stays this long at most for the recorder to hold its events (the refill's asks)
ASK_S = 0.5  # one question's timeout; a recorder behind its inbox answers later: asked again while on the bus
SERVE_S = 0.2  # between two questions, the refill's queries are answered this long
# what a service published last is put on the bus before the recorder is asked of it (`Outbox.flush`); a session
# that ended by itself, never a shutdown's path (a stopped service asks nothing)
FLUSH_S = 1.0


class Held(msgspec.Struct, frozen=True):
    """The recorder's answer: per source, the seq up to which it holds every event, and the highest it
    holds; the holes it has, per source, each (first, last) of the seqs missing between two it holds."""
    contiguous: dict[str, int]
    top: dict[str, int]
    holes: dict[str, list[tuple[int, int]]]


def upto_parameters(upto: dict[str, int]) -> str:
    return "upto=" + ",".join(f"{source}:{seq}" for source, seq in sorted(upto.items()))


def asked_upto(parameters: str) -> dict[str, int]:
    """`upto=<source>:<seq>,...` read back (the recorder's side); what is not a source and a number is left out
    (a query's parameters come from anyone on the bus: at most 16 digits reach int())."""
    out = {}
    for part in parameters.replace("upto=", "").split(","):
        source, _, seq = part.partition(":")
        if source and seq.isascii() and seq.isdigit() and len(seq) <= 16:
            out[source] = int(seq)
    return out


def ask_held(bus: Bus, session: str, upto: dict[str, int], stop: threading.Event | None,
             timeout_s: float = ASK_S, meanwhile: Callable[[], None] | None = None) -> Held | None:
    """The recorder's `Held`, or None if no recorder answered within `timeout_s`; `meanwhile()` is called
    while the answer has not come (Bus.query)."""
    selector = f"{query_key(session, 'recorder', HELD_QUERY)}?{upto_parameters(upto)}"
    # one recorder's answer: two sessions' that differ are none (one of them is not the recorder: services/answers.py)
    for payload in one_answer(bus.query_replies(selector, timeout_s, stop=stop, meanwhile=meanwhile),
                              f"what the recorder of session {session} holds"):
        try:
            return msgpack_decode(payload, type=Held)
        except msgspec.DecodeError as err:
            log.warning("unreadable answer from the recorder to what it holds: %s", err)
    return None


def said_holes(held: Held, upto: dict[str, int] | None = None) -> list[str]:
    """The recording's holes in words ("game seqs 4-6 (3 events)"), and what it lacks of `upto` past the
    highest event it holds of each ("learner after seq 1300 (its last: 1305)")."""
    out = []
    for source in sorted(held.holes):
        for first, last in held.holes[source]:
            n = last - first + 1
            out.append(f"{source} {f'seq {first}' if n == 1 else f'seqs {first}-{last}'} ({counted(n, 'event')})")
    for source, last in sorted((upto or {}).items()):
        top = held.top.get(source, 0)
        if top < last:
            out.append(f"{source} after seq {top} (its last: {last})")
    return out


def _recorder_on_bus(bus: Bus, session: str, stop: threading.Event | None) -> bool:
    """Whether the recorder's token is on the bus. Gone is believed when two asks say so, the second ASK_S later
    and given twice as long: one liveliness ask that timed out on a loaded TLS bus made a service say the recorder
    had left, and its session exit 1, of a whole recording (trial36 O2, 1 run in 8)."""
    key = alive_key(session, "recorder")
    if key in bus.alive_now(key, timeout_s=ASK_S, stop=stop):
        return True
    if stop is None:
        time.sleep(ASK_S)
    elif stop.wait(ASK_S):
        return True  # stopped: nothing more to say of it
    return key in bus.alive_now(key, timeout_s=2 * ASK_S, stop=stop)


def _held(bus: Bus, session: str, upto: dict[str, int], stop: threading.Event, serve: Callable[[float], None],
          done: Callable[[Held], bool], wait_s: float) -> tuple[Held | None, bool]:
    """Ask the recorder until `done(its answer)`, for at most `wait_s` while it is on the bus, `serve(seconds)`
    answering the refill meanwhile: (its last answer, whether a recorder was there to ask)."""
    deadline = time.monotonic() + wait_s
    held = None
    while not stop.is_set():
        answer = ask_held(bus, session, upto, stop, meanwhile=lambda: serve(0.01))
        held = answer or held
        if answer is None and not _recorder_on_bus(bus, session, stop):
            return held, False  # nobody records (a recorder that left holds the game: services/recorderwatch.py)
        if (answer is not None and done(answer)) or time.monotonic() >= deadline:
            break
        serve(SERVE_S)
    return held, True


def until_recorded(bus: Bus, session: str, upto: dict[str, int], serve: Callable[[float], None],
                   stop: threading.Event, wait_s: float | None = None) -> str:
    """Wait until the recorder holds every event of `upto` (source -> its last seq), `serve(seconds)`
    answering the refill's queries meanwhile (see rule). Returns "" once it does, or once `stop` is set; else, after `wait_s` (RECORDED_WAIT_S), what it still lacks, in words, or that the recorder
    left the bus without saying (`_left`)."""
    wait_s = RECORDED_WAIT_S if wait_s is None else wait_s
    upto = {source: seq for source, seq in upto.items() if seq > 0}
    if not upto:
        return ""
    held, asked = _held(bus, session, upto, stop, serve,
                        lambda h: all(h.contiguous.get(s, 0) >= n for s, n in upto.items()), wait_s)
    if stop.is_set():
        return ""
    if not asked:
        return _left(session, upto)
    if held is None:
        return f"the recorder did not say within {wait_s:g} s whether it holds {', '.join(sorted(upto))}'s events"
    lacking = said_holes(Held(held.contiguous, held.top, {s: h for s, h in held.holes.items() if s in upto}), upto)
    return (f"the recording lacks {'; '.join(lacking)}: lost on the bus, not refilled within {wait_s:g} s"
            if lacking else "")


def _left(session: str, upto: dict[str, int]) -> str:
    """The words for a recorder gone from the bus when a service asks what it holds. Asked only once the game has
    ended (a recorder gone before is the game's hold, services/recorderwatch.py): a recorder that left (a crash, a
    signal) after the game's end but before the service had its answer let the session exit 0 saying "the external
    recorder writes its file" (trial34 A)."""
    return (f"the recorder left the bus after the game ended, before it said it holds the last events of "
            f"{', '.join(sorted(upto))}: its file may lack them (session {session}; `pairplay rebuild` of it says what)")


def recording_lacks(bus: Bus, session: str, upto: dict[str, int], stop: threading.Event) -> str:
    """Every hole the recording has now, and what it lacks of `upto`, in words ("" if none, or if no recorder is
    on the bus: one that left before the services had their answers is said by them, `until_recorded`). A
    recorder busy with a refill answers late: asked again for at most RECORDED_WAIT_S."""
    upto = {source: seq for source, seq in upto.items() if seq > 0}
    held, asked = _held(bus, session, upto, stop, lambda seconds: stop.wait(seconds), lambda _h: True,
                        RECORDED_WAIT_S)
    if stop.is_set() or not asked:  # (a recorder that held every service's events may leave before this is
        # asked: the services asked it first, `until_recorded`, and one gone before them is said there)
        return ""
    if held is None:
        return f"the recorder did not say whether it holds every event (session {session})"
    lacking = said_holes(held, upto)
    return (f"the recording lacks events lost on the bus that no refill gave back: {'; '.join(lacking)} "
            f"(session {session})" if lacking else "")
