"""Reading an MCAP file record by record and checking everything the MCAP format lets a reader check.

Rule (the MCAP specification, mcap.dev/spec): a file is the magic, a Header,
the data section (Schema, Channel, Message and Metadata records, or Chunks of
them each followed by its Message Index records), a Data End record with the
CRC-32 of every byte before it, an optional summary section (Schemas,
Channels, Chunk Indexes, Statistics, Metadata Indexes, Summary Offsets), a
Footer with the CRC-32 of the summary and the magic again. `scan` walks the
records in file order and checks each one it can: the magic at both ends,
every record's opcode and length against the bytes left, each chunk's
compression, uncompressed size and CRC and the bounds of the records inside,
every Message Index against the chunk before it (offsets, channels, log
times), each chunk's time range against its messages, each channel's message
sequence numbers rising in file order (a pairplay recorder writes them so:
chunks out of order break it), the data section CRC, the summary CRC, the
Chunk Indexes against the chunks actually found (offsets, lengths, times) and
the Statistics' counts. Each finding is a `Damage` naming the part (which
chunk, the data end, the summary, the footer, the file's end) and its bytes;
one whose records are lost (a chunk that does not open, unreadable bytes) says
where they were among the records read (`lost_at`) and what was lost (`lost`),
and `Scan.brief` says in one short line what was lost where (the data-section
CRC that a lost chunk breaks too is not repeated there: `describe` has every
finding, and was 1,500 characters printed twice by `rebuild`).

A damaged part is never read as if it were whole: a chunk whose bytes fail a
check gives none of its records. The rest is kept: after unreadable bytes the
scan looks for the next record that proves itself (a chunk whose CRC matches,
or a Data End / Metadata record that parses exactly), so every intact chunk
after a damaged one is still read. A chunk whose record head (opcode and
length) is damaged is such unreadable bytes; the summary's Chunk Index that
points into them names them as that chunk, counts its messages from the Message
Index records after it and numbers it in its place: one finding, said once, with
how many later chunks were read (`headless_chunks`), where every later chunk was
"out of order". A file that simply stops (a crash) is
`truncated`, with the offset where it stops; one cut after its Data End lost
no message (`data_complete`). A summary record whose length runs past a file
that ends with the closing magic is a damaged summary, not a cut. Unreadable
bytes right after an intact chunk that are exactly its Message Index records
(as its messages make them, but for a few damaged bytes) lost nothing: still a
finding, named as that chunk's index, with no `lost` (a new user's trial:
two damaged index lengths read as lost records, so verify stopped at the
first and rebuild refused the file, all of whose messages were read).

What a reader can trust (the specification): the messages are the data
section's, each chunk proved by its own CRC and the whole section by the Data
End's; the summary and footer are an index of it (a reader may rebuild them
from the data section), proved by the footer's summary CRC (zero: "not to be
checked", as the spec says) and checked here against the data section anyway
(Chunk Indexes, Statistics). So a zeroed or damaged footer or summary (the last
bytes of a file overwritten: its closing magic always goes first) lost no
message when the Data End was read (`data_complete`), and is still damage: a
finding that makes the file not `whole` (verify FAILs naming it; "no event lost,
but the file is damaged"), never a file called whole. `counted_messages`, the
Statistics' count, is kept only from a summary whose CRC held.
`stream` walks the same way, giving the data section's records to a reader a chunk's at a
time instead of keeping them (LostPart at a part whose records are lost).
"""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass, field
from dataclasses import replace as _replace
from io import BytesIO
from pathlib import Path
from typing import Any, Callable

from mcap.data_stream import ReadDataStream
from mcap.records import (Attachment, AttachmentIndex, Channel, Chunk, ChunkIndex, DataEnd, Footer, Header,
                          Message, MessageIndex, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset)

from pairplay.schemas.jsonfile import MCAP_MAGIC
from pairplay.numbers import counted

_HEAD = struct.Struct("<BQ")
_READERS: dict[int, Callable[[ReadDataStream, int], Any]] = {
    0x01: lambda s, n: Header.read(s), 0x02: lambda s, n: Footer.read(s), 0x03: lambda s, n: Schema.read(s),
    0x04: lambda s, n: Channel.read(s), 0x05: Message.read, 0x06: lambda s, n: Chunk.read(s),
    0x07: lambda s, n: MessageIndex.read(s), 0x08: lambda s, n: ChunkIndex.read(s),
    0x09: lambda s, n: Attachment.read(s), 0x0A: lambda s, n: AttachmentIndex.read(s),
    0x0B: lambda s, n: Statistics.read(s), 0x0C: lambda s, n: Metadata.read(s),
    0x0D: lambda s, n: MetadataIndex.read(s), 0x0E: lambda s, n: SummaryOffset.read(s),
    0x0F: lambda s, n: DataEnd.read(s),
}
_IN_CHUNK = (Schema, Channel, Message)
_SUMMARY = (Schema, Channel, ChunkIndex, AttachmentIndex, Statistics, MetadataIndex, SummaryOffset)


# The largest uncompressed chunk read, in bytes. pairplay's writer closes a chunk once it holds 256 KiB
# (replay/writer.CHUNK_SIZE), so one of its chunks is that plus a message of at most 64 KiB
# (schemas/trust.MAX_PAYLOAD); other writers' chunks are a few MB (mcap's default is 1 MiB). A larger declared
# size is a damaged or hostile chunk, refused before anything is allocated for it.
MAX_CHUNK = 64 * 1024 * 1024


class LostPart(Exception):
    """A part whose records are lost, met by `stream`: where its records were among those given is a reader's to
    mark, and a streaming reader has given the ones before it away (it reads the file whole instead)."""


class Unreadable(ValueError):
    """Bytes that are not the record they claim to be."""


@dataclass(frozen=True)
class Damage:
    offset: int  # the first byte of the affected part
    part: str  # "chunk 3 (bytes 120-4096)", "data end", "summary", "footer", "file end", ...
    what: str
    lost_at: int = -1  # records lost here: how many records of the scan came before them (-1: none lost)
    lost: str = ""  # what was lost, short: "its 139 messages (log times ...)", "the records there"

    def __str__(self) -> str:
        return f"{self.part}: {self.what}"


@dataclass
class ChunkSeen:
    number: int
    offset: int
    length: int  # the whole record, opcode and length field included
    start: int
    end: int
    intact: bool
    messages: list[tuple[int, int, int]] = field(default_factory=list)  # (offset in chunk, channel, log time)
    listed: int = 0  # a chunk that does not open: the messages its Message Indexes list (lost with it)
    # channel -> its messages' (log time, offset) in file order, as its Message Index lists them
    by_channel: dict[int, list[tuple[int, int]]] | None = field(default=None, repr=False)
    indexed: set[int] = field(default_factory=set)  # the channels whose Message Index after it was read
    in_order: bool = False  # its messages' log times never go back in file order (`_Opened.in_order`)


@dataclass
class Scan:
    """What a file holds and what is wrong with it (see the module rule)."""

    path: str
    records: list[Any] = field(default_factory=list)  # data-section records in file order, chunks opened
    metadata_records: list[Metadata] = field(default_factory=list)  # its Metadata records, in file order
    damage: list[Damage] = field(default_factory=list)
    truncated: bool = False  # the file stops before its end
    cut_at: int = -1  # where it stops
    cut_what: str = ""  # what the cut took, when known
    chunks: list[ChunkSeen] = field(default_factory=list)
    summary: bool = False  # a summary section was found and checked
    # the summary's Schema and Channel records (when its CRC holds): they name the channels of messages
    # whose own Schema/Channel records were in a lost chunk
    summary_records: list[Any] = field(default_factory=list)
    size: int = 0
    data_complete: bool = False  # the Data End was read: a cut or damage after it lost no message
    # how many messages the file held, as its summary's Statistics count them when the summary's CRC held (None:
    # no such summary): what its lost parts held is this less the messages read, when they do not say it
    counted_messages: int | None = None

    @property
    def whole(self) -> bool:
        return not self.damage and not self.truncated

    @property
    def lost_chunks(self) -> list[ChunkSeen]:
        return [c for c in self.chunks if not c.intact]

    def losses(self) -> list[tuple[int, int | None]]:
        """Each part whose records are lost: (its `lost_at`, how many messages it held as its Message Indexes
        list them; None when that is not known: unreadable bytes, a chunk whose indexes were lost with it)."""
        listed = {c.offset: c.listed for c in self.chunks if not c.intact}
        return [(d.lost_at, listed.get(d.offset) or None) for d in self.damage if d.lost_at >= 0]

    def describe(self) -> str:
        """One line: what is wrong, or 'whole'. Past DESCRIBED findings, the rest are counted: a file whose every
        message was stored twice said one clause a message, an 84 KB line for 5 rounds (a new user's trial,
        trial29 F3); `damage` keeps each (recover records them all)."""
        parts = [str(d) for d in self.damage[:DESCRIBED]]
        if len(self.damage) > DESCRIBED:
            parts.append(f"{counted(len(self.damage) - DESCRIBED, 'more finding')}")
        if self.truncated:
            # a file cut between two records ends at its last byte: "cut at byte N of N" read as nothing cut
            where = (f"cut at byte {self.cut_at} of {self.size}" if self.cut_at < self.size
                     else f"ends after its last whole record (byte {self.size}) without MCAP's summary and footer")
            parts.append(f"file end: {where}" + (f" ({self.cut_what})" if self.cut_what else ""))
        return "; ".join(parts) if parts else "whole"

    def brief(self) -> str:
        """One short line: what was lost where ("chunk 7 (bytes 79265-85442): its 139 messages lost (zstd
        data does not decompress)"), then the cut; without a lost part, `describe`."""
        lost = [d for d in self.damage if d.lost_at >= 0]
        if not lost:
            return self.describe()
        def said(d: Damage) -> str:
            return f"{d.part}: {d.lost} lost ({d.what.split(': its records')[0]})"
        if len(lost) <= 2:
            parts = [said(d) for d in lost]
        else:  # every lost chunk named was a line of thousands of characters
            parts = [f"{counted(len(lost), 'part')} lost, the first {said(lost[0])}, the last {lost[-1].part}"]
        # the data section's CRC covers the lost bytes: it fails with them, a consequence, not news
        others = sum(1 for d in self.damage if d.lost_at < 0 and d.part != "data section")
        if others:
            parts.append(f"{others} more finding{'s' * (others != 1)} (pairplay recover names each)")
        if self.truncated:
            parts.append(f"file end: cut at byte {self.cut_at} of {self.size}")
        return "; ".join(parts)


DESCRIBED = 3  # findings `Scan.describe` names one by one; the rest it counts

_MESSAGE_HEAD = struct.Struct("<HIQQ")
_MESSAGE_IN_CHUNK = struct.Struct("<BQHIQQ")  # a Message record's opcode, length and fixed fields
_INDEX_HEAD = struct.Struct("<HI")


def _parse(opcode: int, content: bytes) -> Any:
    """One record's content, which must be consumed exactly (Message: wholly)."""
    if opcode == 0x05:  # the common records, without a stream object per record (speed)
        if len(content) < _MESSAGE_HEAD.size:
            raise Unreadable("Message content does not parse (too short)")
        channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(content)
        return Message(channel_id=channel_id, sequence=sequence, log_time=log_time, publish_time=publish_time,
                       data=content[_MESSAGE_HEAD.size:])
    if opcode == 0x07:
        if len(content) < _INDEX_HEAD.size:
            raise Unreadable("MessageIndex content does not parse (too short)")
        channel_id, n = _INDEX_HEAD.unpack_from(content)
        if n % 16 or _INDEX_HEAD.size + n != len(content):
            raise Unreadable(f"MessageIndex declares {counted(len(content), 'byte')} but its fields take {_INDEX_HEAD.size + n}")
        flat = struct.unpack_from(f"<{n // 8}Q", content, _INDEX_HEAD.size)
        return MessageIndex(channel_id=channel_id, records=list(zip(flat[::2], flat[1::2])))
    if opcode == 0x06:  # a chunk read by its fixed fields, without mcap's stream object (speed), when they
        # take its content exactly; anything else is read by mcap's reader below, which says what does not parse
        chunk = _chunk_exactly(content)
        if chunk is not None:
            return chunk
    reader = _READERS.get(opcode)
    if reader is None:
        raise Unreadable(f"unknown opcode 0x{opcode:02x}")
    stream = ReadDataStream(BytesIO(content))
    try:
        record = reader(stream, len(content))
    except Exception as err:  # EndOfFile, struct.error, UnicodeDecodeError: not what the opcode says
        raise Unreadable(f"{_name(opcode)} content does not parse ({type(err).__name__})") from None
    if opcode != 0x05 and stream.count != len(content):
        raise Unreadable(f"{_name(opcode)} declares {counted(len(content), 'byte')} but its fields take {stream.count}")
    return record


_CHUNK_FIXED = struct.Struct("<QQQII")  # a Chunk's start and end times, sizes, CRC and its compression's length


def _chunk_exactly(content: bytes) -> Chunk | None:
    """The Chunk `content` holds when its fields take it exactly (what mcap's `Chunk.read` makes of it then), else
    None (a short or overlong content: mcap's reader and the length check say so in their words)."""
    if len(content) < _CHUNK_FIXED.size + 8:
        return None
    start, end, size, crc, named = _CHUNK_FIXED.unpack_from(content)
    at = _CHUNK_FIXED.size + named
    if at + 8 > len(content):
        return None
    (length,) = struct.unpack_from("<Q", content, at)
    if at + 8 + length != len(content):
        return None
    try:
        compression = str(content[_CHUNK_FIXED.size:at], "utf-8")
    except UnicodeDecodeError:
        return None
    return Chunk(message_start_time=start, message_end_time=end, uncompressed_size=size, uncompressed_crc=crc,
                 compression=compression, data=content[at + 8:])


def _name(opcode: int) -> str:
    reader = {0x01: "Header", 0x02: "Footer", 0x03: "Schema", 0x04: "Channel", 0x05: "Message", 0x06: "Chunk",
              0x07: "MessageIndex", 0x08: "ChunkIndex", 0x09: "Attachment", 0x0A: "AttachmentIndex",
              0x0B: "Statistics", 0x0C: "Metadata", 0x0D: "MetadataIndex", 0x0E: "SummaryOffset",
              0x0F: "DataEnd"}
    return reader.get(opcode, f"opcode 0x{opcode:02x}")


def _decompress(chunk: Chunk) -> bytes:
    """The chunk's data decompressed, never more than its declared uncompressed size (+1 byte, so that a chunk
    holding more says so) and never a declared size above MAX_CHUNK: Unreadable otherwise. A hostile file's
    "bomb" chunk (a few KB of zstd that decompress to GBs, whether it declares the GBs or a few KB) made
    every verb allocate the whole decompressed size before the size check (3.2 GB for a 191 KB file; trial28
    F15): zstandard's `decompress` sizes its output by the frame's own content size, whatever
    `max_output_size` says, so that size is checked first; lz4 is read at most up to the declared size.
    Every frame of the data is decompressed, in turn, and its bytes after the last frame are a finding: zstd's
    and lz4's decoders stop at the end of the first frame, so a second frame, or bytes that are no frame, were
    dropped without a word (the CRC and the size are of what was decompressed: they held)."""
    declared = chunk.uncompressed_size
    if declared > MAX_CHUNK:
        raise Unreadable(f"declares {counted(declared, 'byte')} uncompressed, more than any chunk a recorder writes "
                         f"({counted(MAX_CHUNK, 'byte')}): not read")
    if chunk.compression == "":
        return chunk.data
    if chunk.compression == "zstd":
        return _zstd_frames(chunk.data, declared)
    if chunk.compression == "lz4":
        return _lz4_frames(chunk.data, declared)
    raise Unreadable(f"unknown compression {chunk.compression!r}")


_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"  # a zstd frame's first bytes (RFC 8878 3.1.1)


def _zstd_frame_end(data: memoryview, pos: int) -> int:
    """Where the zstd frame at `pos` ends (RFC 8878 3.1.1: its header, its blocks up to the one marked last, its
    checksum when the header says it has one); Unreadable if no frame starts there or it is cut short. The
    decoder says nothing of where a frame ends, so the blocks' headers are walked (a chunk's frame has a few)."""
    import zstandard

    if data[pos:pos + 4] != _ZSTD_MAGIC:
        if not pos:
            raise Unreadable("zstd data does not decompress (it does not start with a zstd frame)")
        raise Unreadable(f"zstd data holds {counted(len(data) - pos, 'byte')} after its last frame that are no "
                         f"zstd frame")
    try:
        at = pos + zstandard.frame_header_size(data[pos:])
        checksum = zstandard.get_frame_parameters(data[pos:]).has_checksum
    except zstandard.ZstdError:
        raise Unreadable("zstd data does not decompress (a frame header that does not parse)") from None
    last = False
    while not last:
        if at + 3 > len(data):
            break
        head = int.from_bytes(data[at:at + 3], "little")
        last, kind, size = head & 1, (head >> 1) & 3, head >> 3
        if kind == 3:
            raise Unreadable("zstd data does not decompress (a block of the reserved type)")
        at += 3 + (1 if kind == 1 else size)  # an RLE block holds its one byte
    end = at + 4 * checksum
    if not last or end > len(data):
        raise Unreadable("zstd data does not decompress (its last frame is cut short)")
    return end


def _zstd_frames(data: bytes, declared: int) -> bytes:
    """Every zstd frame of `data` decompressed, together at most `declared` + 1 bytes (`_decompress`)."""
    import zstandard

    view, out, pos, made = memoryview(data), [], 0, 0
    while pos < len(view) or not out:
        end = _zstd_frame_end(view, pos)
        frame = view[pos:end]
        framed = zstandard.frame_content_size(frame)  # -1: the frame does not say
        if made + framed > declared:
            said = "its zstd frame says" if not out else f"its {counted(len(out) + 1, 'zstd frame')} say"
            raise Unreadable(f"decompresses to {counted(made + framed, 'byte')} ({said}), the chunk says {declared}")
        # room + 1: a frame making more than the chunk says is said by the size check ("more than"), and a room of
        # 0 is no max_output_size to zstandard
        out.append(zstandard.ZstdDecompressor().decompress(frame, max_output_size=declared - made + 1))
        made += len(out[-1])
        pos = end
        if made > declared:
            break  # more than declared: said by the size check
    return out[0] if len(out) == 1 else b"".join(out)


def _lz4_frames(data: bytes, declared: int) -> bytes:
    """Every lz4 frame of `data` decompressed, together at most `declared` + 1 bytes (`_decompress`)."""
    import lz4.frame

    out, rest, made = [], data, 0
    while rest or not out:
        decompressor = lz4.frame.LZ4FrameDecompressor()
        try:
            out.append(decompressor.decompress(rest, max_length=declared - made + 1))
        except RuntimeError:  # lz4's word for data that is no frame
            if not out:
                raise
            out.append(b"")
        made += len(out[-1])
        if made > declared:
            break  # more than declared: said by the size check
        if not decompressor.eof:
            if len(out) == 1:
                raise Unreadable("lz4 data does not decompress (its frame is cut short)")
            raise Unreadable(f"lz4 data holds {counted(len(rest), 'byte')} after its last frame that are no whole "
                             f"lz4 frame")
        rest = decompressor.unused_data or b""
    return out[0] if len(out) == 1 else b"".join(out)


def _message_maker() -> Callable[[int, int, bytes, int, int], Message]:
    """mcap's Message made from (channel_id, log_time, data, publish_time, sequence) with positional arguments
    when its dataclass has its fields in that order (mcap 1.x), with keywords if a version changes them: one is
    made per message, and keywords cost twice as much (measured, a sixth of a scan's time)."""
    from dataclasses import fields

    if tuple(f.name for f in fields(Message)) == ("channel_id", "log_time", "data", "publish_time", "sequence"):
        return Message
    return lambda channel_id, log_time, data, publish_time, sequence: Message(
        channel_id=channel_id, log_time=log_time, data=data, publish_time=publish_time, sequence=sequence)


_new_message = _message_maker()


@dataclass
class _Opened:
    """A chunk's records, and what its messages say that the walker checks after (facts gathered in the one pass
    over its messages, so that the walker need not make another: see `_Walker.chunk`, `_Walker.message_index`)."""

    records: list[Any]
    messages: list[tuple[int, int, int]]  # (offset in chunk, channel, log time), file order
    in_order: bool  # every message's log time is at least the one before it in the chunk
    first_seq: dict[int, int]  # channel -> its first non-zero sequence number in the chunk
    last_seq: dict[int, int]  # channel -> its last non-zero sequence number in the chunk
    seq_rising: bool  # each channel's non-zero sequence numbers rise within the chunk


def _open_chunk(chunk: Chunk) -> _Opened:
    """The records inside a chunk, after every check the chunk allows (Unreadable if one fails)."""
    try:
        data = _decompress(chunk)
    except Unreadable:
        raise
    except Exception as err:
        raise Unreadable(f"{chunk.compression} data does not decompress ({type(err).__name__})") from None
    if len(data) > chunk.uncompressed_size:  # read no further than one byte past the declared size: "more than"
        raise Unreadable(f"decompresses to more than {counted(chunk.uncompressed_size, 'byte')}, the chunk says "
                         f"{chunk.uncompressed_size}")
    if len(data) != chunk.uncompressed_size:
        raise Unreadable(f"decompresses to {counted(len(data), 'byte')}, the chunk says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise Unreadable(f"CRC mismatch (recorded {chunk.uncompressed_crc:#010x}, computed {zlib.crc32(data):#010x})")
    records, messages, pos, size = [], [], 0, len(data)
    add_record, add_message, make = records.append, messages.append, _new_message
    first_seq: dict[int, int] = {}
    last_seq: dict[int, int] = {}
    in_order = seq_rising = True
    start, end = chunk.message_start_time, chunk.message_end_time
    previous = start
    head, message_head = _HEAD.unpack_from, _MESSAGE_IN_CHUNK.unpack_from
    fixed = _MESSAGE_IN_CHUNK.size  # a Message record's opcode, length and fixed fields: 31 bytes
    least = _MESSAGE_HEAD.size  # a Message's content holds at least its fixed fields (22 bytes)
    last_head = size - fixed  # the last offset where a whole Message head fits
    while pos < size:
        if pos <= last_head:  # most records are messages: one unpack reads the head and the fixed fields (speed)
            opcode, length, channel_id, sequence, log_time, publish_time = message_head(data, pos)
            if opcode == 0x05 and length >= least:
                stop = pos + 9 + length
                if stop > size:
                    raise Unreadable(f"a {_name(opcode)} at byte {pos} of the chunk's data runs past its end")
                if not start <= log_time <= end:
                    raise Unreadable(f"a message logged at {log_time} lies outside the chunk's time range "
                                     f"{start}-{end}")
                add_record(make(channel_id, log_time, data[pos + fixed:stop], publish_time, sequence))
                add_message((pos, channel_id, log_time))
                if log_time < previous:
                    in_order = False
                previous = log_time
                if sequence:
                    seen = last_seq.get(channel_id)
                    if seen is None:
                        first_seq[channel_id] = sequence
                    elif sequence <= seen:
                        seq_rising = False
                    last_seq[channel_id] = sequence
                pos = stop
                continue
        if size - pos < 9:
            raise Unreadable(f"a record header is cut at byte {pos} of the chunk's data")
        opcode, length = head(data, pos)
        stop = pos + 9 + length
        if stop > size:
            raise Unreadable(f"a {_name(opcode)} at byte {pos} of the chunk's data runs past its end")
        record = _parse(opcode, data[pos + 9:stop])  # a Message here is too short: Unreadable
        if not isinstance(record, _IN_CHUNK):
            raise Unreadable(f"a {type(record).__name__} record inside a chunk")
        if isinstance(record, Message):  # (not reached: kept so that no message escapes the checks)
            if not start <= record.log_time <= end:
                raise Unreadable(f"a message logged at {record.log_time} lies outside the chunk's time range "
                                 f"{start}-{end}")
            messages.append((pos, record.channel_id, record.log_time))
            in_order, seq_rising = False, False  # the walker's own checks then run message by message
        records.append(record)
        pos = stop
    return _Opened(records, messages, in_order, first_seq, last_seq, seq_rising)


class _Walker:
    def __init__(self, path: str, data: bytes, sink: Callable[[list[Any]], None] | None = None):
        self.data = data
        self.scan = Scan(path, size=len(data))
        # where the data section's records go as they are read: kept in `scan.records`, or given to `sink` a chunk's
        # (a record's) at a time and not kept (`stream`: a 5,000-round file's records were 600 MB)
        self.sink = sink if sink is not None else self.scan.records.extend
        self.streamed = sink is not None
        self.records = 0  # the data section's records read (`Damage.lost_at` counts them)
        self.last_seq: dict[int, tuple[int, int]] = {}  # channel -> (sequence, chunk number)
        self.last_intact: ChunkSeen | None = None  # the last chunk whose records were read
        self.lost_chunk: tuple[int, ChunkSeen] | None = None  # the last chunk that did not open, its Damage's index
        self.messages = 0  # Message records read (the Statistics' count is checked against it)
        self.metadata = self.attachments = 0  # the same, of the data section's Metadata and Attachment records
        self.summary_crc_held = False  # the footer's summary CRC was there and matched
        self.data_end_at = -1
        self.chunk_indexes: list[ChunkIndex] = []
        self.statistics: Statistics | None = None
        self.summary_records: list[Any] = []
        self.indexes_of: ChunkSeen | None = None  # the intact chunk read last, with nothing but its indexes since
        self.spans: list[tuple[int, int, int]] = []  # unreadable bytes whose records are lost: (start, end, Damage index)

    def damage(self, offset: int, part: str, what: str, lost: str = "") -> None:
        """A finding; `lost`: what it lost (records that are not read), said where they were (LostPart if streamed)."""
        if lost and self.streamed:
            raise LostPart(part)
        self.scan.damage.append(Damage(offset, part, what, self.records if lost else -1, lost))

    def record_at(self, pos: int) -> tuple[int, int, Any]:
        """(opcode, end, record) of the record at `pos` (Unreadable if it is not one)."""
        data = self.data
        if len(data) - pos < 9:
            raise EOFError
        opcode, length = _HEAD.unpack_from(data, pos)
        if opcode not in _READERS:
            raise Unreadable(f"byte {pos} holds no record (opcode 0x{opcode:02x})")
        end = pos + 9 + length
        if end > len(data):
            raise EOFError
        return opcode, end, _parse(opcode, data[pos + 9:end])

    def proven_at(self, pos: int) -> bool:
        """Does a record that proves itself start at `pos` (a chunk with a matching CRC, a Data End
        followed by a record, a Metadata record that parses exactly)?"""
        try:
            opcode, end, record = self.record_at(pos)
        except (Unreadable, EOFError):
            return False
        if opcode == 0x06:
            if not record.uncompressed_crc:
                return False
            try:
                _open_chunk(record)
            except Unreadable:
                return False
            return True
        if opcode == 0x0F:
            try:
                self.record_at(end)
            except (Unreadable, EOFError):
                return self.data[end:end + 8] == MCAP_MAGIC
            return True
        return opcode == 0x0C

    def resync(self, pos: int) -> int:
        """The next offset after `pos` where a record proves itself, or -1."""
        data = self.data
        candidates = [p for p in (data.find(b, pos + 1) for b in (b"\x06", b"\x0c", b"\x0f")) if p >= 0]
        while candidates:
            p = min(candidates)
            if self.proven_at(p):
                return p
            opcode = data[p:p + 1]
            candidates.remove(p)
            q = data.find(opcode, p + 1)
            if q >= 0:
                candidates.append(q)
        return -1

    def walk(self) -> Scan:
        data, scan = self.data, self.scan
        if len(data) < 8:
            scan.truncated, scan.cut_at = True, 0
            if data:
                self.damage(0, "header", f"{counted(len(data), 'byte')}: too short for the MCAP magic")
            return scan
        if data[:8] != MCAP_MAGIC:
            self.damage(0, "header", "the file does not start with the MCAP magic")
        pos = 8
        chunk = None
        while pos < len(data):
            try:
                opcode, end, record = self.record_at(pos)
            except EOFError:
                nxt = self.resync(pos)
                if nxt < 0:
                    scan.truncated, scan.cut_at = True, pos
                    return scan
                self.unreadable(pos, nxt, "a record runs past the end of the file: its length is damaged")
                pos = nxt
                continue
            except Unreadable as err:
                nxt = self.resync(pos)
                if nxt < 0:
                    self.damage(pos, f"bytes {pos}-{len(data)}", f"unreadable: {err}", lost="the records there")
                    scan.truncated, scan.cut_at = True, pos
                    return scan
                self.unreadable(pos, nxt, f"unreadable: {err}")
                pos = nxt
                continue
            if opcode != 0x07:
                self.indexes_of = None
            if opcode == 0x01:
                if pos != 8:
                    self.damage(pos, f"header (byte {pos})", "a second Header record")
            elif opcode == 0x06:
                chunk = self.chunk(pos, end, record)
                self.indexes_of = chunk if chunk.intact else None
            elif opcode == 0x07:
                self.message_index(pos, record, chunk)
            elif opcode == 0x0F:
                self.data_end(pos, record)
                return self.summary(end)
            elif opcode == 0x02:
                self.damage(pos, "data end", "the Footer comes without a Data End record")
                self.footer(pos, end, record, summary_start=pos)
                return scan
            elif isinstance(record, (Schema, Channel, Metadata)):
                self.records += 1
                self.sink([record])
                if isinstance(record, Metadata):
                    self.metadata += 1
                    scan.metadata_records.append(record)
            elif opcode == 0x09:
                self.attachments += 1
            elif isinstance(record, Message):
                self.sequence(pos, record, "message", -1)
                self.records += 1
                self.sink([record])
                self.messages += 1
            pos = end
        scan.truncated, scan.cut_at = True, pos
        return scan

    def unreadable(self, pos: int, nxt: int, what: str) -> None:
        """Bytes `pos`-`nxt` that do not read: lost records, unless they are the Message Indexes of the intact
        chunk just read (`only_indexes`): an index is a reader's aid, its chunk's messages were all read."""
        chunk = self.indexes_of
        self.indexes_of = None
        if chunk is not None and self.only_indexes(chunk, pos, nxt):
            self.damage(pos, f"message index of chunk {chunk.number} (bytes {pos}-{nxt})",
                        f"{what}; only the chunk's Message Index records were there (its messages were all read): "
                        "no message lost")
            return
        self.damage(pos, f"bytes {pos}-{nxt}", what, lost="the records there")
        self.spans.append((pos, nxt, len(self.scan.damage) - 1))

    def only_indexes(self, chunk: ChunkSeen, pos: int, nxt: int) -> bool:
        """Do bytes `pos`-`nxt` hold exactly the Message Index records still owed for `chunk` (one per channel
        of its messages not indexed yet), each one's bytes as its messages make them but for a few damaged ones
        (at most a quarter of a record)? Then no other record, and so no message, can have been there."""
        owed: dict[int, list[tuple[int, int]]] = {}
        for off, ch, t in chunk.messages:
            if ch not in chunk.indexed:
                owed.setdefault(ch, []).append((t, off))
        expected = []
        for ch, entries in owed.items():
            body = struct.pack(f"<HI{2 * len(entries)}Q", ch, 16 * len(entries), *(x for e in entries for x in e))
            expected.append(_HEAD.pack(0x07, len(body)) + body)
        data, at = self.data, pos
        while at < nxt and expected:
            def differ(e: bytes) -> int:
                return sum(a != b for a, b in zip(e, data[at:at + len(e)])) + max(0, at + len(e) - nxt)
            best = min(expected, key=differ)
            if differ(best) > len(best) // 4:
                return False
            expected.remove(best)
            at += len(best)
        return at == nxt

    def chunk(self, pos: int, end: int, chunk: Chunk) -> ChunkSeen:
        n = len(self.scan.chunks)
        seen = ChunkSeen(n, pos, end - pos, chunk.message_start_time, chunk.message_end_time, False)
        self.scan.chunks.append(seen)
        part = f"chunk {n} (bytes {pos}-{end})"
        try:
            opened = _open_chunk(chunk)
        except Unreadable as err:
            self.damage(pos, part, f"{err}: its records are not read", lost="its messages")
            self.lost_chunk = (len(self.scan.damage) - 1, seen)
            return seen
        previous = self.last_intact
        if previous is not None and self.streamed:
            # streamed: only the chunk read last is checked against the Message Indexes after it (`message_index`,
            # `only_indexes`); an earlier one's list of messages is kept only for a caller of `scan` to look at
            previous.messages, previous.by_channel = [], None
        if previous is not None and chunk.message_start_time < previous.start:
            self.damage(pos, part, f"starts at log time {chunk.message_start_time}, before chunk {previous.number}"
                        f" ({previous.start}): chunks out of order")
        records, seen.messages, seen.in_order = opened.records, opened.messages, opened.in_order
        seen.intact = True
        self.last_intact = seen
        self.messages += len(seen.messages)
        last_seq = self.last_seq
        # each channel's sequence numbers rise: within the chunk (checked as it was opened) and from the chunks
        # before; then each channel's last number is the chunk's last. Else, message by message, to say where
        rising = opened.seq_rising
        if rising:
            for channel, first in opened.first_seq.items():
                last = last_seq.get(channel)
                if last is not None and first <= last[0]:
                    rising = False
                    break
        if rising:
            for channel, number in opened.last_seq.items():
                last_seq[channel] = (number, n)
        else:
            for record in records:
                if type(record) is Message and record.sequence:
                    last = last_seq.get(record.channel_id)
                    if last is not None and record.sequence <= last[0]:
                        self.sequence(pos, record, part, n)  # says what is wrong
                    else:
                        last_seq[record.channel_id] = (record.sequence, n)
        self.records += len(records)
        self.sink(records)
        return seen

    def sequence(self, pos: int, message: Message, part: str, n: int) -> None:
        if not message.sequence:
            return
        last = self.last_seq.get(message.channel_id)
        if last is not None and message.sequence <= last[0]:
            where = f"chunk {last[1]}" if last[1] >= 0 else "an earlier message"
            self.damage(pos, part, f"channel {message.channel_id}'s sequence goes back from {last[0]} ({where}) to "
                        f"{message.sequence}: records out of order")
        self.last_seq[message.channel_id] = (message.sequence, n)

    def message_index(self, pos: int, index: MessageIndex, chunk: ChunkSeen | None) -> None:
        if chunk is None:
            self.damage(pos, f"message index (byte {pos})", "a Message Index with no chunk before it")
            return
        if not chunk.intact:  # its messages are lost: how many, as its indexes say
            chunk.listed += len(index.records)
            if self.lost_chunk is not None and self.lost_chunk[1] is chunk:
                k = self.lost_chunk[0]
                self.scan.damage[k] = _replace(self.scan.damage[k], lost=f"its {counted(chunk.listed, 'message')}")
            return
        chunk.indexed.add(index.channel_id)
        if chunk.by_channel is None:  # once per chunk, not once per index
            by_channel: dict[int, list[tuple[int, int]]] = {}
            for off, ch, t in chunk.messages:
                entries = by_channel.get(ch)
                if entries is None:
                    by_channel[ch] = [(t, off)]
                else:
                    entries.append((t, off))
            chunk.by_channel = by_channel
        in_file_order = chunk.by_channel.get(index.channel_id, [])
        if chunk.in_order and index.records == in_file_order:
            return  # the chunk's very messages of the channel, in their order, whose log times never go back
        mine = {(off, t) for t, off in in_file_order}
        listed = {(off, t) for t, off in index.records}
        if listed != mine:
            self.damage(pos, f"message index of chunk {chunk.number} (byte {pos})",
                        f"lists {counted(len(listed), 'message')} of channel {index.channel_id}, the chunk holds {len(mine)} "
                        f"({counted(len(listed - mine), 'entry', 'entries')} point at no such message)")
        times = [t for t, _ in index.records]
        if times != sorted(times):
            self.damage(pos, f"message index of chunk {chunk.number} (byte {pos})", "log times not in order")

    def data_end(self, pos: int, record: DataEnd) -> None:
        self.data_end_at = pos
        self.scan.data_complete = True
        if record.data_section_crc:
            crc = zlib.crc32(self.data[:pos])
            if crc != record.data_section_crc:
                self.damage(pos, "data section", f"CRC mismatch over bytes 0-{pos} (recorded "
                            f"{record.data_section_crc:#010x}, computed {crc:#010x}): some byte before the Data End "
                            "changed")

    def summary(self, pos: int) -> Scan:
        data, scan = self.data, self.scan
        start = pos
        while pos < len(data):
            try:
                opcode, end, record = self.record_at(pos)
            except EOFError:
                if data.endswith(MCAP_MAGIC):  # the file's end is there: not a cut, a damaged length
                    self.damage(pos, "summary", f"the record at byte {pos} has a length past the file's end, which is "
                                "whole (the closing MCAP magic is there): its length is damaged")
                    return scan
                scan.truncated, scan.cut_at = True, pos
                scan.cut_what = "inside the summary; the data section is complete"
                return scan
            except Unreadable as err:
                self.damage(pos, "summary", f"unreadable at byte {pos}: {err}")
                return scan
            if opcode == 0x02:
                self.footer(pos, end, record, summary_start=start)
                return scan
            if not isinstance(record, (*_SUMMARY, Metadata)):
                self.damage(pos, "summary", f"a {type(record).__name__} record after the Data End")
            elif isinstance(record, ChunkIndex):
                self.chunk_indexes.append(record)
            elif isinstance(record, (Schema, Channel)):
                self.summary_records.append(record)
            elif isinstance(record, Statistics):
                self.statistics = record
            pos = end
        scan.truncated, scan.cut_at = True, pos
        scan.cut_what = "after the summary: the footer is missing; the data section is complete"
        return scan

    def footer(self, pos: int, end: int, footer: Footer, summary_start: int) -> None:
        data, scan = self.data, self.scan
        tail = data[end:]
        if len(tail) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(tail):
            scan.truncated, scan.cut_at = True, len(data)  # cut inside the closing magic
        elif tail != MCAP_MAGIC:
            self.damage(end, "file end", "the closing MCAP magic is missing or followed by other bytes")
        if footer.summary_start and footer.summary_start != summary_start:
            self.damage(pos, "footer", f"says the summary starts at byte {footer.summary_start}, it starts at "
                        f"{summary_start}")
        if footer.summary_start and footer.summary_crc:
            crc = zlib.crc32(data[footer.summary_start:pos + 9 + 16])
            if crc != footer.summary_crc:
                self.damage(footer.summary_start, "summary", f"CRC mismatch (recorded {footer.summary_crc:#010x}, "
                            f"computed {crc:#010x})")
            else:
                self.summary_crc_held = True
        scan.summary = bool(footer.summary_start)
        if not any(d.part == "summary" for d in scan.damage):
            scan.summary_records = self.summary_records
            if self.summary_crc_held and self.statistics is not None:
                scan.counted_messages = self.statistics.message_count
        self.check_summary()

    def check_summary(self) -> None:
        if not self.scan.summary:
            return
        self.headless_chunks()
        found = {c.offset: c for c in self.scan.chunks}
        if len(self.chunk_indexes) != len(self.scan.chunks):
            self.damage(self.data_end_at, "summary", f"indexes {counted(len(self.chunk_indexes), 'chunk')}, the data section "
                        f"holds {len(self.scan.chunks)}")
        for i, ci in enumerate(self.chunk_indexes):
            c = found.get(ci.chunk_start_offset)
            if c is None or c.length != ci.chunk_length or (c.start, c.end) != (ci.message_start_time,
                                                                             ci.message_end_time):
                self.damage(ci.chunk_start_offset, f"chunk index {i}", f"no chunk of {counted(ci.chunk_length, 'byte')}, log "
                            f"times {ci.message_start_time}-{ci.message_end_time} at byte {ci.chunk_start_offset}: "
                            "chunks moved or changed")
            elif c.number != i:
                self.damage(c.offset, f"chunk {c.number} (bytes {c.offset}-{c.offset + c.length})",
                            f"indexed as chunk {i}: chunks out of order")
        if self.statistics is not None:
            messages = self.messages
            lost = any(not c.intact for c in self.scan.chunks)
            if self.statistics.message_count != messages and not lost:
                self.damage(self.data_end_at, "summary", f"statistics count "
                            f"{counted(self.statistics.message_count, 'message')}, the data section holds {messages}")
        self.unlose_accounted()

    def headless_chunks(self) -> None:
        """Chunks the summary indexes inside unreadable bytes (a chunk whose record head, opcode and length, is
        damaged: the scan cannot tell it is a chunk and reads on from the next record that proves itself) are
        those bytes: the finding is named as the chunk(s), its messages counted from the Message Index records
        after it when they are exactly what the rest of the bytes hold, and the chunk numbered in its place, so
        the chunks after it keep their own numbers. Before, the scan numbered only the chunks it found: every
        later one was "indexed as chunk N+1: chunks out of order", the index "chunks moved or changed" and its
        count off by one (about 30 findings of one damage, a recover line of 2,000 characters)."""
        scan = self.scan
        found = {c.offset for c in scan.chunks}
        inserted: list[ChunkSeen] = []
        named = []  # (Damage index, its chunks, the span's end, their messages or None: not known)
        for start, end, k in self.spans:
            inside = [ci for ci in self.chunk_indexes if ci.chunk_start_offset not in found
                      and start <= ci.chunk_start_offset and ci.chunk_start_offset + ci.chunk_length <= end]
            if not inside:
                continue
            listed, pos, known = 0, start, True
            seen = []
            for ci in sorted(inside, key=lambda ci: ci.chunk_start_offset):
                known = known and pos == ci.chunk_start_offset  # nothing but chunks and their indexes there
                pos = ci.chunk_start_offset + ci.chunk_length
                n = 0
                while pos < end:  # its Message Index records (intact: only the chunk's head was damaged)
                    try:
                        opcode, stop, record = self.record_at(pos)
                    except (Unreadable, EOFError):
                        break
                    if opcode != 0x07 or stop > end:
                        break
                    n, pos = n + len(record.records), stop
                seen.append(ChunkSeen(-1, ci.chunk_start_offset, ci.chunk_length, ci.message_start_time,
                                      ci.message_end_time, False, listed=n))
                listed += n
            known = known and pos == end
            if known:  # losses() reads a part's count by its offset: the first chunk's holds the span's
                seen[0].listed, seen[1:] = listed, [_replace(x, listed=0) for x in seen[1:]]
            else:
                seen = [_replace(x, listed=0) for x in seen]
            inserted += seen
            named.append((k, seen, end, listed if known else None))
        if not inserted:
            return
        old = {c.offset: c.number for c in scan.chunks}
        scan.chunks = sorted(scan.chunks + inserted, key=lambda c: c.offset)
        for i, c in enumerate(scan.chunks):
            c.number = i
        renumber = {n: next(c.number for c in scan.chunks if c.offset == off) for off, n in old.items()}

        def renamed(text: str) -> str:  # the findings made before the count was known name the scan's numbers
            return re.sub(r"\bchunk (\d+)\b", lambda m: f"chunk {renumber.get(int(m.group(1)), int(m.group(1)))}", text)

        scan.damage = [_replace(d, part=renamed(d.part), what=renamed(d.what)) for d in scan.damage]
        for k, seen, end, listed in named:
            d = scan.damage[k]
            numbers = f"chunk {seen[0].number}" if len(seen) == 1 else f"chunks {seen[0].number}-{seen[-1].number}"
            later = sum(1 for c in scan.chunks if c.intact and c.offset >= end)
            then = f"the scan read on from the next record that proves itself (byte {end}): {counted(later, 'later chunk')} read"
            if len(seen) == 1 and seen[0].offset == d.offset:  # the chunk's own head: it is what is unreadable
                part, what = f"{numbers} (bytes {d.offset}-{end})", \
                    f"its record head is unreadable ({d.what.removeprefix('unreadable: ')}); {then}"
            else:  # something before it, or more than one chunk: the bytes, and which chunks they held
                part, what = f"bytes {d.offset}-{end} ({numbers} among them)", f"{d.what}; {then}"
            if listed is not None:
                lost = f"{'its' if len(seen) == 1 else 'their'} {counted(listed, 'message')}"
            else:
                lost = "its messages" if part.startswith("chunk") else d.lost
            scan.damage[k] = _replace(d, part=part, what=what, lost=lost)

    def unlose_accounted(self) -> None:
        """Unreadable bytes outside every chunk lost nothing when a summary that proves itself (its CRC
        held, nothing in it disagreed) accounts for everything the data section holds: every chunk it
        indexes was read whole, and its Statistics count exactly the messages, chunks, metadata and
        attachment records read. Those bytes then held only what the summary does not count (Message
        Index records: a reader's index, not data); they are still a finding, but none lost."""
        stats, scan = self.statistics, self.scan
        if (stats is None or not self.summary_crc_held or any(d.part == "summary" or d.part.startswith("chunk")
                                                              for d in scan.damage)
                or len(self.chunk_indexes) != len(scan.chunks) or not all(c.intact for c in scan.chunks)
                or (stats.message_count, stats.chunk_count, stats.metadata_count, stats.attachment_count)
                != (self.messages, len(scan.chunks), self.metadata, self.attachments)):
            return
        scan.damage = [_replace(d, lost_at=-1, lost="", what=f"{d.what}; no message lost (the summary accounts "
                                "for every chunk, message and metadata record read)")
                       if d.lost_at >= 0 and d.part.startswith("bytes ") else d for d in scan.damage]


def scan(path: str | Path) -> Scan:
    """Check a whole file (see the module rule); OSError if it cannot be read."""
    data = Path(path).read_bytes()
    return _Walker(str(path), data).walk()


def stream(path: str | Path, sink: Callable[[list[Any]], None]) -> Scan:
    """`scan`, the data section's records given to `sink` as they are read (a chunk's at a time, in file order),
    not kept in `Scan.records`: a reader that folds them as they come holds one chunk's, not the file's. The
    findings are `scan`'s; those made after a record was given (a later chunk's damage, the summary's) are known
    only when it returns."""
    data = Path(path).read_bytes()
    return _Walker(str(path), data, sink).walk()


def scan_bytes(data: bytes, path: str = "") -> Scan:
    return _Walker(path, data).walk()
