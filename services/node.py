"""The shell every service runs in: check the envelope, feed the logic, stamp, publish.

Rule: a service's decisions live in a *logic* object (GameLogic, LearnerLogic,
ParticipantLogic) that turns input events into output events and knows
nothing of Zenoh or clocks. The `Driver` around it never trusts input: what
fails the checks of services/guard.py (decoding and field ranges, key against
envelope, session, who may publish the event, sequence numbers per key and
their jumps per source, one start and one end) or what the logic refuses
(`Rejected`) becomes a MessageRejected event with the reason (rate-limited,
with counts beyond the limit); the service goes on. An input
that arrives before what it depends on (messages from different sources may
overtake each other on different links) raises `NotYet`: it is kept and
retried after every later input, so the logic sees a causal order whatever the
network did. That makes a logic a deterministic function of its inputs, which
three things rely on:
- live: `Node` runs a Driver on the bus;
- restart: `Driver.resume(log)` re-feeds a crashed service's recorded inputs,
  holds back the outputs the log already has (the first N outputs are the N
  recorded ones) and publishes only what the crash left undone; the log is its
  cut point: later deliveries of what the log held (a recovering bus replays the
  publishers' caches to a late joiner) are skipped quietly (services/guard.py);
- verify: the same re-feeding on a whole recording, every output compared.
"""

from __future__ import annotations

import logging
from bisect import insort
from collections import deque
from typing import Callable, Iterable, Protocol

import msgspec

from pairplay.replay.fold import stream_seed  # noqa: F401  (re-exported for the services)
from pairplay.schemas.envelope import Event, stamped
from pairplay.schemas.events import MessageRejected, ServiceStarted
from pairplay.schemas.keys import event_key

from pairplay.services.guard import Guard, Refusals

log = logging.getLogger("pairplay.node")
SHELL_TAGS = frozenset({"ServiceStarted", "MessageRejected"})  # published by the shell, not the logic


class Rejected(Exception):
    """The logic refuses an input; the message is the reason recorded."""


class NotYet(Exception):
    """The input depends on one that has not arrived yet: keep it and retry."""


class Logic(Protocol):
    name: str
    consumes: frozenset[str]
    sources: dict[str, frozenset[str]]  # tag -> the only sources it is taken from (missing: any)
    done: bool
    # optional `by_tag = True`: the logic copes with any order between keys, so its Node may
    # subscribe to just the tags it reads (less traffic, lower latency); otherwise one
    # subscription to the whole session keeps each source's order.

    def start(self) -> list[Event]: ...

    def handle(self, event: Event) -> list[Event]: ...

    # optional `comparable(event) -> event`: what of a recorded output a recomputed one must equal, where
    # a text once worded otherwise means the same (GameLogic: PickRejected's reason, rounds once counted
    # from 0); resume and verify compare `comparable` of both (Driver.same)


def refused_start(logic, event: Event) -> bool:
    """What a logic with no session config does with `event`: waits for the start (NotYet), unless it
    refused the start (`logic.refused`: why). Then it can play no part: it ends on the game's end (True:
    the logic marks itself ended) and refuses everything else, naming why; before, it held them, and the
    end behind them, for ever (a `pairplay run learner` that refused the start ran on after the session)."""
    if not logic.refused:
        raise NotYet
    if type(event).__name__ != "SessionEnded":
        raise Rejected(f"the session's start was refused ({logic.refused[:200]})")
    return True


def _seq(event: Event) -> int:
    return event.seq


def content(event: Event) -> Event:
    """The event without its envelope: what verify and resume compare."""
    return msgspec.structs.replace(event, session="", source="", seq=0, time_ns=0)


class Driver:
    def __init__(self, logic: Logic, session: str, clock: Callable[[], int]):
        self.logic, self.session, self.clock = logic, session, clock
        self.guard = Guard(session, own=logic.name)
        self.refusals = Refusals()
        self.seq = 0
        self.deferred: dict[str, list[Event]] = {}  # per source, in its sequence order
        self.held_back: deque[Event] = deque()  # recorded outputs a resume must not repeat
        self.mismatches: list[str] = []
        self.replaying = False  # during resume/verify: rejections were already recorded live
        self._unmarked = False  # during a resume over a log without the logic's marks (resume's rule)

    @property
    def last_seq(self) -> dict[str, int]:
        return self.guard.last_seq

    @property
    def rejections(self) -> int:
        return self.refusals.total

    # -- output -------------------------------------------------------------
    def _stamp(self, events: Iterable[Event]) -> list[Event]:
        out = []
        for e in events:
            if self._unmarked and self.held_back and self.logic.placed(e) is not None:
                continue  # a mark resume makes over a log from before the marks (resume's rule)
            if self.held_back and not isinstance(e, (MessageRejected, ServiceStarted)):
                recorded = self.held_back.popleft()
                if not self.same(recorded, e):
                    self.mismatches.append(f"{type(recorded).__name__} seq {recorded.seq}: recorded "
                                           f"{content(recorded)!r}, recomputed {content(e)!r}")
                continue
            self.seq += 1
            out.append(stamped(e, session=self.session, source=self.logic.name, seq=self.seq, time_ns=self.clock()))
        return out

    def same(self, recorded: Event, recomputed: Event) -> bool:
        """Whether a recomputed output says what the recorded one says (module rule: resume, verify):
        equal content, or equal after the logic's optional `comparable` (old wordings of a text)."""
        if content(recorded) == content(recomputed):
            return True
        comparable = getattr(self.logic, "comparable", None)
        return comparable is not None and content(comparable(recorded)) == content(comparable(recomputed))

    def reject(self, reason: str, key: str, source: str = "", seq: int = 0, payload: bytes = b"") -> list[Event]:
        """Record a refusal (rate-limited: guard.Refusals); the events to publish."""
        if self.replaying:
            self.refusals.total += 1
            return []
        out = self.refusals.refuse(self.clock(), reason, key, source, seq, payload)
        if self.refusals.recorded:  # logged as recorded: one by one up to the rate, then counted
            log.warning("%s rejected %s from %r seq %s: %s", self.logic.name, key, source, seq, reason[:300])
        return self._stamp(out)

    def tick(self, shed=None, force: bool = False) -> list[Event]:
        """Once in a while (the Node's loop): the counts of refusals not recorded one by one,
        and of what the service's Inbox shed."""
        if shed:
            self.refusals.shed(shed)
        if not self.refusals.pending() or self.replaying:
            return []
        return self._stamp(self.refusals.tick(self.clock(), force))

    def start(self) -> list[Event]:
        return self._stamp(self.logic.start())

    # -- input --------------------------------------------------------------
    def receive(self, key: str, payload: bytes) -> list[Event]:
        """One bus message in, the stamped events to publish out (see rule and guard.py).
        What a resume already took from the log is skipped quietly (the guard's cut)."""
        verdict = self.guard.check(key, payload)
        if self.guard.notices:  # a start or end taken earlier was contradicted (guard._conflict)
            return self._noticed() + self._take(verdict, key, payload)
        return self._take(verdict, key, payload)

    def _noticed(self) -> list[Event]:
        """Record the guard's notices (a start or end it took turned out not to be its source's)."""
        out: list[Event] = []
        for reason, key, source, seq in self.guard.notices:
            out += self.reject(reason, key, source, seq)
        self.guard.notices.clear()
        return out

    def _take(self, verdict, key: str, payload: bytes) -> list[Event]:
        if verdict.quiet:
            return []
        event = verdict.event
        if verdict.reason is not None:
            return self.reject(verdict.reason, key, getattr(event, "source", ""), getattr(event, "seq", 0), payload)
        return self.feed(event, key, payload)

    def feed(self, event: Event, key: str = "", payload: bytes = b"") -> list[Event]:
        """Hand an accepted event to the logic, then retry what waits on it.

        A source's events reach the logic in that source's order (its sequence
        numbers): while an earlier event of a source waits (`NotYet`), a later
        one of the same source waits behind it, so a held TurnResolved is never
        overtaken by the next RoundStarted. Only events of different sources
        may pass each other, and each logic orders those by their references.
        """
        tag = type(event).__name__
        if tag not in self.logic.consumes:
            return []
        allowed = self.logic.sources.get(tag)
        if allowed is not None and event.source not in allowed:
            return self.reject(f"{tag} is taken only from {', '.join(sorted(allowed))}, not from {event.source!r}",
                               key, event.source, event.seq, payload)
        waiting = self.deferred.get(event.source)
        if waiting and waiting[0].seq < event.seq:
            insort(waiting, event, key=_seq)
            return []
        return self._handle(event, key, payload) + self._retry()

    def _retry(self) -> list[Event]:
        """Hand the logic the first waiting event of each source until none can go on."""
        out: list[Event] = []
        progress = True
        while progress:
            progress = False
            for waiting in self.deferred.values():
                while waiting:
                    head = waiting[0]
                    try:
                        produced = self.logic.handle(head)
                    except NotYet:
                        break
                    except Rejected as err:
                        produced = None
                        out += self.reject(str(err), "", head.source, head.seq)
                    except Exception as err:  # a bug must not stop the service: record it and go on
                        log.exception("%s failed on %s", self.logic.name, type(head).__name__)
                        produced = None
                        out += self.reject(f"internal error {type(err).__name__}: {err}", "", head.source, head.seq)
                    waiting.pop(0)
                    out += self._stamp(produced) if produced is not None else []
                    progress = True
        return out

    def _handle(self, event: Event, key: str, payload: bytes) -> list[Event]:
        try:
            return self._stamp(self.logic.handle(event))
        except NotYet:
            insort(self.deferred.setdefault(event.source, []), event, key=_seq)
            return []
        except Rejected as err:
            return self.reject(str(err), key, event.source, event.seq, payload)
        except Exception as err:  # a bug must not stop the service: record it and go on
            log.exception("%s failed on %s", self.logic.name, type(event).__name__)
            return self.reject(f"internal error {type(err).__name__}: {err}", key, event.source, event.seq, payload)

    def _marked(self, recorded: list[Event], own: list[Event]) -> tuple[bool, set[tuple], dict[int, Event]]:
        """Whether the log holds the logic's marks, the (source, tag, seq) of the inputs they mark, and
        {seq of a recorded mark: the recorded input it marks} (resume's rule)."""
        placed = getattr(self.logic, "placed", None)
        if placed is None:
            return False, set(), {}
        marks = {placed(e): e.seq for e in own if placed(e) is not None}
        tags = getattr(self.logic, "PLACED", frozenset())
        inputs = {(e.source, type(e).__name__, e.seq): e for e in recorded
                  if e.session == self.session and type(e).__name__ in tags}
        # a log whose service said it marks these inputs (its ServiceStarted) is marked with no mark in it too:
        # a game that took no pause, and refused one after its last touch that was filed before that touch
        declared = any(isinstance(e, ServiceStarted) and tags and tags <= set(e.marks) for e in own)
        return bool(marks) or declared, set(marks), \
            {seq: inputs[named] for named, seq in marks.items() if named in inputs}

    def _place(self, at_mark: dict[int, Event]) -> list[Event]:
        """Feed the inputs whose recorded mark is the next output to recompute (resume's rule)."""
        out: list[Event] = []
        while self.held_back and self.held_back[0].seq in at_mark:
            out += self._refeed(at_mark.pop(self.held_back[0].seq))
        return out

    def _refeed(self, e: Event) -> list[Event]:
        """Feed a recorded input again, unless the live service took its seq already (a duplicate it rejected)."""
        key = event_key(e.session, e.source, type(e).__name__)
        if e.seq <= self.guard.last_seq.get(key, 0):
            return []
        self.guard.note(key, e)
        return self.feed(e)

    def _only_left(self, event: Event) -> bool:
        """Whether `event` is the one recorded output left to recompute."""
        return len(self.held_back) == 1 and self.held_back[0] is event

    @property
    def waiting(self) -> int:
        """Inputs held until what they depend on arrives."""
        return sum(len(q) for q in self.deferred.values())

    # -- restart and verify ------------------------------------------------
    def resume(self, recorded: list[Event], start: bool = True, announce: Event | None = None,
               stopped: Event | None = None) -> list[Event]:
        """Re-feed a recorded session (file order); return the outputs it still owes.

        The service's own recorded outputs are held back: the first outputs the
        logic recomputes are compared with them instead of being published.
        `stopped`: the recorded SessionEnded a stopped session's shell made its game
        publish (services/session.py `end_game`: interrupted, aborted, failed). The
        live game handled no input after it, so inputs stop being fed once it is the
        only output left to recompute, and the logic is ended as the shell ended it
        (`logic.end(reason, detail)`): its round and turn counts are compared too.
        An input whose whole effect is that end (the logic's ENDS_SESSION: the experimenter's abort) is
        not fed: the recorder may have filed it before inputs the live game took first.
        An input the logic marks where it took it (its PLACED tags, answered by an output `placed(output)`
        names: the game's ControlTaken for a pause or resume) is fed where its recorded mark stands among
        the outputs, once every output before the mark is recomputed, not where the file holds it (the
        recorder filed it as it reached it: maybe the other side of a touch in flight). In a log with
        marks, one without a mark was not taken (refused: it changed nothing) and is not fed while
        recorded outputs are left to compare; beyond them (a log cut after it) it is fed in file order.
        A log is marked when it holds a mark or its service's ServiceStarted names the tags it marks (`marks`:
        a game that took no pause has no mark, and one it refused after its last touch may be filed before it).
        A log without either (made before ControlTaken) is fed in file order, as it always was, and
        the marks the logic makes among its recorded outputs are dropped: the log has none to compare
        them with (one beyond them is owed: a game restarted after taking its first pause, unmarked).
        """
        own = [e for e in recorded if e.source == self.logic.name and e.session == self.session]
        self.held_back = deque(e for e in own if type(e).__name__ not in SHELL_TAGS)
        self.seq = max([self.seq] + [e.seq for e in own])  # new outputs continue the numbering
        out = self._stamp([announce]) if announce is not None else []
        has_marks, marked, at_mark = self._marked(recorded, own)
        placed_tags = getattr(self.logic, "PLACED", frozenset()) if has_marks else frozenset()
        self.replaying = True
        self._unmarked = hasattr(self.logic, "placed") and not has_marks  # the logic's marks are dropped (_stamp)
        refused: list[Event] = []  # placed inputs without a mark: not taken live
        try:
            out += self.start() if start else []
            for e in recorded:
                out += self._place(at_mark)
                if stopped is not None and self._only_left(stopped):
                    break
                if e.source == self.logic.name or e.session != self.session:
                    continue
                tag = type(e).__name__
                if stopped is not None and tag in getattr(self.logic, "ENDS_SESSION", ()):
                    continue  # applied where the recorded end says, below (an abort filed before inputs taken first)
                if tag in placed_tags and (self.held_back or (e.source, tag, e.seq) in marked):
                    refused += [] if (e.source, tag, e.seq) in marked else [e]
                    continue  # fed at its mark (_place), or not taken live (no mark): a refusal changed nothing
                out += self._refeed(e)
            out += self._place(at_mark)
            for e in refused:  # taken from the log all the same: a later delivery of it is skipped (guard.cut)
                self.guard.note(event_key(e.session, e.source, type(e).__name__), e)
            if stopped is not None and self._only_left(stopped) and not self.logic.done:
                out += self._stamp(self.logic.end(stopped.reason, stopped.detail))
        finally:
            self.replaying = self._unmarked = False
            self.guard.cut = dict(self.guard.last_seq)  # deliveries up to here repeat the log (guard.py)
        # anything still held back was recorded but not recomputed: a divergence
        self.mismatches += [f"recorded {type(e).__name__} seq {e.seq} was not recomputed" for e in self.held_back]
        self.held_back.clear()
        return out
