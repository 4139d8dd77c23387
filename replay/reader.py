"""Reading the event log, also when the file was cut short by a crash.

Rule: records are read in file order by `mcapscan.scan`, which checks
everything the MCAP format lets a reader check (magic, record lengths, chunk
CRCs and sizes, message indexes, the data-section and summary CRCs, chunk
order) and reads only the parts that pass: a damaged chunk gives no records,
every intact part around it does. What is wrong is in `damage` (which part, why);
a file that stops early is `truncated` (the reason in `error`); `whole` is true
only for a file with neither. Nothing raises but an unreadable path. Each
message is decoded with msgspec into its event class; a message of an event
type this version does not know (a newer pairplay's) is counted and kept as an
`UnknownEvent` by its tag; any other message that does not decode is kept as a
`BadMessage` with the reason (a recording is evidence: nothing is dropped
silently). Identical copies of one event (its session, source and seq, the same
bytes: a message stored twice, a chunk written again) are read once and counted
(`copies`, said by `copied` in the line every verb says of the file: `loss_free`,
`missing`); a differing event of the same (session, source, seq) is kept, for
replay/forgery.py to judge. A read told `only` some tags looks no further into
the events it does not read than their tag and seq, but for the game's (its copies are
checked): their copies change nothing it makes, and are counted with them. An event whose channel's key names another session,
source or type is not read: a `BadMessage`, as on the bus (`disagreement`). A
gap in any source's seq in a file that lost no part is events missing (`gaps`),
and event channels whose schema is not pairplay's are said (`foreign_schemas`). A message that does not decode is an event every verb reading the
file lacks (a Q update among them: a Q-table the learner never had), so such a
file is damaged as one that lost a part: `EventLog.undecoded` says so in the one
line every verb uses (rebuild, counterfactual, replay and verify, view, report),
`damaged` and `note` join it to the file's damaged parts and its cut.
`stream_log` reads a file as `read_any_log` does, its events given to a fold a chunk's at a time and not kept (a
file whose losses or repeated seqs can be judged only at its end is NotStreamed: read it whole). `fold_log` is
how a verb reads a recording: streamed, or whole for a file a stream cannot judge, the same fold either way
(rebuild, verify, view, counterfactual, a study's report); `events_of` keeps the events alone for a verb that
needs them all at once, never the file's records and each event's bytes.
`EventDecoderFactory` plugs the same decoding into mcap's own readers.
"""

from __future__ import annotations

import gc
import json
from array import array
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import msgspec
from mcap.decoder import DecoderFactory
from mcap.records import Channel, Message, Metadata, Schema

from pairplay.livelock import LIVE, is_live
from pairplay.numbers import counted
from pairplay.schemas.envelope import Event, Seq
from pairplay.schemas.jsonfile import MCAP_MAGIC
from pairplay.schemas.events import EVENT_BY_TAG, Count, RewardGiven, SessionEnded, SessionStarted, decode_event
from pairplay.schemas.events import event_decoder as _event_decoder
from pairplay.schemas.keys import ROOT as KEY_ROOT
from pairplay.schemas.trust import STARTERS

from .mcapscan import Damage, scan
from pairplay.schemas.nesting import TOO_DEEP, JsonDecoder, json_loads


class RecordedEvent(NamedTuple):
    key: str  # the channel topic: the bus key
    event: Event
    log_time_ns: int
    payload: bytes


class UnknownEvent(NamedTuple):
    """A well-formed event of a type this version does not know (from a newer pairplay)."""

    key: str
    tag: str
    log_time_ns: int
    payload: bytes


class _Tagged(msgspec.Struct):
    type: str
    session: str = ""
    source: str = ""
    seq: Seq = 0  # (in range, as the event's: else decoded wholly, a bad message; `seq_jumps` keeps them in int64)


_tagged = JsonDecoder(_Tagged)


class _Typed(msgspec.Struct):
    type: str
    seq: Seq = 0


# only the tag and the seq: what an event a verb does not read is checked for (speed; its seq: `gaps`, from the one
# parse the tag needed: the rest of the payload is skipped unread either way)
_typed = JsonDecoder(_Typed)


class _TypedNamed(_Typed):
    """`_Typed`, and what an event of `NAMES` or `TURNS` names: its request_seq or its pick_seq (0: a recording from
    before the field), or its round and turn, read in the same parse (`misnamed`, `_named_value`)."""

    request_seq: Seq = 0
    pick_seq: Seq = 0
    round: Count = 0
    turn: Count = 0


class _TaggedNamed(_Tagged):
    """`_Tagged`, and what it names, as `_TypedNamed`."""

    request_seq: Seq = 0
    pick_seq: Seq = 0
    round: Count = 0
    turn: Count = 0


def _named_value(kind: str, e) -> int:
    """What event `e` of tag `kind` (`NAMES`, `TURNS`) names, as one number: the seq it names, or its turn
    (round << 32 | turn: both under 2**31)."""
    if kind == "SuggestionMade":
        return e.request_seq
    if kind in ("CardRevealed", "PickRejected"):
        return e.pick_seq
    return e.round << 32 | e.turn


_typed_named = JsonDecoder(_TypedNamed)
_tagged_named = JsonDecoder(_TaggedNamed)


def unknown_tag(payload: bytes) -> str | None:
    """The tag of a payload that is a well-formed event of a type this version does not know, else None."""
    try:
        head = _tagged.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None
    return head.type if head.type and head.type not in EVENT_BY_TAG else None


class BadMessage(NamedTuple):
    key: str
    reason: str
    log_time_ns: int
    payload: bytes


@dataclass
class EventLog:
    """Everything a recording holds, in file order."""

    path: str
    events: list[RecordedEvent] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    bad: list[BadMessage] = field(default_factory=list)
    truncated: bool = False
    data_complete: bool = False  # its Data End was read: a cut or damage after it (the summary) lost no message
    error: str = ""  # what is wrong with the file: every damaged part and the cut ("" if whole)
    brief: str = ""  # the same in one short line: what was lost where (mcapscan's `Scan.brief`)
    live: bool = False  # its end is missing because its recorder is still writing it, not a crash
    damage: list[Damage] = field(default_factory=list)  # the parts that failed a check (not read)
    lost_from: int = -1  # where the first part whose records are lost was, as an index of `events` (-1: none)
    # where events are lost, as indexes of `events` (the event before each was read, the one at it after the loss):
    # every damaged part whose records are lost, and every message that does not decode (`bad`)
    lost_at: list[int] = field(default_factory=list)
    unknown: list[UnknownEvent] = field(default_factory=list)
    channels: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (topic, schema name)
    skipped: dict[str, int] = field(default_factory=dict)  # read_log(only=...): events not decoded, by tag
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)  # id -> (name, encoding, data)
    # a file `pairplay recover` made of a damaged one: what its source lost (the file itself may be whole, its
    # session is not), in one short line (from its RECOVERED metadata); "" if its source lost no
    # message (an index, a CRC: the session is whole) or it is no recovered file
    source_lost: str = ""
    # identical copies of one event (its session, source and seq, the same bytes) read once (module rule: `copied`)
    copies: int = 0
    # events read at a (session, source, seq) an earlier, different event holds: replay/forgery.py's to judge
    differing: int = 0
    # where a source's seq skips numbers between two events read (every source's: each numbers its events 1, 2,
    # 3, ..., services/node.py): (source, seq before, seq after), by source, then seq (`gaps`)
    seq_jumps: list[tuple[str, int, int]] = field(default_factory=list)
    # events missing that no seq shows (a source's tail, an event cut and the rest renumbered), seen as answers
    # fewer or more than what they answer, or as seqs named by another source's events (a request_seq, a pick_seq)
    # that hold no event of the kind named: (the source missing them, the clause saying what and what shows it):
    # `unanswered`, `misnamed`, `gaps`
    unanswered: list[tuple[str, str]] = field(default_factory=list)
    # a seq held by more than one event just before a hole in its source's seqs (one renumbered, not lost):
    # (source, seq) (`gaps`)
    repeated: list[tuple[str, int]] = field(default_factory=list)

    @property
    def copied(self) -> str:
        """The identical copies of events the file held, read once, in one short line ("" if none): a file whose
        every message was stored twice (a copying tool, a chunk written again) was folded twice, exit 0: a
        policy of doubled visits and Q updated twice (a hostile user's trial). A copy changes nothing, so it is
        said, not a loss; a differing event of the same (session, source, seq) is no copy (replay/forgery.py)."""
        if not self.copies:
            return ""
        return f"{counted(self.copies, 'identical copy', 'identical copies')} of events read once"

    @property
    def foreign_schemas(self) -> str:
        """The channels of pairplay events whose schema is not pairplay's, in one short line ("" if none): the
        events decode all the same (pairplay reads the JSON, not the schema), but the file misdescribes them to any
        other MCAP reader (Foxglove), and `recover` copies it along (schemas replaced by `{"type":"string"}` or by
        bytes that are not JSON passed every verb with no word: a hostile user's trial). A schema is pairplay's if it
        is a JSON Schema ("jsonschema") named as its channel's event, a JSON object of that title and of type
        "object" (what schemas/jsonschema.py writes; the exact text changes as events gain fields, so is not
        compared)."""
        wrong = []
        for topic, schema_id in self.channels.values():
            tag = topic.rsplit("/", 1)[-1]
            if tag in EVENT_BY_TAG:
                why = not_pairplays(tag, self.schemas.get(int(schema_id)))
                if why:
                    wrong.append(f"{tag}: {why}")
        if not wrong:
            return ""
        many = len(wrong) > 1
        return (f"{counted(len(wrong), 'channel')}{chr(39) + ' schemas are' if many else chr(39) + 's schema is'} not "
                f"pairplay's ({wrong[0]}{', ...' if many else ''}): the events are read as their JSON says")

    @property
    def said_too(self) -> str:
        """What every verb says of a file beside what it lost, in one short line ("" if nothing): identical copies
        read once (`copied`), schemas that are not pairplay's (`foreign_schemas`); neither loses an event."""
        return "; ".join(n for n in (self.copied, self.foreign_schemas) if n)

    @property
    def gaps(self) -> str:
        """The events missing from a file that lost no part, in one short line ("" if none, or if a lost part, a
        message that does not decode or the file it was recovered from lost them: they say so): `gaps_of` every
        source."""
        return self.gaps_of()

    def gaps_of(self, sources: frozenset[str] | None = None, but: frozenset[str] = frozenset()) -> str:
        """`gaps` of the sources in `sources` (None: every one) but those in `but`, in one short line, one clause
        per source: every source numbers its events 1, 2, 3, ... per session (the game, the learner, the
        participant, the robot, the board's server, the recorder, the experimenter's console: one numbering
        each, resumed after a restart: services/node.py, services/protocol.py), so a skipped number is an event
        the file lacks although every byte of it checks out (a copying tool that dropped the RoundEnded: view
        said "0 notes", rebuild "the session ended (completed) before round 1"; a learner's QUpdated seq 16
        rewritten as 999: rebuild and view said nothing, verify only DIFFERS: hostile users' trials). A seq far
        past the source's others is said as that, not as the events between (a seq 189 rewritten as 999 was "800
        events missing"), and a hole after a seq held twice as a seq repeated (21 rewritten as 20 was "1 event
        missing"). A first seq past 1 of the game or the learner is a hole at the start (`FROM_ONE`; another
        source's events before its first one in the file are not counted, as the recorder counts holes:
        services/recorder.py `_holes`: the board's start is not in a pilot's recordings). What no seq shows
        (a source's end, an event cut and the rest renumbered): answers fewer or more than what they answer
        (`unanswered`: the learner's last Q update dropped, rebuild wrote a whole, wrong policy: a new user's
        trial), a seq another source's event names holding no event of the kind named (`misnamed`); said by
        what is missing, never "the last": a count cannot tell where."""
        if not (self.seq_jumps or self.unanswered) or self.lost_at or self.source_lost:
            return ""
        by: dict[str, list[tuple[int, int]]] = {}
        for source, before, after in self.seq_jumps:
            if (sources is None or source in sources) and source not in but:
                by.setdefault(source, []).append((before, after))
        twice = set(self.repeated) if not self.copies else set()  # (copies hold every seq twice: no sign there)
        said = []
        for source, jumps in by.items():
            clauses, n, holes = [], 0, []
            last = max(after for _, after in jumps)
            for before, after in jumps:
                if before == 0:  # seq 0 read: no source numbers an event 0 (a seq 1 rewritten as 0)
                    clauses.append(f"an event has seq 0 (seqs start at 1; its next is {after})")
                elif before == -1:  # (`seq_jumps`' mark of a first seq past 1)
                    first = "event" if after == 2 else counted(after - 1, "event")
                    clauses.append(f"its first {first} missing: its seq starts at {after}")
                elif after == last and after - before - 1 > before:  # far past the rest: a seq renumbered
                    clauses.append(f"an event has seq {after}, far past its others (the last {before})")
                elif (source, before) in twice:
                    clauses.append(f"seq {before} held by two events, none by {before + 1}: one renumbered")
                else:
                    n += after - before - 1
                    holes.append((before, after))
            if holes:
                (before, after), more = holes[0], len(holes) - 1
                clauses.insert(0, f"{counted(n, 'event')} missing: its seq jumps from {before} to {after}"
                               + (f" and in {counted(more, 'other place')}" if more else ""))
            # (one hole alone: said as before, "N events of 'x' missing: ...")
            alone = holes and len(clauses) == 1
            said.append(clauses[0].replace(" missing:", f" of {source!r} missing:", 1) if alone
                        else f"{source!r}: " + ", ".join(clauses))
        for source, clause in self.unanswered:
            # (a source with holes said: they are the answers missing; one clause a source)
            if (sources is None or source in sources) and source not in but and source not in by:
                by[source] = []
                said.append(clause)
        return "; ".join(said)

    @property
    def whole(self) -> bool:
        """Every byte of the file checked out and nothing is missing at its end."""
        return not self.truncated and not self.damage

    @property
    def cut_lost(self) -> bool:
        """Whether the file's cut lost events: it stops before its data section's end (a cut in the summary,
        after the Data End, lost none: every message was read)."""
        return self.truncated and not self.data_complete

    @property
    def undecoded(self) -> str:
        """The messages in the file that do not decode, in one short line ("" if none): how many, the first's
        channel and reason (a new user's trial: rebuilt, then fitted, with exit 0 and no word)."""
        said = []
        for wrong in (False, True):  # what does not decode; what its key does not name (`disagreement`)
            bad = [m for m in self.bad if m.reason.startswith(DISAGREES) == wrong]
            if bad:
                one = len(bad) == 1
                what = (("is not what its key names" if one else "are not what their key names") if wrong
                        else f"{'does' if one else 'do'} not decode")
                why = bad[0].reason.removeprefix(DISAGREES).lstrip(":, ")
                said.append(f"{len(bad)} message{'' if one else 's'} in it {what} "
                            f"({bad[0].key or 'no channel'}: {why[:80]})")
        return "; ".join(said)

    @property
    def damaged(self) -> str:
        """What is damaged in the file, in one short line ("" if nothing): its damaged parts (`brief`) and
        the messages that do not decode (`undecoded`); a cut alone is not damage."""
        return "; ".join(n for n in (self.brief if self.damage else "", self.undecoded, self.gaps) if n)

    @property
    def source_cut(self) -> str:
        """What a recovered file's source lost to its cut, in one short line (`said_source_cut`; "" if it was not
        cut before its data section's end, or this is no recovered file): the file is whole, its session is a
        part, as the cut file's was (a new user's trial: view and counterfactual said nothing of it)."""
        return said_source_cut(self.metadata.get(RECOVERED, {}))

    @property
    def loss_free(self) -> str:
        """What is wrong with a file that lost no event (a damaged summary or index, a cut after its Data End),
        in the one line every verb says of it ("" if the file is whole, or lost events: `missing` says what): its
        events are the session's, so no verb marks its output partial, and none is silent of it (a new user's
        trial: verify FAILed it, view, counterfactual and report said nothing); verify PASSes it when the damage
        is all after the data section (`data_intact`)."""
        if self.missing or self.lost_from >= 0:
            return ""
        if self.whole:  # whole, but for copies of events, or schemas that are not pairplay's: said all the same
            return self.said_too
        what = "damaged" if self.damage else "cut after its data section"
        said = f"the file is {what}, no event lost ({self.brief}): pairplay recover makes a whole copy"
        return "; ".join(n for n in (said, self.said_too) if n)

    @property
    def data_intact(self) -> bool:
        """Whether every damaged part is after the data section (the summary, the footer, the file's end: where no
        event is) and the data section was read to its Data End: every event is as recorded, proved by its chunk's
        and the data section's CRC. Damage inside the data section (an index, the data section's CRC, chunks moved)
        lost no event either, but bytes among the events changed: verify still FAILs it (services/verify.py)."""
        return self.data_complete and all(d.part.startswith(AFTER_DATA) for d in self.damage)

    @property
    def note(self) -> str:
        """What a verb that reads the file's intact parts lacks, in one short line ("" if the file is whole,
        every message decodes and it is no recovery of a file that lost some): "damaged: ..." or "truncated: ..."
        (`brief`), what the file it was recovered from lost (`source_lost`, `source_cut`), and `undecoded`."""
        cut = "" if self.whole else f"{'damaged' if self.damage else 'truncated'}: {self.brief}"
        return "; ".join(n for n in (cut, self.source_lost, self.source_cut, self.undecoded, self.gaps) if n)

    @property
    def lost(self) -> str:
        """What the file lost among its events, in one short line ("" if nothing): a damaged part that held
        some (said by `brief`), what the damaged file it was recovered from lost (`source_lost`: a recovered
        file is whole, its session is not) and the messages that do not decode (`undecoded`). What is made of
        such a file lacks events its session had (rebuild: refused without --partial; view: a partial view;
        report: the game left out); a damage that lost no event (a summary's CRC) is not a loss."""
        return self.lost_of()

    def lost_of(self, sources: frozenset[str] | None = None) -> str:
        """`lost`, of its holes in seqs (`gaps_of`) only those of `sources` (None: every source's): what a verb
        whose output is made of those sources' events lacks (rebuild's policy: the game's and the learner's)."""
        own = any(d.lost_at >= 0 for d in self.damage)
        return "; ".join(n for n in (self.brief if own else "", self.source_lost, self.undecoded,
                                     self.gaps_of(sources)) if n)

    @property
    def missing(self) -> str:
        """`note` when the file lacks events of its session (a damaged part that held some, a cut before its data
        section's end, a recovered file's source's losses or cut (`source_cut`), messages that do not decode:
        `lost`, `cut_lost`); ""
        when its damage lost none (an index, a summary, a cut after the Data End): such a file is whole to a verb
        that reads its events (counterfactual, view, replay said "not whole" of it, and marked their output
        partial)."""
        if not (self.lost or self.cut_lost or self.source_cut):
            return ""
        return "; ".join(n for n in (self.note, self.said_too) if n)  # (said too: `loss_free` is "" here)

    @property
    def no_session(self) -> str:
        """Why the file holds no session, in the one line every verb that reads a recording says it in ("" if it
        holds one): replay, verify, rebuild, view, counterfactual, recover (replay/check.py `read_session`) and the
        report of a study (replay/studydata.py `recording_of`). A session starts with its SessionStarted (the
        config every verb folds with), so a file without one holds no session, whatever else it holds: only MCAP's
        magic or header (a recorder that died at once), another program's MCAP, pairplay events of a session that
        never started, or a session whose start the file's damage lost. A cut loses a file's end, never its start:
        a cut file without a SessionStarted holds no session either (recover copied one and said so with exit 0,
        where every other verb refused it: a new user's trial)."""
        if any(type(r.event).__name__ == "SessionStarted" for r in self.events):
            return ""
        size = Path(self.path).stat().st_size if Path(self.path).exists() else 0
        foreign = len(self.bad) + len(self.unknown)
        stopped = self.metadata.get("pairplay.recorder.end", {}).get("stopped_by", "")
        if not self.events and not foreign and not self.skipped and not stopped:
            # in words a user has (not "MCAP's magic"): the recorder died before it wrote anything
            if size <= len(MCAP_MAGIC) + 2:
                return f"holds no session: an MCAP file with no records ({counted(size, 'byte')}): the recording holds nothing"
            cut = ", cut short" if self.truncated else ""
            return (f"holds no session: an MCAP file with no messages ({counted(size, 'byte')}{cut}): the recording "
                    "holds nothing")
        # (pairplay events on keys that name other ones are no other program's: said as damage, below)
        if not self.events and not self.skipped and foreign > sum(m.reason.startswith(DISAGREES) for m in self.bad):
            topics = sorted({topic for topic, _ in self.channels.values()})[:2]
            return (f"holds no session: not a pairplay recording ({counted(foreign, 'message')}, none a pairplay event; "
                    f"channels {', '.join(repr(t) for t in topics)})")
        # a recorder that finished its file says why it stopped, even before any event came (a signal
        # during the game's wait for its services, on a loaded machine: test_session_end)
        n = len(self.events) + sum(self.skipped.values())
        if self.damaged:  # its start may be lost to the damage (a part, a message that does not decode): no session
            # that "never started" (a new user's trial: a SessionStarted that did not decode was said so)
            return (f"holds no session: {counted(n, 'pairplay event')} but no SessionStarted in its intact parts: the "
                    f"file is damaged ({self.damaged})")
        why = f"stopped ({stopped}) before its game started" if stopped else "a session that never started"
        return f"holds no session: {counted(n, 'pairplay event')} but no SessionStarted ({why})"

    def unknown_types(self) -> dict[str, int]:
        """How many events of each type this version does not know, by tag."""
        counts: dict[str, int] = {}
        for u in self.unknown:
            counts[u.tag] = counts.get(u.tag, 0) + 1
        return counts

    def of(self, *tags: str) -> list[Event]:
        """The events with one of these tags, in order."""
        return [r.event for r in self.events if type(r.event).__name__ in tags]


@contextmanager
def gc_paused():
    """Python's cyclic GC paused for a bulk read: a read makes a few acyclic objects per
    message (records, events) and keeps them, so the collector's passes over them cost
    30-40% of a rebuild (measured); restored as it was after."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


AFTER_DATA = ("summary", "footer", "file end", "chunk index")  # mcapscan's parts after the Data End (`data_intact`)
_LOST_HERE = object()  # _read_log's marker among the records: a damaged part's lost records were here
RECOVERED = "pairplay.recovered"  # the metadata record `pairplay recover` writes (replay/recover.py)
# in it: where the damaged file's lost parts were, as the number of messages the recovered file holds before each
LOST_AT_KEY = "lost_at_messages"
DATA_COMPLETE_KEY = "data_complete"  # in it: "true" when the source's data section was read to its Data End


JOURNAL_WHOLE_KEY = "journal_whole"  # in it: "true" when its recorder's journal beside it was read to its end


def recovered_cut(recovered: dict[str, str]) -> bool:
    """Whether the file a recovered one was made from was cut before its data section's end (a cut after it,
    in the summary, lost no message), and what its cut lost is not back: one recovered before recover said so
    is taken as cut, as it was. A cut whose recorder's journal (replay/wal.py) was read to its end and gave
    back the session's end (SessionEnded) lost none of the session: the journal holds every message the
    recorder received, in order, so it holds all of them up to that end (a new user's trial: the copy
    `pairplay recover` completed from the journal was "recovered from a cut file: the events after its cut are
    lost", its policy partial, and a study game read from it had none)."""
    cut = recovered.get("truncated") == "true" and recovered.get(DATA_COMPLETE_KEY) != "true"
    return cut and not journal_restored(recovered)


def journal_restored(recovered: dict[str, str]) -> bool:
    """Whether a recovered file's recorder's journal was read to its end and the session's end is in the file:
    then what the journal added is the session's whole rest (`recovered_cut`), not a part of it."""
    return recovered.get(JOURNAL_WHOLE_KEY) == "true" and recovered.get("session_ended") == "true"


def recovered_lost(recovered: dict[str, str]) -> bool:
    """Whether the damaged file a recovered one (its RECOVERED metadata) was made from lost messages: a
    damage that lost none (an index, a CRC) left the session whole; a file recovered before recover said
    where its losses were (no LOST_AT_KEY) is taken as having lost some, as it was."""
    if recovered.get("damaged", "[]") in ("", "[]"):
        return False
    return recovered.get(LOST_AT_KEY, "") != "[]"


def said_source_lost(recovered: dict[str, str]) -> str:
    """What the damaged file a recovered one (its RECOVERED metadata) was made from lost, in one short line, as
    `Scan.brief` says a damaged file's ("" if it lost no message: `recovered_lost`)."""
    if not recovered_lost(recovered):
        return ""
    try:
        parts = [str(p) for p in json_loads(recovered.get("lost", "[]") or "[]")]
    except (ValueError, TypeError):
        parts = []
    source = Path(recovered.get("source", "")).name
    try:  # a recovered file recovered again: the files before its source (replay/recover.py `earlier`), oldest first
        earlier = [Path(str(e)).name for e in json_loads(recovered.get("earlier", "[]") or "[]") if e]
    except (ValueError, TypeError):
        earlier = []
    if source and earlier:
        source += f", itself recovered from {' and '.join(reversed(earlier))}"
    # (a restarted recorder's file records its predecessor's losses so too: services/recorder.py `earlier_losses`;
    # and a live recorder what the bus lost that no refill gave back, `bus` "true": `Recorder._note_bus_lost`)
    how = said_source_made(recovered)
    head = f"{how}{f' ({source})' if source else ''}"
    if not parts:  # recovered before recover said what each part lost
        return f"{head} whose damaged parts are lost"
    if len(parts) > 2:  # every part named was a line of thousands of characters (as Scan.brief)
        return f"{head}: {counted(len(parts), 'part')} lost, the first {parts[0]}, the last {parts[-1].split(': ')[0]}"
    return f"{head}: {'; '.join(p + ' lost' for p in parts)}"


def said_source(recovered: dict[str, str]) -> str:
    """The file a recovered one (its RECOVERED metadata) was made of, in words that fit what it is: "the recording
    it continues" (a restarted recorder's copy: services/recorder.py `earlier_losses`) or "the recording it was
    recovered from" (`pairplay recover`); verify said the latter of a continued file (a new user's trial)."""
    bus, shed, flood = (recovered.get(k) == "true" for k in ("bus", "shed", "flood"))
    if bus and not shed and not flood:  # a live recorder's own record of what the bus lost (netns)
        return "this recording on the bus (no refill gave it back)"
    if shed and not bus and not flood:  # what its recorder took off the bus and shed at the exit (a flood, or the
        return "this recording at its recorder's exit (shed, still queued when the recording stopped)"  # deadline)
    if bus or shed or flood:  # a live recorder's own record of holes, each under its cause (`Recorder._note_bus_lost`)
        causes = (["on the bus (no refill gave it back)"] * bus + ["shed by its recorder's full inbox in a flood"] * flood
                  + ["shed by its recorder at the exit"] * shed)
        return f"this recording {' or '.join(causes)}"
    return "the recording it continues" if recovered.get("continued") else "the recording it was recovered from"


def said_source_made(recovered: dict[str, str]) -> str:
    """How a recovered file was made of a damaged one, as `said_source_lost` starts: "continues a damaged
    recording", "events lost on the bus that no refill gave back" (a live recorder's, `bus` "true"), "events
    its recorder shed at the exit ..." (`shed` "true"; both, joined, when it holds both) or "recovered from a
    damaged file"."""
    if recovered.get("continued"):
        return "continues a damaged recording"
    bus, shed, flood = (recovered.get(k) == "true" for k in ("bus", "shed", "flood"))
    if bus or shed or flood:  # a live recorder's own record: what the bus lost, and what it shed itself, apart
        # (a hole its shedding left, at the exit or in a flood, was said to be the bus's, and counted twice)
        return " and ".join(["events lost on the bus that no refill gave back"] * bus
                            + ["events its recorder's full inbox shed in a flood (no refill gave them back)"] * flood
                            + ["events its recorder shed at the exit (still queued when the recording stopped)"] * shed)
    return "recovered from a damaged file"


def said_source_cut(recovered: dict[str, str]) -> str:
    """What the file a recovered one (its RECOVERED metadata) was made from lost to its cut, in one short line
    ("" if it was not cut before its data section's end: `recovered_cut`); every verb says it so."""
    if not recovered_cut(recovered):
        return ""
    source = Path(recovered.get("source", "")).name
    return f"recovered from a cut file{f' ({source})' if source else ''}: the events after its cut are lost"


# the RECOVERED record's counts that add up across the copies of a recording (`carry_recovery`): what its journal
# gave back or refused, the chunks lost, the events the bus lost and its recorder shed (services/recorder.py
# `_note_bus_lost`); `messages` and `last_round` are the newest file's own
COUNTED = ("from_journal", "journal_refused", "lost_chunks", "lost_count", "shed_count")


def carry_recovery(earlier: dict[str, str], new: dict[str, str], marks_moved: bool = True) -> dict[str, str]:
    """The RECOVERED record of a recovery, `new`, with the losses of the recovery before it (`earlier`: {} if its
    source was never recovered) carried forward (replay/recover.py's rule): the damaged parts and losses of both,
    the earlier first; a cut before the Data End stays a cut; the counts (`COUNTED`) add up; `earlier` names the
    earlier sources, oldest first. `marks_moved`: `new`'s LOST_AT_KEY holds the earlier marks already, moved into its
    count (recover); else (`folded_recovery` of a file an older recover made twice) the earlier marks before
    `new`'s first are kept (nothing the newer recovery lost came before them) and those after it are left to
    it (where they fall past a newer loss is not known; every verb stops comparing at the first). An earlier
    record that lost messages without saying where (a recover before LOST_AT_KEY) leaves none: lost, place
    unknown, as it was."""
    if not earlier:
        return new
    merged = {**earlier, **new}
    if "continued" not in new:  # (said of the newest: a recovered copy of a continued file is a recovered file)
        merged.pop("continued", None)
    for key in ("damaged", "lost"):
        merged[key] = json.dumps(listed_values(earlier.get(key)) + listed_values(new.get(key)))
    # a live recorder's own record names its own file as its source (services/recorder.py `_note_bus_lost`): carried
    # into a record of that same file (a restarted recorder's `earlier_losses`) it is no earlier copy; named as one,
    # the restarted recorder took the losses for carried already and recorded none of them
    same = Path(earlier.get("source", "")).name == Path(new.get("source", "")).name
    merged["earlier"] = json.dumps(listed_values(earlier.get("earlier")) + [earlier.get("source", "")] * (not same))
    if recovered_cut(earlier):  # an earlier cut before the Data End: its tail is lost from every copy
        merged["truncated"], merged[DATA_COMPLETE_KEY], merged[JOURNAL_WHOLE_KEY] = "true", "false", "false"
    for key in COUNTED:  # (every count of what a copy lost or took: the newest's alone forgot the earlier ones')
        if key in earlier:
            merged[key] = str(_number(earlier[key]) + _number(new.get(key, "0")))
    if not marks_moved and LOST_AT_KEY in earlier and LOST_AT_KEY in new:
        try:
            old, mine = (sorted(int(n) for n in json_loads(m[LOST_AT_KEY])) for m in (earlier, new))
        except (ValueError, TypeError):
            old, mine = [], []
        merged[LOST_AT_KEY] = json.dumps(sorted({*mine, *(n for n in old if not mine or n <= mine[0])}))
    if recovered_lost(earlier) and LOST_AT_KEY not in earlier:
        merged.pop(LOST_AT_KEY, None)
    return merged


def folded_recovery(records: list) -> dict[str, str]:
    """A file's RECOVERED metadata, every such record of it folded ({} if none): recover now writes one that
    carries every earlier recovery's losses (it has `earlier`); a file an older recover made of a recovered one
    holds the earlier record copied and its own after it, and the reader read only the newest (the earlier
    losses were forgotten): they are carried here (`carry_recovery`, marks not moved)."""
    found = [dict(r.metadata) for r in records if type(r) is Metadata and r.name == RECOVERED]
    folded: dict[str, str] = {}
    for newer in found:
        folded = newer if "earlier" in newer else carry_recovery(folded, newer, marks_moved=False)
    return folded


def listed_values(text: str | None) -> list[str]:
    try:
        value = json_loads(text or "[]")
    except ValueError:
        return [text] if text else []
    return [str(v) for v in value] if isinstance(value, list) else [str(value)]


def _number(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        return 0


def recovered_losses(records: list, own: list[tuple[int, int | None]] = (),
                     recovered: dict[str, str] | None = None) -> list[int] | None:
    """Where a file `pairplay recover` wrote lost parts of the file it was recovered from, as indexes of
    `records` (None: not such a file, or one recovered before recover said where). Its metadata record is
    written after every message but the last chunk's; every one is read (`folded_recovery`). `own`: the parts this
    file lost itself (damaged after its recovery), as (index of `records`, how many messages it held; None: not
    known): the recorded places count the messages the file held when it was written, those lost among them,
    so each lost part's messages are counted where it was (a mark inside it falls at it; a mark after a part
    whose count is not known falls at that part too: where it was past it is not known). `recovered`: the
    file's `folded_recovery`, if known."""
    recovered = folded_recovery(records) if recovered is None else recovered
    if LOST_AT_KEY not in recovered:
        return None
    try:
        wanted = sorted(int(n) for n in json_loads(recovered[LOST_AT_KEY]))
    except (ValueError, TypeError):
        return None
    lost = sorted(own)
    at, seen, found, k = 0, 0, [], 0
    for i, r in enumerate(records):
        while k < len(lost) and lost[k][0] <= i:  # a part lost before this record: its messages were here
            seen = float("inf") if lost[k][1] is None else seen + lost[k][1]
            k += 1
        while at < len(wanted) and wanted[at] <= seen:
            found.append(i)
            at += 1
        if type(r) is Message:
            seen += 1
    return found + [len(records)] * (len(wanted) - at)


def read_log(path: str | Path, only: frozenset[str] | None = None) -> EventLog:
    """Read a recording (whole, cut or damaged); see the module rule. The public API's (`pairplay.read_log`).

    `only`: decode wholly only the events with these tags (what a fold reads); any
    other known event is checked by its envelope alone (its type agrees with its
    channel, session, source and seq decode) and counted in `skipped` by tag, not
    kept (rebuild: 2/3 of a session's events are ones its fold only counts). A
    message whose envelope fails that check is decoded wholly, as without `only`,
    so it still ends up an event, an UnknownEvent or a BadMessage.
    InputError, before any reading, naming the file, if `path` is no recording at all, as every verb says it
    (replay/check.py `check_recording`: no such file, a folder, a file of nothing, not MCAP, a recorder's journal;
    ArgumentError if it is no path: pairplay/arguments.py): a text file was read as an EventLog whose `error`
    said so, a researcher's script going on with no events. What a real MCAP file holds, cut or damaged, is
    the EventLog's to say, and so is a file its recorder is writing now (pairplay/livelock.py: `live`), even
    before its first record (it is no recorder that stopped). `read_any_log` reads any file, as this did."""
    from .check import check_recording, recording_file
    path = recording_file(path, "read_log")
    if not is_live(path):
        check_recording(path, function="read_log")
    with gc_paused():
        return _read_log(path, only)


def read_any_log(path: str | Path, only: frozenset[str] | None = None) -> EventLog:
    """`read_log` (`only` as there) of a file that need not be MCAP at all: what it is not is the EventLog's to say
    (`error`, `no_session`). For code that checked the file first in its own words (replay/check.py `read_session`,
    a study folder's readers, which say a game's unreadable recording as the game's), or must take what a recorder
    left, whatever it is: recover (a file of nothing beside its journal), a server reading back the recording of a
    game that just ended, a session's summary of its own recording. InputError only if `path` names no file or a
    folder (ArgumentError if it is no path)."""
    from .check import recording_file
    path = recording_file(path, "read_log")
    with gc_paused():
        return _read_log(path, only)


def _read_log(path: str | Path, only: frozenset[str] | None = None) -> EventLog:
    log = EventLog(str(path))
    checked = scan(path)
    reading = _Reading(log, only)
    records = checked.summary_records + checked.records
    own = [(len(checked.summary_records) + at, n) for at, n in checked.losses()]
    lost = sorted({at for at, _ in own})
    # a recovered file is whole, but its source lost parts: marked where they were, as in the source (and, if it
    # lost parts itself since, counted with theirs: `recovered_losses`)
    # every recovery's losses, not the newest's alone: of the data section's Metadata records, which the scan
    # keeps apart too (a pass over every record to find them was 3% of a rebuild)
    recovered = folded_recovery(checked.metadata_records)
    lost = sorted({*lost, *(recovered_losses(records, own, recovered) or ())})
    if lost:  # a marker where each lost part's records were (`lost_at`; the first: `lost_from`)
        marked, before = [], 0
        for at in lost:
            marked += records[before:at]
            marked.append(_LOST_HERE)
            before = at
        records = marked + records[before:]
    reading.take(records, log.events)
    reading.ends(log.events)
    return reading.finish(checked, recovered)


class NotStreamed(Exception):
    """A file `stream_log` does not read as it goes (a part or a message lost, a recovered file's source's losses:
    where they were is known only at its end): read it whole (`read_any_log`)."""


def stream_log(path: str | Path, only: frozenset[str] | None, each: Callable[[list[RecordedEvent]], None]) -> EventLog:
    """`read_any_log(path, only)` of a file whose every part was read (none lost, no message that does not decode,
    no loss recorded by a recover: NotStreamed, before or after `each` was called, for any other), its events given
    to `each` a chunk's at a time, in file order, and not kept (`EventLog.events` is empty): a verb that folds them as
    they come holds one chunk's records, not the file's (rebuild: a 5,000-round file's were 600 MB, and reading
    them all first kept it under its 0.8x goal). Everything else of the EventLog is `read_any_log`'s: the summary's
    channels are taken first, as there, after the fact (they name only channels whose messages the data section's
    own Channel records name too: one they alone name is a message on an unknown channel, NotStreamed)."""
    from .check import recording_file
    from .mcapscan import LostPart, stream

    path = recording_file(path, "read_log")
    log = EventLog(str(path))
    reading = _Reading(log, only, firsts=False)

    def sink(records: list) -> None:
        events: list[RecordedEvent] = []
        reading.take(records, events)
        if log.lost_at:  # a message that does not decode, or on no channel: `lost_at` marks it among the events
            raise NotStreamed(path)
        reading.ends(events)
        reading.passed += len(events)
        if events:
            each(events)

    with gc_paused():
        try:
            checked = stream(path, sink)
        except LostPart:
            raise NotStreamed(path) from None
        recovered = folded_recovery(checked.metadata_records)
        # a seq read twice (a copy, or a differing event: `copies`, `differing`) is judged against the first bytes
        # read of it, which a stream does not keep
        if checked.losses() or recovered_losses([], (), recovered) or seq_twice(reading.route.values()):
            raise NotStreamed(path)
        if checked.summary_records:  # first, as `_read_log` reads them (the order of `channels` and of `gaps`)
            channels, schemas, route = log.channels, log.schemas, reading.route
            log.channels, log.schemas, reading.route = {}, {}, {}
            reading.take(checked.summary_records, [])
            log.channels.update(channels)
            log.schemas.update(schemas)
            reading.route.update(route)
        return reading.finish(checked, recovered)


def fold_log(path: str | Path, only: frozenset[str] | None, make: Callable[[], Callable[[list[RecordedEvent]], Any]]):
    """(the EventLog, the fold) of the recording at `path`: `make()` a fold, called with each chunk's events as they
    are read (`stream_log`; `EventLog.events` empty, none kept), so a verb that folds the log in order holds one
    chunk's records, not the file's (verify, view, report, counterfactual: a 5,000-round file's records and events
    were 1.6 GB in verify). A file `stream_log` does not read as it goes (NotStreamed: a lost part, a seq read twice)
    or that holds no SessionStarted (`EventLog.no_session` says why from its events) is read whole
    (`read_any_log(path, only)`: its events kept, `lost_at` counts them) and given to a fresh fold at once: the same
    fold either way. `only` must hold SessionStarted if it is given."""
    fold, started = make(), []

    def each(recorded: list[RecordedEvent]) -> None:
        if not started and any(type(r.event).__name__ == "SessionStarted" for r in recorded):
            started.append(True)
        fold(recorded)

    try:
        log = stream_log(path, only, each)
        if started:
            return log, fold
    except NotStreamed:
        pass
    log = read_any_log(path, only)
    fold = make()
    fold(log.events)
    return log, fold


def events_of(path: str | Path, only: frozenset[str] | None = None, tags: frozenset[str] | None = None):
    """(the EventLog, its events in file order as a list: those with `tags`, every one if None) of the recording at
    `path` (`fold_log`), which holds them alone, not the file's records and each event's bytes besides: for a verb
    that needs them at once (verify: each source's events re-sorted, a service's own outputs held back before its
    inputs are fed), or only a few of them (a study's questionnaire answers)."""
    return fold_log(path, only, lambda: _Kept(tags))


class _Kept(list):
    """`events_of`'s fold: the events with its tags (every one if None), in file order."""

    def __init__(self, tags: frozenset[str] | None) -> None:
        super().__init__()
        self.tags = tags

    def __call__(self, recorded: list[RecordedEvent]) -> None:
        tags = self.tags
        self.extend(r.event for r in recorded if tags is None or type(r.event).__name__ in tags)


def _first(at: tuple[str, str, int], data: bytes) -> bytes:
    """`_Reading.take`'s look-up of the first event read of `at` when none is kept (`stream_log`): each is the first."""
    return data


def seq_twice(routes) -> bool:
    """Whether some (session, source) has a seq read more than once among the events on `routes` (`_read_log`'s
    channels; counted by `_distinct`)."""
    import numpy as np

    for numbers in _seqs_by_source(routes).values():
        seqs = np.frombuffer(numbers, dtype=np.int64)
        if _distinct(seqs) < len(seqs):
            return True
    return False


class _Reading:
    """`_read_log`'s and `stream_log`'s one reading of records into an EventLog (module rule): `take` each batch of
    records in file order, `ends` of the events each gave, then `finish`."""

    def __init__(self, log: EventLog, only: frozenset[str] | None, firsts: bool = True) -> None:
        self.log, self.only = log, only
        # channel -> (its topic, its tag if its events are only counted, else None, and what an event on it must be:
        # the session, source and event class its topic names (None: no pairplay event key): `disagreement`; and the
        # seqs of the events read on it (`gaps`: one append per message, grouped by source once at the end)): one
        # look-up
        self.route: dict[int, tuple[str, str | None, str | None, str | None, type | None, array]] = {}
        # the first event read of each (session, source, seq): an identical one after it is a copy, read once (module
        # rule; FirstOfEach's test, inlined: a call per message was 50% more time for a read); none kept by
        # `stream_log`, which reads a file with no seq read twice (its first bytes, kept, were a third of its memory)
        self.firsts = FirstOfEach() if firsts else None
        self.passed = 0  # the events read before this batch (`lost_at` counts them)
        self.ended_by: dict[str, str] = {}  # session -> its SessionEnded's reason (`unanswered`)
        self.learned: dict[str, set] = {}  # session -> the seqs of the learner's RewardGiven that learned
        self.robots: dict[str, str] = {}  # session -> the robot its SessionStarted names ("" none: `unanswered`)
        # channel of an event that names a seq or a turn (`NAMES`, `TURNS`) -> its topic and what its events name
        # (`misnamed`, `unresolved`):
        # read by a small decoder of that field alone, whether or not the read decodes the event (rebuild's does
        # not decode SuggestionMade); kept across a channel's record again, as `route`'s seqs are
        self.names: dict[int, tuple[str, array]] = {}

    def take(self, records: list, events: list[RecordedEvent]) -> None:
        """Read `records` (file order), their events appended to `events`."""
        log, only, route, names = self.log, self.only, self.route, self.names
        skipped: dict[str, int] = log.skipped
        decode, head, type_of = _event_decoder.raw, _tagged.raw, _typed.raw  # (RecursionError caught: nesting.py)
        append = events.append
        seen = self.firsts.seen.setdefault if self.firsts is not None else _first
        for record in records:
            if type(record) is Message:  # most records (mcap's record classes have no subclasses)
                routed = route.get(record.channel_id)
                if routed is None:
                    log.bad.append(BadMessage("", f"message on unknown channel {record.channel_id}",
                                              record.log_time, record.data))
                    log.lost_at.append(self.passed + len(events))
                    continue
                key, tag, k_session, k_source, k_type, numbers = routed
                data = record.data
                naming = names.get(record.channel_id)  # (an event naming a seq: `misnamed`; its field read in
                # the same parse as its tag, or from the event decoded)
                if tag is not None:
                    try:
                        if k_source not in STARTERS:  # not read, no copy looked for (only the game's): its copies
                            # change nothing the verb makes: only its tag and seq are decoded (a copy check for each
                            # was an eighth of a rebuild, under the bench's 0.8x goal); its seq for `gaps`
                            typed = type_of(data) if naming is None else _typed_named.raw(data)
                            if typed.type == tag:  # (else decoded below: a bad message is kept as one)
                                numbers.append(typed.seq)
                                if naming is not None:
                                    naming[1].append(_named_value(tag, typed))
                                skipped[tag] = skipped.get(tag, 0) + 1
                                continue
                        h = head(data) if naming is None else _tagged_named.raw(data)
                        if h.type == tag and h.session == k_session and h.source == k_source:  # else decoded below
                            numbers.append(h.seq)
                            first = seen(((h.session, h.source, h.seq)), data)
                            if first is data:
                                if naming is not None:
                                    naming[1].append(_named_value(tag, h))
                                skipped[tag] = skipped.get(tag, 0) + 1
                                continue
                            if first == data:
                                log.copies += 1  # an identical copy of one event read: once (module rule)
                                continue
                            # (other bytes of a seq read: decoded wholly below, to compare)
                    except (msgspec.DecodeError, msgspec.ValidationError, RecursionError):
                        pass  # decoded wholly below: a bad message is kept as one
                try:
                    e = decode(data)
                    if type(e) is not k_type or e.session != k_session or e.source != k_source:
                        # changes nothing, as on the bus (services/guard.py): kept as a bad message, said
                        log.bad.append(BadMessage(key, disagreement(key, e), record.log_time, data))
                        log.lost_at.append(self.passed + len(events))
                        continue
                    numbers.append(e.seq)
                    if naming is not None:
                        naming[1].append(_named_value(k_type.__name__, e))
                    first = seen((e.session, e.source, e.seq), data)
                    if first is not data:
                        if first == data or _decoded(first) == e:
                            log.copies += 1  # an identical copy of one event read: once (module rule)
                            continue
                        log.differing += 1  # another event at a seq read: kept, for replay/forgery.py
                    append(RecordedEvent(key, e, record.log_time, data))
                except (msgspec.DecodeError, msgspec.ValidationError, RecursionError) as err:
                    if isinstance(err, RecursionError):
                        err = msgspec.DecodeError(TOO_DEEP)
                    tag = unknown_tag(record.data)
                    if tag is not None:
                        log.unknown.append(UnknownEvent(key, tag, record.log_time, record.data))
                    else:
                        log.bad.append(BadMessage(key, str(err), record.log_time, record.data))
                        log.lost_at.append(self.passed + len(events))
            elif isinstance(record, Channel):
                log.channels[record.id] = (record.topic, str(record.schema_id))
                tag = record.topic.rsplit("/", 1)[-1]
                parts = record.topic.split("/")
                named = (parts[1], parts[2]) if len(parts) == 4 and parts[0] == KEY_ROOT else (None, None)
                # a channel's record again (the summary's copy, a writer that repeats it in every chunk, as MCAP lets
                # it) keeps the seqs read on it: new ones, a chunk's seqs dropped, were holes its other channels' seqs
                # surrounded
                known = route.get(record.id)
                numbers = known[5] if known is not None and known[0] == record.topic else array("q")
                route[record.id] = (record.topic, tag if only is not None and tag in EVENT_BY_TAG and tag not in only
                                    else None, *named, EVENT_BY_TAG.get(tag) if named[0] is not None else None, numbers)
                if (named[1], tag) in NAMES or (named[1], tag) in TURNS:
                    had = names.get(record.id)
                    names[record.id] = (record.topic, had[1] if had is not None and had[0] == record.topic
                                        else array("q"))
            elif isinstance(record, Schema):
                log.schemas[record.id] = (record.name, record.encoding, record.data)
            elif isinstance(record, Metadata):
                log.metadata[record.name] = dict(record.metadata)
            elif record is _LOST_HERE:
                log.lost_at.append(self.passed + len(events))
                if log.lost_from < 0:
                    log.lost_from = self.passed + len(events)

    def ends(self, events: list[RecordedEvent]) -> None:
        """Note each session's end, its robot and the learner's RewardGiven that learned among `events`
        (`unanswered`)."""
        ended_by, learned = self.ended_by, self.learned
        for r in events:
            kind = type(r.event)
            if kind is SessionEnded:
                ended_by[r.event.session] = r.event.reason
            elif kind is SessionStarted:
                self.robots[r.event.session] = r.event.config.robot
            elif kind is RewardGiven and r.event.learned and r.event.source == "learner":
                learned.setdefault(r.event.session, set()).add(r.event.seq)

    def finish(self, checked, recovered: dict[str, str]) -> EventLog:
        """The EventLog, after its last records: what the scan found, the holes in seqs, what is unanswered."""
        log, path = self.log, self.log.path
        route, skipped = self.route, log.skipped
        log.truncated, log.damage, log.data_complete = checked.truncated, checked.damage, checked.data_complete
        log.seq_jumps, log.repeated = seq_jumps(route.values())
        # (RewardGiven decoded, not skipped: whether each learned is known)
        learned = self.learned if "RewardGiven" not in skipped else None
        # (SessionStarted decoded, not skipped: whether its robot is known)
        robots = self.robots if "SessionStarted" not in skipped else None
        log.unanswered = unanswered(route.values(), self.ended_by, learned, robots) + \
            misnamed(route, self.names, self.ended_by) + unresolved(route, self.names, self.ended_by)
        if recovered:
            log.metadata[RECOVERED] = recovered
        log.source_lost = said_source_lost(log.metadata.get(RECOVERED, {}))
        log.error = "" if checked.whole else checked.describe()
        log.brief = "" if checked.whole else checked.brief()
        if log.truncated and is_live(path):  # not cut: its recorder is still writing it (pairplay/livelock.py)
            log.live = True
            log.error = f"{LIVE}, read as far as it goes; {log.error}"
            log.brief = f"{LIVE}, read as far as it goes; {log.brief}"
        return log


class FirstOfEach:
    """The first event read of each (session, source, seq) (module rule): an identical one after it is a copy (a
    file whose every message was stored twice, a chunk written again: read once, counted); one that differs is
    kept, for replay/forgery.py to judge (a contradiction). The reader's and recover's (which copies no copy)."""

    def __init__(self) -> None:
        self.seen: dict[tuple[str, str, int], bytes] = {}  # -> the bytes of the first event read of it

    def copy(self, at: tuple[str, str, int], data: bytes, event: Event | None = None) -> bool | None:
        """Whether `data` (decoded: `event`) is a copy of the first event read of `at`: None if it is the first,
        True if the same bytes or (decoded) an equal event (another encoder's spacing: forgery.py's test),
        False if it differs (or is not decoded yet and its bytes differ)."""
        first = self.seen.setdefault(at, data)
        if first is data:
            return None
        if first == data:
            return True
        return event is not None and _decoded(first) == event

    def copy_of(self, data: bytes) -> bool:
        """Whether the message `data` is a copy of an event read before (False for one that does not decode: a
        bad message is evidence, kept)."""
        try:
            head = _tagged.decode(data)
        except (msgspec.DecodeError, msgspec.ValidationError):
            return False
        at = (head.session, head.source, head.seq)
        same = self.copy(at, data)
        return bool(same) or (same is False and self.copy(at, data, _decoded(data)) is True)


def not_pairplays(tag: str, schema: tuple[str, str, bytes] | None) -> str:
    """Why `schema` (name, encoding, data) is not pairplay's schema of event `tag` ("" if it is: see
    `EventLog.foreign_schemas`)."""
    if schema is None:
        return "no schema"
    name, encoding, data = schema
    if name != tag or encoding != "jsonschema":
        return f"named {name!r} ({encoding})"
    try:  # (nesting's: a hostile file's schema nested deep is no RecursionError)
        text = json_loads(data)
    except (ValueError, UnicodeDecodeError):
        return "not JSON"
    if not isinstance(text, dict) or text.get("title") != tag or text.get("type") != "object":
        return "not the JSON Schema of its event"
    return ""


def disagreement(key: str, e: Event) -> str:
    """Why event `e` on a channel whose topic is `key` is not the event its key names ("" if it is):
    the key `pairplay/<session>/<source>/<tag>` names its session, source and type, as on the bus, where a guard
    refuses a message whose key disagrees with its envelope (services/guard.py); in a file it was accepted, read as
    its payload said (a copy whose every topic named another session: rebuild, verify, view said nothing of it: a
    hostile user's trial)."""
    parts = tuple(key.split("/"))
    said = (type(e).__name__, e.session, e.source)
    if parts == (KEY_ROOT, said[1], said[2], said[0]):
        return ""
    if len(parts) != 4 or parts[0] != KEY_ROOT:
        return f"{DISAGREES}, no pairplay event key"
    named = (parts[3], parts[1], parts[2])
    what = next(i for i in range(3) if named[i] != said[i])
    return (f"{DISAGREES}: it names {('type', 'session', 'source')[what]} {named[what]!r}, its payload "
            f"{said[what]!r}")


DISAGREES = "its key disagrees with its payload"  # how `disagreement` starts (`EventLog.undecoded` counts them apart)


# the sources whose seq 1 (their ServiceStarted) every recording of their session holds: the game's, the
# learner's, the participant's and the robot's, one process each, recorded from their start (services/session.py,
# the protocol's games, a restart resumes the numbering: services/runner.py; `replay --as` publishes the recorded
# seqs; one started before the recorder listened is asked for its first events: services/recorder.py
# `_catch_up`). Not the board's: every lab page and a protocol's scripted player publish as it, and a pilot's
# scripted player's ServiceStarted, its seq 1, is published as its Node starts, before run_session starts the
# recorder (services/protocol.py `_play`: a pilot's recordings start the board at 2, test_copies); nor the
# experimenter's console's (one for many games)
FROM_ONE = STARTERS | {"learner", "participant", "robot"}


def seq_jumps(routes) -> tuple[list[tuple[str, int, int]], list[tuple[str, int]]]:
    """Where each (session, source)'s seqs, sorted, skip numbers: (source, seq before, seq after), by source in the
    order its first channel came, then by seq; a first seq past 1 of a source of `FROM_ONE` is a jump from -1. And
    the seqs before such a jump held by more than one event (source, seq): a seq repeated, the next one renumbered,
    not lost. `routes`: `_read_log`'s channels (topic, tag, session, source, class, the seqs read on it: an array of
    int64, as Seq bounds them); a channel of no pairplay key holds none. Marked in a table of the source's span, not
    sorted (a set of a 5,000-round session's seqs was 4% of its rebuild); a span far wider than the seqs (a forged
    seq 2^53) is sorted instead."""
    import numpy as np  # (here: a read that meets no seq needs none)

    jumps, repeated = [], []
    for (_, source), numbers in _seqs_by_source(routes).items():
        seqs = np.frombuffer(numbers, dtype=np.int64)
        low, high = int(seqs.min()), int(seqs.max())
        if high - low < 4 * len(seqs):
            held = np.zeros(high - low + 1, dtype=bool)
            held[seqs - low] = True
            if held.all() and low <= 1:
                continue  # every number from the first to the last: no gap
            ordered = np.flatnonzero(held) + low
        else:
            ordered = np.unique(seqs)
        at = np.flatnonzero(np.diff(ordered) > 1)
        if low > 1 and source in FROM_ONE:  # its seq starts at 1, resumed after a restart: a hole at the start
            jumps.append((source, -1, int(ordered[0])))  # (-1: its start; a seq 0 read is a jump from 0)
        found = [(source, int(ordered[i]), int(ordered[i + 1])) for i in at]
        if found:  # (only then: counting every source's seqs was a cost for nothing)
            values, times = np.unique(seqs, return_counts=True)
            twice = set(values[times > 1].tolist())
            repeated += [(source, before) for _, before, _ in found if before in twice]
        jumps += found
    return jumps, repeated


def _seqs_by_source(routes) -> dict[tuple[str, str], array]:
    """The seqs read on `routes` (`_read_log`'s channels) by (session, source), in the order their first channel
    came."""
    by: dict[tuple[str, str], array] = {}
    for _, _, session, source, _, numbers in routes:
        if numbers:
            by.setdefault((session, source), array("q")).extend(numbers)
    return by


# what a source answers one for one in a session that ran to its end (services/learner.py, services/game.py):
# every game's SuggestionRequested by the learner's SuggestionMade (its request_seq), every SuggestionMade by the
# learner's RewardGiven that settles it (not every TurnResolved: a turn resolved with no suggestion, under "gaze",
# has none), every pick (the participant's, or a board's) by the game's CardRevealed or PickRejected naming it
# (its pick_seq; not its MessageRejected: one of a malformed pick names no pick recorded). Seq cannot see a source's
# tail (its last events dropped: no number after them) nor an event cut and the rest renumbered; these pairs can,
# both ways: fewer answers than asks are the answerer's events missing, more answers than asks the asker's (a new
# user's trials: the learner's last Q update dropped, rebuild wrote a whole, wrong policy, exit 0; the participant's
# last pick, or every one of its events, dropped: no verb said it; a game's request cut and renumbered:
# counterfactual fitted fewer picks silently). (asking sources, what they ask, answering sources, what answers, its
# refusal if any)
ANSWERED = ((("game",), "SuggestionRequested", ("learner",), "SuggestionMade", ()),
            (("learner",), "SuggestionMade", ("learner",), "RewardGiven", ()),
            (("participant", "board"), "CardPicked", ("game",), "CardRevealed",
             ("PickRejected",)))
UPDATES = ("QUpdated", "LSPIUpdated")  # what follows each learner's RewardGiven that learned (`unanswered`)
# in a session with a robot (its ServiceStarted or a RobotActed in the file), the robot's RobotActed for each
# learner's SuggestionMade (services/robot/bridge.py: superseded ones too), unless the recorder's MessageRejected
# count the ones it never had (services/recorder.py `_unreported_suggestions`, a shed: said there already)
ROBOT = (("robot", "ServiceStarted"), ("robot", "RobotActed"), ("learner", "SuggestionMade"),
         ("recorder", "MessageRejected"))


def unanswered(routes, ended_by: dict[str, str], learned: dict[str, set] | None = None,
               robots: dict[str, str] | None = None) -> list[tuple[str, str]]:
    """The pairs of `ANSWERED` whose answers are fewer, or more, than what they answer: (the source whose events are
    missing, the clause saying at least how many of what kind, and what shows it: `_missing`), counted from the distinct seqs read on each channel (`_read_log`'s
    routes; an identical copy counts once), per session. A session that did not complete (`ended_by`: its
    SessionEnded's reason by session: a signal, an abort; none recorded) may end between a request and its answer:
    one unanswered there is its end, not a loss, and so is one answer whose ask the file's order put past its end
    (the recorder takes two publishers' events in the order they reach it). `learned`: by session,
    the seqs of the learner's RewardGiven that learned, each followed by its update (QUpdated or LSPIUpdated:
    services/learner.py `_reward`; its last Q update dropped alone), None if the read did not decode them. `robots`: by
    session, the robot its SessionStarted names (SessionConfig.robot), None if not decoded: one named while no event
    of 'robot' is read and the learner made suggestions is "the robot sent nothing" (its RobotActed are counted only
    when it sent some: a file without any was said by no verb, trial33 E's robot). Said by
    kind, with no "last": a count cannot tell where (an event cut from the middle and the rest renumbered is counted
    the same: "the last events of 'learner' missing" placed a cut of round 2 of 6 at the end: trial33 G)."""
    import numpy as np

    paired = {("learner", tag) for tag in UPDATES} | set(ROBOT)
    for askers, asked, answerers, answer, refusal in ANSWERED:
        paired |= {(s, asked) for s in askers} | {(s, t) for s in answerers for t in (answer, *refusal)}
    seqs: dict[tuple[str, str, str], list] = {}  # (session, source, tag) -> the seqs read on its channels
    for _, _, session, source, kind, numbers in routes:
        if numbers and kind is not None and (source, kind.__name__) in paired:  # (only these: speed)
            seqs.setdefault((session, source, kind.__name__), []).append(np.frombuffer(numbers, dtype=np.int64))
    count = {at: _distinct(np.concatenate(held)) for at, held in seqs.items()}
    robot_sent = {session for _, _, session, source, _, numbers in routes if source == "robot" and numbers}
    out = []
    for session in sorted({at[0] for at in count}):
        def n(sources, *tags):
            return sum(count.get((session, s, t), 0) for s in sources for t in tags)
        slack = 0 if ended_by.get(session) == "completed" else 1
        for askers, asked, answerers, answer, refusal in ANSWERED:
            n_asked, n_answered, refused = n(askers, asked), n(answerers, answer), n(answerers, *refusal)
            answers = f"{n_answered} {answer}{f' and {refused} {refusal[0]}' if refused else ''}"
            if n_asked and n_answered + refused + slack < n_asked:  # asks unanswered: the answerer's missing
                whom = " or ".join(repr(s) for s in askers if n((s,), asked))
                out.append(_missing(answerers[0], n_asked - n_answered - refused, " or ".join((answer, *refusal)),
                                    f"{answers if refused else n_answered} for the {n_asked} {asked} of {whom}"))
            elif n_answered + refused > n_asked + slack:  # answers to no ask: the asker's missing (a file cut or a
                # session stopped may end between an ask and its answer in the file's order too: the recorder took
                # the game's CardRevealed before the board's CardPicked it answers, and the cut fell between; a full
                # CI run called such a cut file "damaged: 1 CardPicked of 'board' missing")
                out.append(_missing(_asker(askers, n_asked, refused, lambda s: n((s,), asked)),
                                    n_answered + refused - n_asked, asked,
                                    f"the {answers} of {answerers[0]!r} answer {n_asked}"))
        made, acted, starts = n(("learner",), "SuggestionMade"), n(("robot",), "RobotActed"), n(("robot",), "ServiceStarted")
        robot = (robots or {}).get(session, "")
        if robot and made and session not in robot_sent:  # (a robot sends its ServiceStarted before the game starts)
            out.append(("robot", f"the robot sent nothing: no event of 'robot' in a session started with robot "
                                 f"{robot!r}, for the {made} SuggestionMade of 'learner'"))
        # (only in a session that completed: a cut or a signal's end falls among the robot's acts, which lag; and
        # by a robot that started once: one killed and restarted never acted on what was suggested while it was
        # down, and sent nothing for it: test_faults_restart's robot case)
        if starts + acted and starts <= 1 and not n(("recorder",), "MessageRejected") and not slack \
                and acted < made:
            out.append(_missing("robot", made - acted, "RobotActed", f"{acted} for the {made} SuggestionMade of 'learner'"))
        n_learned = len((learned or {}).get(session, ()))
        updates = {tag: count.get((session, "learner", tag), 0) for tag in UPDATES}
        if n_learned > sum(updates.values()) + slack:
            tag = max(updates, key=updates.get)
            out.append(_missing("learner", n_learned - sum(updates.values()), tag,
                                f"{updates[tag]} for the {n_learned} RewardGiven that learned"))
    return out


def _missing(source: str, n: int, what: str, shows: str) -> tuple[str, str]:
    """`unanswered`'s finding: `n` events of kind `what` of `source` missing, `shows` saying how it is known
    ("1 QUpdated of 'learner' missing (9 for the 10 RewardGiven that learned)"): what is missing by its kind
    and count, never "the last events": a count cannot tell where they were."""
    return source, f"{counted(n, what, what)} of {source!r} missing ({shows})"


# the events that name another source's event by its seq, and what they name (services/learner.py: a SuggestionMade's
# request_seq is the game's SuggestionRequested it answers; services/game.py: a CardRevealed's or PickRejected's
# pick_seq the CardPicked it answers, the participant's or a board's): (source, tag) -> the sources named and the
# kind of event each named seq must hold. An event cut from the named source and its later seqs renumbered leaves no
# hole and, with a matching cut elsewhere or an event of another kind, no count unpaired (a game's TurnResolved cut:
# rebuild, recover and counterfactual said nothing, counterfactual fitted fewer picks: trial33 G), but the seqs named
# after it move off their events
NAMES = {("learner", "SuggestionMade"): (("game",), "SuggestionRequested", "request_seq"),
         ("game", "CardRevealed"): (("participant", "board"), "CardPicked", "pick_seq"),
         ("game", "PickRejected"): (("participant", "board"), "CardPicked", "pick_seq")}


# a learner's RewardGiven settles a suggestion of a turn the game resolves (services/learner.py: on its TurnResolved,
# or at a press of the wrong-suggestion button within it): every turn one settles has the game's TurnResolved in a
# session that completed. Seen by round and turn, as neither names the other's seq: a TurnResolved cut and the
# game's later seqs renumbered after the last request (which no request_seq shows)
TURNS = {("learner", "RewardGiven"): ("game", "TurnResolved"), ("game", "TurnResolved"): None}


def unresolved(route: dict, names: dict[int, tuple[str, array]], ended_by: dict[str, str]) -> list[tuple[str, str]]:
    """The sessions whose learner settled turns (`TURNS`) the game resolved none of: ("game", the clause), one a
    session. Past the last turn resolved in a session that did not complete is its end (an abort leaves a suggestion
    unsettled, its RewardGiven said so), not counted."""
    import numpy as np

    turns: dict[tuple[str, str], list] = {}  # (session, tag) -> the turns its events name
    for channel, (topic, numbers) in names.items():
        routed = route.get(channel)
        if routed is not None and routed[0] == topic and numbers and (routed[3], routed[4].__name__) in TURNS:
            turns.setdefault((routed[2], routed[4].__name__), []).append(np.frombuffer(numbers, dtype=np.int64))
    out = []
    for (session, tag), held in turns.items():
        if tag != "RewardGiven" or (session, "TurnResolved") not in turns:
            continue  # (no TurnResolved at all: a session that stopped in its first turn, or the seqs say it)
        settled = np.unique(np.concatenate(held))
        resolved = np.unique(np.concatenate(turns[(session, "TurnResolved")]))
        off = settled[~np.isin(settled, resolved)]
        if ended_by.get(session) != "completed":
            off = off[off < resolved.max()]
        if off.size:
            first = int(off[0])
            turn = f"round {(first >> 32) + 1} turn {(first & 0xFFFFFFFF) + 1}"
            out.append(("game", f"{counted(off.size, 'TurnResolved', 'TurnResolved')} of 'game' missing ("
                                + (f"a RewardGiven of 'learner' settles {turn}, which no TurnResolved resolves)"
                                   if off.size == 1 else f"RewardGiven of 'learner' settle {counted(off.size, 'turn')} no "
                                   f"TurnResolved resolves, the first {turn})")))
    return out


def misnamed(route: dict, names: dict[int, tuple[str, array]], ended_by: dict[str, str]) -> list[tuple[str, str]]:
    """The sources whose seqs, as other sources' events name them (`NAMES`), hold no event of the kind named:
    (the source, the clause saying so), one a source and session. `route`: `_Reading.route` (channel id -> topic,
    tag, session, source, class, seqs read); `names`: `_Reading.names`. A seq named past the last of its kind in a
    session that did not complete is its end (the recording stopped before the event named was written), not
    counted; a 0 names nothing (a recording from before the field)."""
    import numpy as np

    held: dict[tuple[str, str, str], list] = {}  # (session, source, tag) -> the seqs read on its channels
    named: dict[tuple[str, tuple, str, str], list] = {}  # (session, sources named, tag named, field) -> seqs named
    by: dict[tuple[str, tuple, str, str], set] = {}  # the same -> the tags naming them
    for channel, (topic, numbers) in names.items():
        routed = route.get(channel)
        if routed is None or routed[0] != topic or not numbers or (routed[3], routed[4].__name__) not in NAMES:
            continue
        _, _, session, source, kind, _ = routed
        sources, tag, name = NAMES[(source, kind.__name__)]
        named.setdefault((session, sources, tag, name), []).append(np.frombuffer(numbers, dtype=np.int64))
        by.setdefault((session, sources, tag, name), set()).add((source, kind.__name__))
    if not named:
        return []
    for _, _, session, source, kind, numbers in route.values():
        if numbers and kind is not None:
            held.setdefault((session, source, kind.__name__), []).append(np.frombuffer(numbers, dtype=np.int64))
    out = []
    for (session, sources, tag, name), seqs in named.items():
        seqs = np.unique(np.concatenate(seqs))
        seqs = seqs[seqs > 0]
        targets = [np.concatenate(held[(session, s, tag)]) for s in sources if (session, s, tag) in held]
        target = np.unique(np.concatenate(targets)) if targets else seqs[:0]
        if not seqs.size or seqs.size > target.size:
            continue  # nothing named, or more named than held: the counts say it (`unanswered`)
        off = seqs[~np.isin(seqs, target)]
        if ended_by.get(session) != "completed":
            off = off[off < target.max()]  # (past the last one read: the recording's end, not a renumbering)
        if off.size:
            whose = next((s for s in sources if (session, s, tag) in held), sources[0])
            naming = sorted(by[(session, sources, tag, name)])
            of = " or ".join(t for _, t in naming) + f" of {naming[0][0]!r}"  # (one source names each kind)
            out.append((whose, f"{whose!r}: its seqs renumbered (an event cut or added): the {name} of {off.size} {of}"
                               f" {'names' if off.size == 1 else 'name'} no {tag} (the first: {int(off[0])})"))
    return out


def _distinct(seqs) -> int:
    """How many distinct numbers `seqs` (an int64 array) holds: marked in a table of its span, as `seq_jumps` does
    (a sort of a 5,000-round session's picks was 3% of its rebuild), sorted if the span is far wider."""
    import numpy as np

    low, high = int(seqs.min()), int(seqs.max())
    if high - low >= 4 * len(seqs):
        return len(np.unique(seqs))
    held = np.zeros(high - low + 1, dtype=bool)
    held[seqs - low] = True
    return int(np.count_nonzero(held))


def _asker(askers: tuple[str, ...], n_asked: int, refused: int, asks) -> str:
    """Whose asks are missing among `askers` (`unanswered`): the first (the participant), unless it asked none and
    another's asks were more than the refusals (`refused`): a pilot's scripted player picks as the board; a board's
    stray pick refused (a lab page's touch) makes no player of it."""
    if asks(askers[0]) or n_asked <= refused:
        return askers[0]
    return max(askers, key=asks)


def _decoded(data: bytes) -> Event | None:
    """`data` decoded (None if it does not decode): the first event of a seq, kept as bytes, to compare."""
    try:
        return decode_event(data)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None


def read_events(path: str | Path) -> list[Event]:
    """Just the decoded events of a recording, in file order."""
    return [r.event for r in read_log(path).events]


class EventDecoderFactory(DecoderFactory):
    """msgspec decoding of pairplay JSON channels for mcap's readers
    (`make_reader(f, decoder_factories=[EventDecoderFactory()])`)."""

    def decoder_for(self, message_encoding: str, schema: Optional[Schema]) -> Optional[Callable[[bytes], Any]]:
        if message_encoding == "json" and schema is not None and schema.encoding == "jsonschema":
            return decode_event
        return None
