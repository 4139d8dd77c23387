"""Completing a recording cut short by a crash or damaged on disk (`pairplay recover`).

Rule: every record of every intact part of the file (`mcapscan.scan`: the
parts that pass the MCAP format's checks, including the chunks after a damaged
one) is copied, in order, into a new file that is then finished with a summary,
an index and CRCs, so any MCAP reader opens it. Nothing is invented: a lost
tail or a damaged chunk stays lost, and a "pairplay.recovered" metadata record
says what recover completed (the summary and index it wrote), what it read,
from where, what was wrong (every damaged part, the cut), where each damaged
part's lost messages were (`lost_at`: how many messages the new file holds
before each; the reader marks a loss there, as it does in the damaged file, so
`replay --verify` compares up to the first, where it printed every event after
a lost one as DIFFERS, and a damage that lost no message is no loss), whether the data
section was read to its Data End (`data_complete`: a cut after it, in the summary, lost no
message, so the copy is not a partial session) and how far the
session got (whether its SessionEnded survived, the last round). A source that is
itself a recovered file (recovered, then damaged again) carries its own
"pairplay.recovered" record: its losses are carried forward into the one new
record, never dropped (a second recovery wrote only its own, and the reader
reads the newest: the twice-recovered file was "whole"): `lost_at` holds the
source's marked losses too, moved to where they fall in the new file, `damaged`
and `lost` list the earlier parts first, a cut of an earlier source before its
Data End stays a cut, the journal counts add up, and `earlier` names the
earlier sources (oldest first): reader.carry_recovery. The old record is not
copied (its `lost_at` counts messages of the source, not of the new file); a
file an older recover made twice holds both, and the reader folds them
(reader.folded_recovery). Every tool that copies a
recording's messages into a new MCAP keeps its metadata so (tools/verify_soak.py
copies every record). A whole file
(complete already) is not copied: nothing is written unless something is
recovered (`Recovered.complete`, output None), as when its journal holds
nothing it lacks; before, a complete file was copied to <stem>.recovered.mcap, a second
file of the same events. The original is never modified.

A recorder that did not finish its file leaves its write-ahead journal beside
it (`<recording>.journal`, replay/wal.py): what it received, durable within
5 ms of receipt. Given an `admit` (the live checks: services/walmerge.py; the
`recover` verb gives it), recover reads the journal up to its end or its torn
tail and adds, after the file's records, what `admit` decides the file lacks
(the events, and the refusals of what the live recorder would have refused),
counted in the "pairplay.recovered" metadata (`from_journal`, `journal_refused`,
`journal_torn`). A journal of another session is refused (InputError); an
unreadable one is named and left out, never a traceback.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from typing import Callable

from pairplay.errors import InputError, OutputError, command_word
from pairplay.numbers import counted
from pairplay.replay.reader import (DATA_COMPLETE_KEY, JOURNAL_WHOLE_KEY, LOST_AT_KEY, RECOVERED, carry_recovery,
                                    folded_recovery, not_pairplays, recovered_losses, said_source_cut,
                                    said_source_lost)
from pairplay.schemas.events import EVENT_BY_TAG
from pairplay.schemas.jsonschema import schema_text
from pairplay.schemas.keys import parse_event_key
from pairplay.outputs import check_output, output_file

from pairplay.arguments import flag_argument, path_argument

from .check import check_recording
from .continued import continued_in
from .mcapscan import scan
from .reader import FirstOfEach, read_any_log
from .wal import RECORDER_METADATA, NotAJournal, not_its, read_journal, wal_path
from .writer import CHUNK_SIZE, PROFILE
from pairplay.schemas.nesting import json_loads


@dataclass
class Recovered:
    output: Path | None  # None: nothing written (`complete`, or asked not to `write`)
    messages: int
    truncated: bool
    reason: str  # "" when the input was whole
    damaged: list[str] = field(default_factory=list)  # the parts not copied, and why
    ended: bool = False  # the session's SessionEnded was among the records kept
    last_round: int = -1
    journal: Path | None = None  # the journal read beside it, if any
    from_journal: int = 0  # events added from it
    journal_refused: int = 0  # records of it refused by the live checks (recorded as refusals)
    journal_torn: str = ""  # where the journal stops short of a frame's end ("" if it does not)
    journal_error: str = ""  # a journal beside it that could not be read at all: why (its records are not used)
    not_its_journal: str = ""  # a journal beside a whole file that is another recording's: why (NotItsJournal)
    journal_present: int = 0  # records of the journal the file holds already
    complete: bool = False  # the file is whole and its journal (if any) holds nothing it lacks: nothing written
    lost: list[str] = field(default_factory=list)  # each damaged part that lost messages, and what: "chunk 7 (...): its 18 messages"
    lost_messages: int | None = 0  # how many messages those parts held (None: not known, unreadable bytes' records)
    earlier_lost: str = ""  # what the source's own source lost, carried forward (a recovered file recovered again)
    earlier_cut: str = ""  # what the source's own source lost to its cut (reader.said_source_cut), likewise
    copies: int = 0  # identical copies of events in the source, not copied (reader.FirstOfEach)
    # events missing from a source's seq in a file that lost no part (reader.EventLog.gaps): not in the file, nor in
    # any copy of it; said (a hole in the learner's seq was "complete already", no word: trial29 F10)
    gaps: str = ""
    schemas_left_out: str = ""  # the source's schemas that are not pairplay's, not copied (`_PairplaySchemas`)


def default_output(path: Path) -> Path:
    return path.with_name(path.stem + ".recovered.mcap")


class NoSession(InputError):
    """`recover`'s refusal of a recording that holds no session (no SessionStarted in the file, none its journal
    adds): what a verb cut before its session started leaves, nothing to recover (cli/session.py `cut_line` says
    so, not "pairplay recover completes it")."""


class NotItsJournal(InputError):
    """The journal beside a recording is of another recording of its session id (its header's
    `recording_started_ns` is not the file's started_ns, replay/wal.py): what a cut `session --force` over the
    file left when the user gave the earlier file its name back. None of its records are the file's: a whole
    file is complete, and said so with the journal named (recover took it and wrote a copy: a new user's
    trial); a cut one is refused."""


def recover(path: str | Path, output: str | Path | None = None, force: bool = False,
            admit: Callable | None = None, write: bool = True) -> Recovered:
    """Copy the intact records of `path` into a complete file (see rule), and with `admit`
    (services/walmerge.admit) what its journal holds that the file lacks; nothing when the file is
    `complete` already (output None); with `write` False, only what it would do (output None).

    InputError if `path` is not an MCAP file at all (missing, empty, no MCAP magic: unless, with
    `admit`, its journal is beside it, as a recorder killed before its first flush leaves it) or would
    write no session (reader.EventLog.no_session: no SessionStarted in it, none its journal adds), or if
    its journal is of another session;
    OutputError if `output` is the input, or exists (unless `force`) when there is something to
    write; the output appears only when complete (pairplay.outputs)."""
    path = check_recording(path, journal_ok=admit is not None, function="recover")  # (a file of nothing: its journal holds it)
    output = path_argument(output, "recover", "output") if output is not None else default_output(path)
    force, write = flag_argument(force, "recover", "force"), flag_argument(write, "recover", "write")
    if output.resolve() == path.resolve():
        raise OutputError("recover writes a new file; give an output path other than the input", output)
    # read whole, not as it comes: the copy starts with the summary's Schemas and Channels (read after the data),
    # marks each lost part where its records were (known at the file's end), copies an event once (every first
    # kept) and, before anything is written, decides whether there is anything to write (`complete`) and what the
    # journal adds (against every message the file holds); a file that lost nothing is not copied at all
    log = read_any_log(path)
    checked = scan(path)
    try:
        journal, journal_error = _journal_beside(path, log) if admit is not None else (None, "")
        not_its = ""
    except NotItsJournal as err:
        if not checked.whole:
            raise
        journal, journal_error, not_its = None, "", err.what
    added = None
    if journal is not None:  # what the journal holds that the file lacks, decided before anything is written
        added = admit(journal.session, _recorded(checked), journal.records)
    # what it would write holds no session (no SessionStarted in the file, none its journal adds): refused in the
    # reader's words, as every verb refuses such a file (reader.EventLog.no_session); a cut or damaged one was
    # copied, exit 0, a file no verb takes (a new user's trial: "recover" 0, "replay --verify" 2 of one file)
    if log.no_session and not (added is not None and any(key.rsplit("/", 1)[-1] == "SessionStarted"
                                                          for key, *_ in added.items)):
        raise NoSession(log.no_session, path)
    # and nothing more to add, and no identical copies of events in it (a copy has none: reader.FirstOfEach)
    complete = checked.whole and not (added is not None and added.items) and not log.copies
    # the source's own recovery record, if it was recovered before: its losses are carried forward (module rule)
    earlier = folded_recovery(checked.records)
    lost_parts = [f"{d.part}: {d.lost}" for d in checked.damage if d.lost_at >= 0]
    lost_words = dict(lost=lost_parts, lost_messages=_lost_count(checked), earlier_lost=said_source_lost(earlier),
                      earlier_cut=said_source_cut(earlier), gaps=log.gaps)
    if complete or not write:
        return Recovered(None, sum(isinstance(r, Message) for r in checked.records), checked.truncated,
                         "" if checked.whole else checked.describe(), [str(d) for d in checked.damage],
                         ended=any(type(r.event).__name__ == "SessionEnded" for r in log.events),
                         journal=journal.path if journal is not None else None,
                         from_journal=added.taken if added else 0, journal_refused=added.refused if added else 0,
                         journal_present=added.present if added is not None else 0,
                         journal_torn=journal.torn if journal is not None else "", journal_error=journal_error,
                         complete=complete, not_its_journal=not_its, **lost_words)
    check_output(output, force)  # only an output that will be written (a complete file writes none)
    messages, ended, last_round, copies = 0, False, -1, 0
    firsts = FirstOfEach()
    sources: dict[int, Schema] = {}  # the source's Schema records, by id
    channel_ids: dict[int, int] = {}
    topics: dict[int, str] = {}
    with output_file(output, "wb", force) as out:
        writer = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD, enable_data_crcs=True)
        writer.start(profile=PROFILE, library="pairplay recover")
        schemas = _PairplaySchemas(writer)
        # the summary's Schemas and Channels first: they name the channels of messages whose own
        # records were in a lost chunk
        # where each damaged part's lost records were, as the number of messages written before them: the
        # reader marks a loss there (replay/reader.py LOST_AT_KEY), as in the damaged file, so `replay --verify`
        # stops comparing at the first and `rebuild` flags the rounds around each
        # and where the source's own source lost parts, if it is a recovered file (module rule)
        losses = sorted({len(checked.summary_records) + d.lost_at for d in checked.damage if d.lost_at >= 0}
                        | set(recovered_losses(checked.summary_records + checked.records,
                                               [(len(checked.summary_records) + at, n) for at, n in checked.losses()])
                              or ()))
        lost_at: list[int] = []
        for at, record in enumerate(checked.summary_records + checked.records):
            while losses and at >= losses[0]:
                lost_at.append(messages)
                losses.pop(0)
            if isinstance(record, Schema):
                sources.setdefault(record.id, record)  # written only with a channel it is pairplay's schema of
            elif isinstance(record, Channel):
                if record.id not in channel_ids:
                    channel_ids[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schemas.of(record, sources.get(record.schema_id)),
                        dict(record.metadata))
                    topics[record.id] = record.topic
            elif isinstance(record, Message):
                if firsts.copy_of(record.data):  # an identical copy of an event written: not copied again
                    copies += 1
                    continue
                if record.channel_id in channel_ids:
                    writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    messages += 1
                    tag = topics[record.channel_id].rsplit("/", 1)[-1]
                    ended |= tag == "SessionEnded"
                    if tag == "RoundStarted":
                        last_round = max(last_round, _round_of(record.data))
            elif isinstance(record, Metadata) and record.name != RECOVERED:  # (an earlier one: carried below)
                writer.add_metadata(record.name, dict(record.metadata))
        if added is not None:
            # the output's ids: channel_ids maps the source's to them (they match only if both writers numbered
            # alike, which a file another tool wrote need not)
            by_topic = {topic: channel_ids[cid] for cid, topic in topics.items()}
            last_ns = max((r.log_time for r in checked.records if isinstance(r, Message)), default=0)
            for key, payload, log_ns, seq in added.items:
                channel = by_topic.get(key)
                if channel is None:
                    channel = by_topic[key] = writer.register_channel(key, "json", schemas.event(
                        parse_event_key(key).tag))
                last_ns = max(last_ns, log_ns)  # log times never go back in a file (writer.py)
                writer.add_message(channel, last_ns, payload, last_ns, seq & 0xFFFFFFFF)
                messages += 1
                tag = key.rsplit("/", 1)[-1]
                ended |= tag == "SessionEnded"
                if tag == "RoundStarted":
                    last_round = max(last_round, _round_of(payload))
        lost_at += [messages] * len(losses)  # a part lost after the last record read
        left_out = schemas.left_out(sources)
        damaged = [str(d) for d in checked.damage]
        reason = "" if checked.whole else checked.describe()
        writer.add_metadata(RECOVERED, carry_recovery(earlier, {
            "source": str(path), "messages": str(messages), "truncated": str(checked.truncated).lower(),
            DATA_COMPLETE_KEY: str(checked.data_complete).lower(), "reason": reason, "damaged": json.dumps(damaged), "lost_chunks": str(len(checked.lost_chunks)),
            LOST_AT_KEY: json.dumps(lost_at), "lost": json.dumps([f"{d.part}: {d.lost}" for d in checked.damage if d.lost_at >= 0]),
            "completed": "summary, indexes and CRCs written by pairplay recover",
            "session_ended": str(ended).lower(), "last_round": str(last_round), "copies_dropped": str(copies),
            **({"schemas_left_out": left_out} if left_out else {}),
            **({"journal": journal.path.name if journal is not None else journal_error,
                "from_journal": str(added.taken if added else 0),
                "journal_refused": str(added.refused if added else 0),
                "journal_torn": journal.torn if journal is not None else "",
                JOURNAL_WHOLE_KEY: str(journal is not None and not journal.torn).lower()}
               if journal is not None or journal_error else {})}))
        writer.finish()
    return Recovered(output, messages, checked.truncated, reason, damaged, ended, last_round,
                     journal_present=added.present if added else 0,
                     journal=journal.path if journal is not None else None,
                     from_journal=added.taken if added else 0, journal_refused=added.refused if added else 0,
                     journal_torn=journal.torn if journal is not None else "", journal_error=journal_error,
                     copies=copies, schemas_left_out=left_out, **lost_words)


class _PairplaySchemas:
    """The schemas a recovered copy holds: pairplay's alone. A channel of a pairplay event keeps its source's
    schema when it is pairplay's schema of that event (reader.not_pairplays), else it is given pairplay's, once per
    event (as a channel the journal adds is); any other channel has none (schema id 0: MCAP's schemaless). So a
    Schema record of the source that is not pairplay's, one a hand-made or hostile file added (`{"type":"string"}`
    in place of an event's, bytes that are not JSON, one no channel uses), is left out, and `left_out` says so:
    copied along, the copy misdescribed its events to every other MCAP reader (Foxglove) and passed them on
    unsaid."""

    def __init__(self, writer: Writer):
        self.writer = writer
        self.written: dict[int, int] = {}  # source schema id -> the copy's
        self.events: dict[str, int] = {}  # event tag -> the copy's id of pairplay's schema of it

    def of(self, channel: Channel, schema: Schema | None) -> int:
        """The copy's schema id for `channel`, whose source schema is `schema` (None: none, or not read)."""
        tag = channel.topic.rsplit("/", 1)[-1]
        if tag not in EVENT_BY_TAG:
            return 0
        if schema is not None and not not_pairplays(tag, (schema.name, schema.encoding, schema.data)):
            if schema.id not in self.written:
                self.written[schema.id] = self.writer.register_schema(schema.name, schema.encoding, schema.data)
            return self.written[schema.id]
        return self.event(tag)

    def event(self, tag: str) -> int:
        """The copy's id of pairplay's own schema of event `tag`."""
        if tag not in self.events:
            self.events[tag] = self.writer.register_schema(tag, "jsonschema", schema_text(EVENT_BY_TAG[tag]).encode())
        return self.events[tag]

    def left_out(self, sources: dict[int, Schema]) -> str:
        """The source's schemas not copied, in one short line ("" if none): how many, the first named."""
        out = [s for i, s in sources.items() if i not in self.written]
        if not out:
            return ""
        first = out[0].name[:40] or "(no name)"
        return (f"{counted(len(out), 'schema')} not pairplay's left out ({first!r}"
                f"{', ...' if len(out) > 1 else ''}): the events' channels have pairplay's")


def _lost_count(checked) -> int | None:
    """How many messages the damaged parts lost: what each part's Message Indexes list (mcapscan `Scan.losses`),
    or, when a part's are lost with it, what the summary's Statistics count less the messages read (a summary
    whose CRC held); None when neither says."""
    counts = [n for _, n in checked.losses()]
    if None not in counts:
        return sum(counts)
    if checked.counted_messages is None:
        return None
    read = sum(type(r) is Message for r in checked.records)
    return checked.counted_messages - read if checked.counted_messages > read else None


def _journal_beside(path: Path, log):
    """(the journal beside `path` read, or None; why an existing one could not be read, or "").
    InputError if it is of another session than the recording's."""
    beside = wal_path(path)
    if not beside.exists():
        return None, ""
    try:
        journal = read_journal(beside)
    except (NotAJournal, OSError) as err:
        return None, f"{beside.name} not read: {err}"
    recorder = log.metadata.get(RECORDER_METADATA, {})
    session = recorder.get("session", "")
    if session and journal.session != session:
        raise InputError(f"the journal beside it ({beside.name}) is of session {journal.session!r}, "
                         f"not {session!r}; move it away", path)
    other = not_its(journal, recorder)
    if other:  # same session id, another recording of it (`session --force` over this file)
        raise NotItsJournal(f"the journal beside it ({beside.name}) is not this file's: {other}; move it away", path)
    return journal, ""


def _round_of(payload: bytes) -> int:
    try:
        return int(json_loads(payload).get("round", -1))
    except (ValueError, AttributeError):
        return -1



def _recorded(checked) -> list[tuple[str, bytes]]:
    """The (key, payload) of every message an `mcapscan.scan` read, in file order."""
    topics = {r.id: r.topic for r in checked.summary_records + checked.records if isinstance(r, Channel)}
    return [(topics[r.channel_id], r.data) for r in checked.records if isinstance(r, Message) and r.channel_id in topics]


def journal_left(path: str | Path) -> str:
    """The one line every verb that reads a recording says when its recorder's journal beside it holds messages
    it lacks ("" when not): how many (the session's end among them, if so), and that `pairplay recover` adds them,
    or that its recovered copy (`default_output`) is there already. A file cut by a crash was read as PARTIAL, or
    "PASS as far as the file goes", not a word of the journal holding the rest (a new user's trial). Counted as
    recover counts what is there already (services/walmerge.py: a record of the journal the file holds, byte for
    byte, once per copy); what recover then refuses through the live checks, a forgery, it records as a refusal.
    Read only when a journal is there, never of a live file (its recorder writes both: pairplay/livelock.py);
    a journal that cannot be read, is another session's, or adds nothing says nothing (recover names those).
    A file a restarted recorder continued (replay/continued.py) says that file instead, journal or not."""
    from collections import Counter

    from pairplay.livelock import is_live

    path = Path(path)
    beside = wal_path(path)
    if is_live(path):
        return ""
    later = continued_in(path)
    if later is not None:  # the session goes on, whole, in a restarted recorder's file: that, not recover (trial34 N)
        return (f"a restarted recorder continued it in {later.name} beside it, which holds the whole session from "
                f"this file's events on: give that instead")
    if not beside.is_file():
        return ""
    try:
        journal, _ = _journal_beside(path, read_any_log(path, only=frozenset()))
        checked = scan(path)
    except (InputError, OSError):
        return ""
    if journal is None:
        return ""
    held = Counter(_recorded(checked))
    lacks = []
    for key, payload, _ in journal.records:
        if held[(key, payload)] > 0:
            held[(key, payload)] -= 1
        else:
            lacks.append(key)
    if not lacks:
        return ""
    ended = any(key.rsplit("/", 1)[-1] == "SessionEnded" for key in lacks)
    more = f"{counted(len(lacks), 'message')} the file lacks" + (", the session's end (SessionEnded) among them"
                                                                  if ended else "")
    recovered = default_output(path)
    if recovered.is_file():
        return (f"its recorder's journal {beside.name} beside it holds {more}; {recovered} is beside it "
                "(`pairplay recover`'s copy with them): give that instead")
    return (f"its recorder's journal {beside.name} beside it holds {more}: `pairplay recover {command_word(path)}` adds them "
            f"(to {recovered.name})")


def journal_more(path: str | Path) -> str:
    """`journal_left` as the end of a refusal's line ("; its recorder's journal ..."), "" when it says nothing: a
    file cut before its first round ended is refused, and the rest of its session may be in the journal."""
    left = journal_left(path)
    return f"; {left}" if left else ""
