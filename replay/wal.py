"""A live recording's write-ahead journal (`<recording>.journal`): every message durable when received.

Rule: the recorder's bus callback only appends (key, payload) to a list (one
append: it never blocks and never does I/O); a journal thread writes everything
appended since its last write with ONE `os.write` every `PERIOD_S` (5 ms), so a
message is in the page cache, where a SIGKILL of the process cannot reach it,
at most `PERIOD_S` + scheduling after it was received, whether or not the
recorder's writer (decode, checks, MCAP) has caught up with its inbox. It is
not fsync'd: a power cut or a kernel crash can lose what the OS had not written
back (docs/bus.md). The journal is removed once the recording is complete and
fsync'd (services/recorder.py `close`); one left beside a recording means the
recorder did not finish it, and `pairplay recover` adds from it what the
recording lacks (services/walmerge.py decides what, through the live checks).
Not the study journal (journal.jsonl, schemas/journal.py): this one is the
recorder's own, raw and temporary.

Format (little-endian; all integers unsigned):
  MAGIC (20 bytes), then frames. A frame is a 20-byte head: body length (u32),
  record count (u32), the time the journal thread took the records (u64, ns
  since the epoch: the receipt time recover gives them, at most one period
  late), CRC-32 (u32, zlib's) of the head's first 16 bytes and the body; then
  the body: a MessagePack array of [key (str), payload (bin)] pairs. The first
  frame's body is instead a MessagePack map naming the recording (`session`,
  `recording`, `software_version`, `started_ns`, and `recording_started_ns`: the `started_ns` of the
  recording's own metadata, "pairplay.recorder", which tells a file's journal from another recording's of
  the same name: `session --force` over it, cut, left its journal beside the earlier file), its count 0. One frame per
  write: a write cut by the kill (a torn tail) fails its length or CRC check,
  and the journal is read up to it (`read_journal`, `Journal.torn` says where
  and why). One CRC per frame, not per record: per record it cost ~1.5 us per
  event in Python (measured), the whole frame's ~0.3 us, and a torn frame only
  holds what was received within one period of the kill, the bound anyway.
"""

from __future__ import annotations

import fcntl
import os
import struct
import threading
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import msgspec
from pairplay.inputs import refusal
from pairplay.numbers import counted
from pairplay.schemas.nesting import MsgpackDecoder, msgpack_decode

MAGIC = b"\x89pairplay journal 1\n"  # 20 bytes: no MCAP reader takes it for a recording
assert len(MAGIC) == 20
SUFFIX = ".journal"
RECORDING_STARTED = "recording_started_ns"  # header key: the started_ns of the recording it journals (module rule)
RECORDER_METADATA = "pairplay.recorder"  # the recording's own metadata record, whose started_ns the header repeats
PERIOD_S = 0.005  # the journal thread writes what was received at least this often
_HEAD = struct.Struct("<IIQI")  # body length, count, taken_ns, crc32
MAX_FRAME = 1 << 30  # a frame's body longer than this is damage, not data (a period's messages are a few MB)
_encode = msgspec.msgpack.Encoder().encode
_records = MsgpackDecoder(list[tuple[str, bytes]])


def wal_path(recording: str | Path) -> Path:
    """The journal beside `recording`: `<recording>.journal` (s.mcap -> s.mcap.journal)."""
    recording = Path(recording)
    return recording.with_name(recording.name + SUFFIX)


def is_journal(path: str | Path) -> bool:
    """Whether `path` starts with the journal's MAGIC (False if it cannot be read, or is no regular file: a
    pipe is never opened, which blocked: pairplay/inputs.py)."""
    if refusal(path):
        return False
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def _frame(body: bytes, count: int, taken_ns: int) -> bytes:
    head = _HEAD.pack(len(body), count, taken_ns, 0)[:16]
    return head + struct.pack("<I", zlib.crc32(body, zlib.crc32(head))) + body


class JournalWriter:
    """Appends what the recorder receives to `<recording>.journal` (see the module rule).

    `add` is the callback's list append ((key: str, payload: bytes)); `start` starts the
    journal thread; `close(remove)` writes what is left, closes, and removes the file if told.
    A write error stops the journal: `failure` says why and `on_failure` is called (from the
    journal thread). FileExistsError if the journal exists already (it is never replaced)."""

    def __init__(self, recording: str | Path, session: str, *, software_version: str = "",
                 clock: Callable[[], int] = time.time_ns, period_s: float = PERIOD_S,
                 on_failure: Callable[[str], None] | None = None, recording_started_ns: int | None = None):
        self.path = wal_path(recording)
        self.clock, self.period_s, self.on_failure = clock, period_s, on_failure
        self.pending: list[tuple[str, bytes]] = []
        self.add = self.pending.append  # the callback's only step (atomic under the GIL)
        self.failure: str | None = None
        self.records = self.writes = self.bytes = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # live while we write it (pairplay/livelock.py)
        header = _encode({"session": session, "recording": Path(recording).name,
                          "software_version": software_version, "started_ns": str(clock()),
                          **({RECORDING_STARTED: str(recording_started_ns)} if recording_started_ns is not None else {})})
        self._write(MAGIC + _frame(header, 0, clock()))

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="pairplay-journal", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            time.sleep(self.period_s)
            self.write_pending()

    def write_pending(self) -> int:
        """Write everything appended since the last write as one frame, one os.write; how many.
        (Only the journal thread calls it while it runs.)"""
        pending = self.pending
        n = len(pending)
        if not n:
            return 0
        if self.failure is not None:  # the recording has failed (told already): nothing more is kept
            del pending[:n]
            return 0
        # the prefix [0:n] is ours: appends only ever go after it, and both steps are single
        # operations under the GIL (a free-threaded Python would need a lock here)
        items = pending[:n]
        del pending[:n]
        self._write(_frame(_encode(items), n, self.clock()))
        self.records += n
        return n

    def _write(self, data: bytes) -> None:
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self._fd, view):]
            self.writes += 1
            self.bytes += len(data)
        except OSError as err:
            self.failure = f"journal {self.path}: {err.strerror or err}"
            self.pending.clear()
            if self.on_failure is not None:
                self.on_failure(self.failure)

    def close(self, remove: bool = False) -> None:
        """Stop the thread, write what is left, close the file; `remove` it (the recording is
        complete). Never raises."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        if self._thread is None or not self._thread.is_alive():
            self.write_pending()
        if remove:  # before the close: a journal that is there is locked until it is gone
            try:
                self.path.unlink()
            except OSError:
                pass
        if self._fd >= 0:
            try:
                os.close(self._fd)
            except OSError:
                pass
            self._fd = -1


@dataclass
class Journal:
    """A journal read (`read_journal`): its header, the records of every intact frame in
    order as (key, payload, taken_ns), and where it stops if not at a frame's end."""

    path: Path
    header: dict
    records: list[tuple[str, bytes, int]] = field(default_factory=list)
    torn: str = ""  # "" when it ends at a frame's end; else where and why it stops
    frames: int = 0

    @property
    def session(self) -> str:
        return str(self.header.get("session", ""))


def not_its(journal: Journal, metadata: dict[str, str]) -> str:
    """Why `journal` is not the journal of the recording whose RECORDER_METADATA is `metadata` ("" if it may be):
    another recording of its session id (the header's RECORDING_STARTED is not the file's `started_ns`). One of
    them without it (a journal written before the key existed, a file cut before its metadata reached the disk)
    is taken as the file's, as before the key. Every reader that takes a journal's records for a file's asks
    (replay/recover.py, services/recorder.py `earlier_records`, replay/cutgame.py): by the session id alone, a
    restarted recorder merged another recording's events into its file."""
    mine, its = str(metadata.get("started_ns", "")), journal.header.get(RECORDING_STARTED, "")
    if not mine or not its or mine == its:
        return ""
    return (f"it is of another recording of session {journal.session!r} (started {_when(its)}, "
            f"this file {_when(mine)})")


def _when(ns: str) -> str:
    """A recorder's started_ns in words (UTC, to the second)."""
    from datetime import datetime, timezone
    try:
        return datetime.fromtimestamp(int(ns) / 1e9, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    except (ValueError, OverflowError, OSError):
        return repr(ns)


class NotAJournal(ValueError):
    """The file is not a journal (no MAGIC, or its header frame is unreadable)."""


def read_journal(path: str | Path) -> Journal:
    """Read a journal up to its end or its first torn or damaged frame (see the module rule).
    NotAJournal if it does not start with MAGIC and an intact header frame; OSError if unreadable."""
    path = Path(path)
    if said := refusal(path):  # a pipe beside a recording: `recover` waited on it (pairplay/inputs.py)
        raise NotAJournal(f"{path} {said}")
    data = path.read_bytes()
    if data[:len(MAGIC)] != MAGIC:
        raise NotAJournal(f"{path} is not a recorder's journal (no journal magic)")
    pos = len(MAGIC)
    frames: list[tuple[bytes, int, int]] = []
    torn = ""
    while pos < len(data):
        if len(data) - pos < _HEAD.size:
            torn = f"cut inside a frame's head at byte {pos} of {len(data)}"
            break
        size, count, taken_ns, crc = _HEAD.unpack_from(data, pos)
        start = pos + _HEAD.size
        if size > MAX_FRAME or start + size > len(data):
            torn = f"cut inside a frame at byte {pos} of {len(data)} ({counted(size, 'byte')} announced)"
            break
        body = data[start:start + size]
        if zlib.crc32(body, zlib.crc32(data[pos:pos + 16])) != crc:
            torn = f"a frame at byte {pos} fails its CRC (torn or damaged); {counted(len(data) - pos, 'byte')} not read"
            break
        frames.append((body, count, taken_ns))
        pos = start + size
    if not frames:
        raise NotAJournal(f"{path}: the journal's header is {'damaged' if torn else 'missing'}")
    try:
        header = msgpack_decode(frames[0][0], type=dict[str, str])
    except (msgspec.DecodeError, msgspec.ValidationError) as err:
        raise NotAJournal(f"{path}: the journal's header is unreadable ({err})") from None
    journal = Journal(path, header, torn=torn, frames=len(frames))
    for i, (body, count, taken_ns) in enumerate(frames[1:], 1):
        try:
            items = _records.decode(body)
        except (msgspec.DecodeError, msgspec.ValidationError) as err:
            journal.torn = f"frame {i} is unreadable ({err}); read up to it"
            break
        if len(items) != count:
            journal.torn = f"frame {i} holds {counted(len(items), 'record')}, its head says {count}; read up to it"
            break
        journal.records.extend((k, p, taken_ns) for k, p in items)
    return journal
