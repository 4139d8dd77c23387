"""Reading the event log, also when the file was cut short by a crash.

Rule: records are read in file order with mcap's StreamReader, the one reader
that yields every complete record of a truncated file; a truncated or corrupt
tail ends the read with `truncated=True` and the reason, never an exception,
and loses nothing before it. Each message is decoded with msgspec into its
event class; a message that does not decode is kept as a `BadMessage` with the
reason (a recording is evidence: nothing is dropped silently).
Hot path: `read_log` takes the chunks whole from StreamReader and splits them
itself (`_chunk_records`: one struct call per message, no record object), the
records and their order exactly those of mcap's `breakup_chunk`; a chunk whose
records overrun it ends the read as a corrupt tail does.
`EventDecoderFactory` plugs the same decoding into mcap's own readers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, NamedTuple, Optional

import struct
from io import BytesIO

import msgspec
from mcap.data_stream import ReadDataStream
from mcap.decoder import DecoderFactory
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from pairplay.schemas.envelope import Event
from pairplay.schemas.events import decode_event


class RecordedEvent(NamedTuple):
    key: str  # the channel topic: the bus key
    event: Event
    log_time_ns: int
    payload: bytes


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
    error: str = ""  # why reading stopped early
    channels: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (topic, schema name)
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)  # id -> (name, encoding, data)

    def of(self, *tags: str) -> list[Event]:
        """The events with one of these tags, in order."""
        return [r.event for r in self.events if type(r.event).__name__ in tags]


def iter_records(path: str | Path) -> Iterator[Any]:
    """Every complete record of the file; raises at a truncated or corrupt tail."""
    with open(path, "rb") as f:
        yield from StreamReader(f, record_size_limit=1 << 30).records


_RECORD = struct.Struct("<BQ")  # opcode, length
_MESSAGE = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_MESSAGE_OP, _CHANNEL_OP, _SCHEMA_OP = int(Opcode.MESSAGE), int(Opcode.CHANNEL), int(Opcode.SCHEMA)


class ChunkOverrun(ValueError):
    """A record inside a chunk claims more bytes than the chunk holds."""


def _chunk_records(chunk: Chunk) -> Iterator[tuple]:
    """A chunk's records in order: (channel id, log time, data) per message, else the mcap record object."""
    if chunk.compression == "zstd":
        import zstandard
        data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "":
        data = chunk.data
    else:  # lz4 and anything newer: mcap's own split
        for record in breakup_chunk(chunk):
            yield (record.channel_id, record.log_time, record.data) if isinstance(record, Message) else record
        return
    pos, size = 0, len(data)
    record_head, message_head = _RECORD.unpack_from, _MESSAGE.unpack_from
    while pos < size:
        opcode, length = record_head(data, pos)
        pos += 9
        end = pos + length
        if end > size:
            raise ChunkOverrun(f"a record of {length} bytes overruns its chunk at byte {pos}")
        if opcode == _MESSAGE_OP:
            channel_id, _, log_time, _ = message_head(data, pos)
            yield channel_id, log_time, data[pos + 22:end]
        elif opcode == _CHANNEL_OP:
            yield Channel.read(ReadDataStream(BytesIO(data[pos:end])))
        elif opcode == _SCHEMA_OP:
            yield Schema.read(ReadDataStream(BytesIO(data[pos:end])))
        pos = end


def read_log(path: str | Path) -> EventLog:
    """Read a recording (complete or truncated); see the module rule."""
    log = EventLog(str(path))
    channels: dict[int, str] = {}
    decode = decode_event
    append = log.events.append
    new = tuple.__new__  # a RecordedEvent without NamedTuple's keyword handling

    def other(record) -> None:
        if isinstance(record, Channel):
            channels[record.id] = record.topic
            log.channels[record.id] = (record.topic, str(record.schema_id))
        elif isinstance(record, Schema):
            log.schemas[record.id] = (record.name, record.encoding, record.data)
        elif isinstance(record, Metadata):
            log.metadata[record.name] = dict(record.metadata)

    def message(channel_id: int, log_time: int, data: bytes) -> None:
        key = channels.get(channel_id)
        if key is None:
            log.bad.append(BadMessage("", f"message on unknown channel {channel_id}", log_time, data))
            return
        try:
            append(new(RecordedEvent, (key, decode(data), log_time, data)))
        except (msgspec.DecodeError, msgspec.ValidationError) as err:
            log.bad.append(BadMessage(key, str(err), log_time, data))

    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, emit_chunks=True, record_size_limit=1 << 30).records:
                if type(record) is Chunk:
                    for item in _chunk_records(record):
                        if type(item) is tuple:
                            message(*item)
                        else:
                            other(item)
                elif isinstance(record, Message):
                    message(record.channel_id, record.log_time, record.data)
                elif isinstance(record, Footer):
                    break
                else:
                    other(record)
    except OSError:
        raise  # a file that cannot be opened is not a cut recording
    except Exception as err:  # a cut or corrupt tail: keep what came before it
        log.truncated = True
        log.error = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
    return log


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
