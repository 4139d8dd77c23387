"""Completing a recording cut short by a crash or damaged on disk (`pairplay recover`).

Rule: every record of every intact part of the file (`mcapscan.scan`: the
parts that pass the MCAP format's checks, including the chunks after a damaged
one) is copied, in order, into a new file that is then finished with a summary,
an index and CRCs, so any MCAP reader opens it. Nothing is invented: a lost
tail or a damaged chunk stays lost, and a "pairplay.recovered" metadata record
says what recover completed (the summary and index it wrote), what it read,
from where, what was wrong (every damaged part, the cut) and how far the
session got (whether its SessionEnded survived, the last round). A whole file
recovers to an equivalent whole file. The original is never modified.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from pairplay.errors import InputError, OutputError
from pairplay.outputs import check_output, output_file

from .check import check_recording, no_session
from .mcapscan import scan
from .reader import read_log
from .writer import CHUNK_SIZE, PROFILE


@dataclass
class Recovered:
    output: Path
    messages: int
    truncated: bool
    reason: str  # "" when the input was whole
    damaged: list[str] = field(default_factory=list)  # the parts not copied, and why
    ended: bool = False  # the session's SessionEnded was among the records kept
    last_round: int = -1
    started: bool = True  # the session's SessionStarted was among the records kept


def default_output(path: Path) -> Path:
    return path.with_name(path.stem + ".recovered.mcap")


def recover(path: str | Path, output: str | Path | None = None, force: bool = False) -> Recovered:
    """Copy the intact records of `path` into a complete file (see rule).

    InputError if `path` is not an MCAP file at all (missing, empty, no MCAP magic) or holds no
    session (check.py `no_session`), unless it is cut or damaged and holds pairplay events;
    OutputError if `output` exists (unless `force`) or is the input; the output
    appears only when complete (pairplay.outputs)."""
    path = check_recording(path)
    output = Path(output) if output is not None else default_output(path)
    if output.resolve() == path.resolve():
        raise OutputError("recover writes a new file; give an output path other than the input", output)
    check_output(output, force)
    log = read_log(path)
    why = no_session(log)
    # a cut or damaged file of a session's events is kept whatever it lost (its start may be in the lost
    # part, or before a recorder that joined late); one with nothing of a session, or whole, has nothing
    if why and not (log.events and not log.whole):
        raise InputError(f"{why}; nothing to recover", path)
    checked = scan(path)
    messages, ended, last_round = 0, False, -1
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics: dict[int, str] = {}
    with output_file(output, "wb", force) as out:
        writer = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD, enable_data_crcs=True)
        writer.start(profile=PROFILE, library="pairplay recover")
        # the summary's Schemas and Channels first: they name the channels of messages whose own
        # records were in a lost chunk
        for record in checked.summary_records + checked.records:
            if isinstance(record, Schema):
                if record.id not in schema_ids:
                    schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                if record.id not in channel_ids:
                    channel_ids[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0),
                        dict(record.metadata))
                    topics[record.id] = record.topic
            elif isinstance(record, Message):
                if record.channel_id in channel_ids:
                    writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    messages += 1
                    tag = topics[record.channel_id].rsplit("/", 1)[-1]
                    ended |= tag == "SessionEnded"
                    if tag == "RoundStarted":
                        last_round = max(last_round, _round_of(record.data))
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, dict(record.metadata))
        damaged = [str(d) for d in checked.damage]
        reason = "" if checked.whole else checked.describe()
        writer.add_metadata("pairplay.recovered", {
            "source": str(path), "messages": str(messages), "truncated": str(checked.truncated).lower(),
            "reason": reason, "damaged": json.dumps(damaged), "lost_chunks": str(len(checked.lost_chunks)),
            "completed": "summary, indexes and CRCs written by pairplay recover",
            "session_ended": str(ended).lower(), "last_round": str(last_round)})
        writer.finish()
    return Recovered(output, messages, checked.truncated, reason, damaged, ended, last_round, started=not why)


def _round_of(payload: bytes) -> int:
    try:
        return int(json.loads(payload).get("round", -1))
    except (ValueError, AttributeError):
        return -1
