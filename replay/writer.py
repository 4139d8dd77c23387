"""Writing the event log: one MCAP channel per bus key, JSON messages, bounded loss.

Rule: a message is written as the exact JSON bytes seen on the bus, on the
channel named by its key, with the flattened JSON Schema of its event class
(schemas/jsonschema.py), so `mcap` tools and Foxglove read the file as it is.
Loss on a crash is bounded by age: `maybe_flush(now_ns)` closes the open chunk
and flushes the file once the oldest message not yet flushed is
`flush_interval_ns` old (default 25 ms, from its log time, the moment the
recorder took it), so a writer killed with SIGKILL loses only messages younger
than that; the other three quarters of the 0.1 s bound (`LOSS_BOUND_NS`) are the
recorder's margin for its own backlog and the scheduler. `max_flush_age_ns` is the oldest any
message got before its flush. Times must fit MCAP's unsigned 64-bit fields:
anything else raises ValueError before the file is touched. Metadata records (session config, seed, software
version) can be added at any point of the file. The caller owns the clock: every
time is an argument. Log times are the writer's own record of when it took each
message and never go backwards in a file (a time before the last one written is
written as the last one: Zenoh threads hand messages over slightly out of order,
and wall clocks step back); the publish time is the log time unless the caller
has a time of its own it trusts, never a time read from the message itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from pairplay.schemas.events import EVENT_BY_TAG
from pairplay.schemas.jsonschema import schema_text
from pairplay.schemas.keys import parse_event_key

PROFILE = "pairplay"
LOSS_BOUND_NS = 100_000_000  # 0.1 s: the most a crash may lose (README)
# flush once the oldest unflushed message is this old: a quarter of the bound, the rest is the margin for
# the recorder's inbox, the piece it is writing and the scheduler (at 50 ms, 1-2 of 10 SIGKILLs under
# load lost events 105-130 ms old with no backlog in the file: the recorder had been preempted)
FLUSH_INTERVAL_NS = LOSS_BOUND_NS // 4
U64 = 2**64
CHUNK_SIZE = 256 * 1024  # a chunk also closes when this full, whatever the time


class EventLogWriter:
    """Append bus messages to an MCAP file; see the module rule."""

    def __init__(self, output: str | Path | BinaryIO, *, flush_interval_ns: int = FLUSH_INTERVAL_NS,
                 chunk_size: int = CHUNK_SIZE, library: str = "pairplay"):
        self._own = isinstance(output, (str, Path))
        self._stream = open(output, "wb") if self._own else output
        # data CRCs on: the Data End record then carries the CRC of the whole data section (mcapscan checks it)
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=CompressionType.ZSTD,
                              enable_data_crcs=True)
        self._writer.start(profile=PROFILE, library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.flush_interval_ns = int(flush_interval_ns)
        self._oldest_ns: int | None = None  # log time of the oldest message not flushed yet
        self._last_log_ns = 0
        self._unflushed = 0
        self.max_flush_age_ns = 0
        self.last_flush_age_ns = 0  # age of the oldest message of the last flush
        self.flushes = 0
        self.count = 0
        self.closed = False

    def channel_for(self, key: str) -> int:
        """The channel id of a bus key, registering it (and its schema) on first use."""
        channel = self._channels.get(key)
        if channel is None:
            tag = parse_event_key(key).tag
            if tag not in EVENT_BY_TAG:
                raise ValueError(f"no event type {tag!r} for key {key!r}")
            schema = self._schemas.get(tag)
            if schema is None:
                schema = self._writer.register_schema(tag, "jsonschema", schema_text(EVENT_BY_TAG[tag]).encode())
                self._schemas[tag] = schema
            channel = self._writer.register_channel(key, "json", schema)
            self._channels[key] = channel
        return channel

    def write(self, key: str, payload: bytes, *, log_time_ns: int, publish_time_ns: int = 0, sequence: int = 0) -> None:
        """Append one message (already validated JSON of the key's event type).
        (Once per event in the recorder: kept to the few operations the rule needs.)"""
        if not (0 <= log_time_ns < U64 and 0 <= publish_time_ns < U64):
            raise ValueError(f"times out of MCAP's range: log {log_time_ns}, publish {publish_time_ns}")
        if log_time_ns < self._last_log_ns:  # monotonic per file (see rule)
            log_time_ns = self._last_log_ns
        else:
            log_time_ns = self._last_log_ns = int(log_time_ns)
        channel = self._channels.get(key)
        if channel is None:
            channel = self.channel_for(key)
        self._writer.add_message(channel, log_time_ns, payload, publish_time_ns or log_time_ns, sequence & 0xFFFFFFFF)
        self.count += 1
        if not self._unflushed:
            self._oldest_ns = log_time_ns
        self._unflushed += 1

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def due_in_ns(self, now_ns: int) -> int | None:
        """How long until the next flush is due (None: nothing waits to be flushed)."""
        if not self._unflushed or self._oldest_ns is None:
            return None
        return max(0, self._oldest_ns + self.flush_interval_ns - now_ns)

    def maybe_flush(self, now_ns: int) -> bool:
        """Flush if the oldest unflushed message is `flush_interval_ns` old; True if it did."""
        due = self.due_in_ns(now_ns)
        if due is None or due > 0:
            return False
        self.flush(now_ns)
        return True

    def flush(self, now_ns: int) -> None:
        """Close the open chunk and push everything to the OS."""
        self.last_flush_age_ns = 0 if self._oldest_ns is None else now_ns - self._oldest_ns
        self.max_flush_age_ns = max(self.max_flush_age_ns, self.last_flush_age_ns)
        self._writer.flush()
        self._oldest_ns = None
        self._unflushed = 0
        self.flushes += 1

    def abandon(self) -> None:
        """After a write error: close the stream as it is (readable up to the error:
        `pairplay recover`), never raising."""
        self.closed = True
        if self._own:
            try:
                self._stream.close()
            except OSError:
                pass

    def close(self) -> None:
        """Write the summary and close: the file is then complete and indexed."""
        if self.closed:
            return
        self.closed = True
        self._writer.finish()
        self._stream.flush()
        if self._own:
            self._stream.close()
