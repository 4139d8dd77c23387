"""The checks every message passes before a service (node.Driver) or the recorder takes it.

Rule (schemas/trust.py states what is trusted): a `Guard` decodes a message
(field ranges are checked there), then refuses it with a reason if its key
disagrees with its envelope, it belongs to another session, its source may
not publish its event, its sequence number is not above the last one on its
key (a duplicate or out of order) or jumps more than MAX_SEQ_JUMP above the
highest seen from its source (a refused jump is not remembered, so a forged
seq 1e9 cannot make the real messages after it look like duplicates), or it
is a second SessionStarted/SessionEnded.

Starts and ends (ONCE_PER_SESSION; issue "forge": whatever came first claiming
to be the game won). Zenoh names no publisher per message, so a guard cannot
authenticate one; it takes a start or an end only where it fits its claimed
source's own sequence, and notices when the source contradicts it later:
- a start or an end whose seq is not above every seq already taken from its
  source is refused (a source starts before and ends after everything else it
  publishes); a start only by a guard that gets the whole session in each
  publisher's order (`whole`): one subscribed by tag gets keys in any order
  between them (a later request may come before the start);
- once one is taken, another event of that source at the same seq, or (an end)
  a later event of the source that is not its shell's (ServiceStarted,
  MessageRejected) nor a start or end, shows the one taken was not the source's
  (and, to a guard subscribed by tag (`by_tag`: the learner, the robot bridge),
  an end of the source at a higher seq: the events between were on keys it does
  not get; any other guard refuses a second end, which cannot displace the one taken):
  the notice is recorded (a MessageRejected naming it, `notices`) and an end's slot is
  given back, so the source's real end is taken when it comes. "Later" is by seq, or,
  for a guard that gets the whole session (`whole`: the recorder, a service not
  subscribed by tag; Zenoh keeps a publisher's order on a link), by arrival. Not on a
  recovering bus (services/bus.py `--recover`): each key has its own publisher there,
  and what an outage held up comes back in order per key only, so the game's next event
  may arrive before its start and an earlier one after its end; judged by arrival, the
  real start was refused (the session then stopped: services/refusal.py) and the real
  end noted as contradicted. There `whole` is off and a guard judges by seq.
A service ignores messages on its own keys, before decoding them (its own,
delivered back to the recorder, which takes the whole session), except the
game (`names_forgeries`): its own publications never come back to it
(services/runner.py Node.subscribe), so a message on its keys is another
process's and is named a forgery (`forged`): the game thus sees a forged start
or end of its session (services/session.py stops it).

A service restarted after a crash takes its state from the recorder's log
(node.Driver.resume) up to a cut point: per key, the last sequence number the
log held (`cut`). A delivery at or below it is what the log already gave, so it
is skipped quietly and counted (`skipped`), never taken again and never a
refusal: the publishers' caches of a recovering bus (services/bus.py) replay
their whole history to a subscriber that joins late, and a plain bus delivers
what was on its way while the log was read. Only what lies above the cut (the
log lagged behind the bus) is new. A forged repeat below the cut is then
skipped by that service too; the recorder, which never restarts into a live
session this way, still refuses and records it.

`Refusals` turns refusals into MessageRejected events, at most
REJECTIONS_PER_S one by one per second; beyond that, and for what an Inbox
shed, it counts and records the counts once a second (`tick`). Every refusal
is recorded, one way or the other; none stops the service.
"""

from __future__ import annotations

import hashlib
import re
from collections import Counter
from typing import Callable, NamedTuple

import msgspec

from pairplay.schemas.envelope import SEQ_MAX, Event
from pairplay.schemas.events import MessageRejected, decode_event
from pairplay.schemas.keys import parse_event_key
from pairplay.schemas.trust import (MAX_NAME, MAX_PAYLOAD, MAX_REASON, MAX_SEQ_JUMP, ONCE_PER_SESSION, REJECTIONS_PER_S,
                                    clip, publisher_refusal)
from pairplay.numbers import counted

EXCERPT = 200
MAX_KINDS = 20
OTHER_KIND = ("*", "other refusals")  # what a refusal beyond MAX_KINDS kinds in a second is counted under
_COUNT = re.compile(r"(\d+) messages? refused and not recorded one by one \(limit \d+/s\): (.*)", re.S)  # tick's
SECOND_NS = 1_000_000_000
CONTRADICTED = "contradicted: "  # how a notice's reason begins (_conflict): not a refusal of the message named
NO_END = 2**62  # above every seq (schemas/envelope.py Seq): no end taken yet
# what does not contradict a start or end taken from its source (_conflict): its shell's events (published
# after its end too) and a start or end itself (a second one is refused: it cannot displace the one taken)
UNCONTRADICTING = frozenset({"ServiceStarted", "MessageRejected"}) | ONCE_PER_SESSION
KEYS_CACHED = 4096
KIND_MAX = 160  # of a counted refusal's reason (Refusals.kind): our own reasons fit whole
FORGED_KEPT = 1000  # forged starts and ends kept for the session to judge (services/forgery.py); the rest are refused


class Verdict(NamedTuple):
    event: Event | None  # decoded (None if it did not decode)
    reason: str | None  # why it is refused (None: taken)
    quiet: bool = False  # nothing to take and nothing to record (our own, or a resume's overlap)


QUIET = Verdict(None, None, quiet=True)
_new_tuple = tuple.__new__


class Guard:
    """`decode`: what turns a payload into the object checked and handed on: the event
    (events.decode_event, for a service that folds it) or its checked twin
    (schemas/checked.py check_event: every check of the event's decoder, for the recorder,
    which writes the bytes and only needs the envelope)."""

    def __init__(self, session: str, own: str | None = None, decode: Callable[[bytes], object] = decode_event,
                 whole: bool = False):
        self.session, self.own, self.decode = session, own, decode
        # it gets every key of the session, each publisher's in its order (False on a recovering bus, whose order
        # holds per key only: see rule)
        self.whole = whole
        # it gets only the keys of the tags its service reads (the learner, the robot bridge): the source's events
        # that would show an end it took was not the source's may never reach it (see rule)
        self.by_tag = False
        self.names_forgeries = False  # a message on our own keys is not ours: a forgery (see rule)
        # forged starts and ends on our own keys, why, and the message's identity (`identity`; `_forged`)
        self.forged: list[tuple[Event, str, bytes]] = []
        self.last_seq: dict[str, int] = {}  # per key
        self.top_seq: dict[str, int] = {}  # per source: the highest taken
        self.once: dict[str, tuple[str, int]] = {}  # ONCE_PER_SESSION tag taken -> (its key, its seq)
        # (key, seq) of every start and end ever taken (a slot given back too) -> the identities of the messages
        # taken there (`identity`; None: folded from a log, its bytes unknown). By identity, not (key, seq): a
        # replayed old start at the seq of the game's own was called taken, and the session stopped (trial28 F14)
        self.took: dict[tuple[str, int], set[bytes | None]] = {}
        self.marks: dict[str, tuple[int, int]] = {}  # per source: seq of the start and of the end taken from it
        self.notices: list[tuple[str, str, str, int]] = []  # (reason, key, source, seq) to record (_conflict)
        self.cut: dict[str, int] = {}  # per key: the last seq a resume took from the log (see rule)
        self.skipped = 0  # deliveries at or below the cut, skipped quietly
        self._keys: dict[str, tuple] = {}  # key -> what the key alone decides (_key)

    def _key(self, key: str) -> tuple:
        """What the key alone decides, once per key: (our own key, its parts, why it is not an
        event key, what an event that matches the key gets: None (checked on), QUIET (our own
        source) or the reason it is refused (wrong session, a source that may not publish it)).
        Cached for at most KEYS_CACHED keys (made-up keys cannot grow the cache); the recorder
        checks every message of a session on a handful of keys."""
        info = self._keys.get(key)
        if info is None:
            own = self.own is not None and key.count("/") == 3 and key.split("/", 3)[2] == self.own
            try:
                k = parse_event_key(key)
            except ValueError as err:
                info = (own, None, str(err), None)
            else:  # the order of check's rule: session, our own source, who may publish the event
                matched = (f"wrong session {k.session!r} (this is {self.session!r})" if k.session != self.session
                           else QUIET if k.source == self.own else publisher_refusal(k.tag, k.source))
                info = (own, k, None, matched)
            if len(self._keys) < KEYS_CACHED:
                self._keys[key] = info
        return info

    def check(self, key: str, payload: bytes, overlap: bool = False) -> Verdict:
        """Decide on one message (see rule). `overlap`: it may repeat what a resume
        already folded from the log; an old sequence number is then quietly skipped."""
        info = self._keys.get(key) or self._key(key)
        if info[0]:
            return self._forged(key, payload) if self.names_forgeries else QUIET
        if len(payload) > MAX_PAYLOAD:
            return Verdict(None, f"payload of {counted(len(payload), 'byte')} is over the limit of {MAX_PAYLOAD}")
        try:
            event = self.decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as err:
            return Verdict(None, f"malformed payload: {err}")
        _own, k, key_error, matched = info
        if k is None:
            return Verdict(event, key_error)
        source = event.source
        if k.source != source or k.session != event.session or k.tag != type(event).__name__:
            return Verdict(event, f"key {key} does not match the payload's session {event.session!r}, source "
                                  f"{source!r}, event {type(event).__name__}")
        if matched is not None:  # what the key decides (_key)
            return Verdict(event, None, quiet=True) if matched is QUIET else Verdict(event, matched)
        seq = event.seq
        last = self.last_seq.get(key, 0)
        if seq <= last:
            if overlap:
                return Verdict(event, None, quiet=True)
            if seq <= self.cut.get(key, 0):  # the log gave it already (see rule)
                self.skipped += 1
                return Verdict(event, None, quiet=True)
            return Verdict(event, f"sequence number {seq} from {source} is not above the last one seen "
                                  f"on {key} ({last}): duplicate or out of order")
        top = self.top_seq.get(source, 0)
        if seq > top + MAX_SEQ_JUMP:
            return Verdict(event, f"sequence number {seq} from {source} jumps more than {MAX_SEQ_JUMP} "
                                  f"above the highest seen from it ({top})")
        marks = self.marks.get(source)
        if marks is not None and (seq == marks[0] or seq == marks[1] or (
                marks[1] < NO_END and self._after_end(k.tag, seq, marks[1], overlap))):
            self._conflict(k.tag, key, source, seq, marks)
        if k.tag in ONCE_PER_SESSION:
            if k.tag in self.once:
                return Verdict(event, f"a second {k.tag} in session {self.session} (the one taken claims {source!r} "
                                      f"seq {self.once[k.tag][1]}; this one seq {seq})")
            # a start or an end is never behind its source's own events (see rule). For a start that is known
            # only to a guard that gets them in the source's order: one subscribed by tag (the learner) may get
            # a SuggestionRequested before the SessionStarted the game sent first (a learner refused the real
            # start so, and the session waited for ever: 1 fresh-clone CI run). An end is the last of the
            # source's events that a by-tag guard takes (only its shell's come after), in any order
            # A refill (`overlap`) fills a hole behind the source's events by definition: a start lost with a
            # damaged chunk is given back so (a restarted recorder's refill refused it: the copy lacked the
            # session's start, test_recorder_continues_losses, once in two fresh-clone CI runs)
            if seq <= top and ((self.whole and not overlap) or k.tag != "SessionStarted"):
                return Verdict(event, f"{k.tag} seq {seq} claiming {source!r} is not after the events {source} "
                                      f"already published (seq {top}): not {source}'s; refused")
            self._take_once(k.tag, key, source, seq, identity(payload))
        self.last_seq[key] = seq  # note(), inlined: seq is above both already or equal to top
        if seq > top:
            self.top_seq[source] = seq
        return _new_tuple(Verdict, (event, None, False))  # Verdict(event, None) without its Python __new__


    def _forged(self, key: str, payload: bytes) -> Verdict:
        """A message on one of our own keys that we did not publish (see rule): named, kept in `forged`."""
        try:
            event = self.decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError):
            event = None
        if event is not None and event.seq <= self.cut.get(key, 0):
            self.skipped += 1  # our own from before a restart, as the log gave it (a cache's replay): see rule
            return QUIET
        what = (f"{type(event).__name__} seq {event.seq} claiming source {event.source!r}" if event is not None
                else "a malformed message")
        reason = f"forged: {what} on {key} was not published by this {self.own} (another process on the bus)"
        if event is not None and type(event).__name__ in ONCE_PER_SESSION and len(self.forged) < FORGED_KEPT:
            # what the session acts on (services/forgery.py); every other forgery is only refused and recorded,
            # so a flood of them cannot grow this list (each refusal is counted: Refusals)
            self.forged.append((event, reason, identity(payload)))
        return Verdict(event, reason)

    def note(self, key: str, event: Event) -> None:
        """Remember a taken event (also: one folded from the log by a resume)."""
        self.last_seq[key] = max(self.last_seq.get(key, 0), event.seq)
        self.top_seq[event.source] = max(self.top_seq.get(event.source, 0), event.seq)
        tag = type(event).__name__
        if tag in ONCE_PER_SESSION and tag not in self.once:
            self._take_once(tag, key, event.source, event.seq)

    def took_message(self, key: str, seq: int, message: bytes) -> bool:
        """Whether this guard took the start or end of identity `message` (`identity`) at (`key`, `seq`): the
        session asks it of a forgery (services/forgery.py). One folded from a log (its bytes unknown) counts as
        that message: a service that resumed cannot tell, and a start or end it may have taken stops the session."""
        taken = self.took.get((key, seq), ())
        return message in taken or None in taken

    def _take_once(self, tag: str, key: str, source: str, seq: int, message: bytes | None = None) -> None:
        """Take a source's SessionStarted/SessionEnded: remember where, so that a later event of the
        source that contradicts it (`_conflict`) can be noticed with one dict lookup per message; and
        which message it was (`message`, its `identity`; None from a log), so a copy at its seq is not it."""
        self.once[tag] = (key, seq)
        self.took.setdefault((key, seq), set()).add(message)
        start, end = self.marks.get(source, (-1, NO_END))
        self.marks[source] = (seq, end) if tag == "SessionStarted" else (start, seq)

    def _after_end(self, tag: str, seq: int, end: int, overlap: bool) -> bool:
        """Does an event of a source, coming after the end taken from it at seq `end`, show that end was not
        the source's (see rule)? Only asked once an end is taken, never on the hot path."""
        if tag not in UNCONTRADICTING:
            return seq > end or (self.whole and not overlap)
        # a guard that gets the whole session in the source's order saw every event between two ends: a second
        # end is refused (it cannot displace the one taken). One subscribed by tag did not: after a forged end it
        # took, the game's refusal of it (a MessageRejected) and its other events are on keys it does not get;
        # the game's real end, at a higher seq, was refused as a second one, and the learner waited GAME_GONE_S
        # (30 s) for the game to leave the bus (test_forge's game in a process of its own: 32 s a run)
        return tag == "SessionEnded" and self.by_tag and seq > end

    def _conflict(self, tag: str, key: str, source: str, seq: int, marks: tuple[int, int]) -> None:
        """An event of `source` contradicts the start or end taken from it (see rule): the one taken
        claimed `source` but was not its (another event at its seq, or events after an end). The end's
        slot is given back (the source's real end is taken when it comes); the notice is recorded."""
        start, end = marks
        if seq == start:
            what, other = "SessionStarted", f"{tag} seq {seq} claims the same seq"
        else:
            what = "SessionEnded"
            other = f"{tag} seq {seq} came {'at the same seq' if seq == end else 'after it'}"
            self.once.pop("SessionEnded", None)
            self.marks[source] = (start, NO_END)
        taken = self.once.get(what, (event_key_of(key, what), start if what == "SessionStarted" else end))
        self.notices.append((f"{CONTRADICTED}the {what} taken as {source}'s (seq {taken[1]}) was not {source}'s: {other}"
                             + ("; its real end will be taken" if what == "SessionEnded" else ""),
                             taken[0], source, taken[1]))


def recordable(text: str) -> str:
    """`text` as an event can carry it: one that UTF-8 cannot encode (a lone surrogate) with it escaped.
    A refusal is about what came from outside; a MessageRejected that cannot be encoded, or that its
    peers refuse (an offending seq above the bus's bound), is a refusal lost (module rule: every refusal
    is recorded), so `Refusals.refuse` bounds each of its fields before it builds one."""
    try:
        text.encode()
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode()


class Refusals:
    """Refusals -> MessageRejected events, rate-limited with counts (see rule). A refusal's fields are
    bounded as the bus checks them (`recordable`): its seq 0 and the reason saying the number if it lies
    beyond the bus's (a page's `id` of 2**64 made a MessageRejected every peer refused)."""

    def __init__(self, per_s: int = REJECTIONS_PER_S):
        self.per_s = per_s
        self.window_ns: int | None = None
        self.in_window = 0
        self.held: Counter = Counter()  # (source, kind) -> refusals not recorded one by one yet
        self.total = 0
        self.recorded = False  # the last refusal was recorded one by one (not only counted)

    def refuse(self, now_ns: int, reason: str, key: str, source: str = "", seq: int = 0,
               payload: bytes = b"") -> list[MessageRejected]:
        """The MessageRejected events to publish for one refusal (`recorded`: whether it was recorded one
        by one). The reason, key and source may quote a hostile message (a 60,000-character source): each
        is clipped (schemas/trust.py clip), so the refusal always fits the bus's MAX_PAYLOAD; a larger
        one was shed unread by every listener, a hole in the recording (trial28 F21)."""
        self.total += 1
        out = self.tick(now_ns)
        self.recorded = self.in_window < self.per_s
        if self.recorded:
            self.in_window += 1
            if not (type(seq) is int and 0 <= seq <= SEQ_MAX):  # (a page's id, a made-up number: see recordable)
                reason, seq = f"{reason} (its seq {str(seq)[:40]} is beyond the bus's 0..{SEQ_MAX})", 0
            out.append(MessageRejected(reason=recordable(clip(reason, MAX_REASON)),
                                       key=recordable(clip(str(key), MAX_NAME)),
                                       offending_source=recordable(clip(source, MAX_NAME)), offending_seq=seq,
                                       excerpt=excerpt(payload)))
        else:
            self._hold(source, reason)
        return out

    @staticmethod
    def kind(source: str, reason: str) -> tuple[str, str]:
        """What a refusal is counted under: (its source, its reason without numbers and details)."""
        # clipped at a word with its marker (a cut "(lost on the bus" read as the whole reason: trial33 L)
        return source[:40], clip(re.sub(r"\d+", "N", reason.split(":", 1)[0]), KIND_MAX)

    @staticmethod
    def counted(rejection: MessageRejected) -> tuple[tuple[str, str], int] | None:
        """(kind, how many) if `rejection` is a count of refusals not recorded one by one (`tick`),
        else None (one refusal recorded by itself)."""
        found = None if rejection.key else _COUNT.match(rejection.reason)
        return ((rejection.offending_source, found[2]), int(found[1])) if found else None

    def _hold(self, source: str, reason: str, n: int = 1) -> None:
        """Count a refusal under its kind: the reason without its numbers and details; at most
        MAX_KINDS kinds a second (made-up sources or keys cannot make the summary a flood)."""
        kind = self.kind(source, reason)
        if kind not in self.held and len(self.held) >= MAX_KINDS:
            kind = OTHER_KIND
        self.held[kind] += n

    def shed(self, counts: Counter) -> None:
        """Messages an Inbox shed, by (source, why): recorded as counts at the next tick."""
        self.total += sum(counts.values())
        for (source, why), n in counts.items():
            self._hold(source, f"shed unread ({why})", n)

    def tick(self, now_ns: int, force: bool = False) -> list[MessageRejected]:
        """A new second (or `force`: the end): the counts of what was not recorded one by one."""
        if not force and self.window_ns is not None and now_ns - self.window_ns < SECOND_NS:
            return []
        self.window_ns, self.in_window = now_ns, 0
        held, self.held = self.held, Counter()
        return [MessageRejected(reason=f"{counted(n, 'message')} refused and not recorded one by one (limit {self.per_s}/s): "
                                       f"{kind}", key="", offending_source=source, excerpt="")
                for (source, kind), n in sorted(held.items())]

    def pending(self) -> bool:
        return bool(self.held)


def excerpt(payload: bytes) -> str:
    """A refusal's excerpt of the message it refused (MessageRejected.excerpt): its first EXCERPT bytes as text."""
    return bytes(payload[:EXCERPT]).decode("utf-8", "replace")


def identity(payload: bytes) -> bytes:
    """What tells one message from another at the same key and seq (a replayed or forged copy of a start
    or end): a digest of its bytes, as every listener in the process got them. Only taken for starts and
    ends, never on the hot path."""
    return hashlib.blake2b(payload, digest_size=16).digest()


def event_key_of(key: str, tag: str) -> str:
    """`key` (pairplay/<session>/<source>/<tag>) with its tag replaced."""
    return key.rsplit("/", 1)[0] + "/" + tag
