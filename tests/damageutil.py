"""Real damage done to a real, finished recording, as a disk or a careless hand would (tests of the verbs that
read a recording back: each must say what the reader says, replay/reader.py `EventLog.note`)."""

from __future__ import annotations

import os

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig


def small_chunked_session(path, session: str, rounds: int = 3):
    """A real recording of a 3-round session (or `rounds`) at `path`, written by the recorder's writer in small
    chunks (about 20 for 3 rounds), to be damaged."""
    from loopback_session import loopback_events

    config = SessionConfig(session=session, participant="sim:deaf", persona="deaf", seed=4, rounds=rounds)
    w = EventLogWriter(path, chunk_size=4096)
    w.add_metadata("pairplay.session", {"session": config.session})
    for i, e in enumerate(loopback_events(config)):
        w.write(event_key(e.session, e.source, type(e).__name__), encode_event(e), log_time_ns=10**18 + i,
                sequence=e.seq)
    w.close()
    return path


def damage(path, how: str, tag: str = "") -> None:
    """Damage the finished recording at `path`: "chunk", a flipped byte in a chunk (its CRC fails: the chunk
    is lost), the one holding the first event of `tag` (the file written again in 4 KB chunks first), else its
    middle one; "cut", its last third cut off; "undecodable", the first event of `tag` (default a Q update)
    replaced by bytes that do not decode."""
    if how == "cut":
        data = path.read_bytes()
        _replace(path, data[:len(data) * 2 // 3])
    elif how == "chunk":
        chunks = scan(path).chunks
        c = chunks[len(chunks) // 2]
        if tag:
            when = _rewritten(path, tag, broken=False)
            [c] = [c for c in scan(path).chunks if any(t == when for _, _, t in c.messages)]
        data = bytearray(path.read_bytes())
        data[c.offset + c.length - 7] ^= 0x5A
        _replace(path, bytes(data))
    else:
        _rewritten(path, tag or "QUpdated", broken=True)
    assert read_log(path).note


def _rewritten(path, tag: str, broken: bool) -> int:
    """The recording at `path` written again in 4 KB chunks, the first event of `tag` replaced by bytes that do
    not decode if `broken`; that event's log time."""
    log = read_log(path)
    [first] = [r for r in log.events if type(r.event).__name__ == tag][:1]
    tmp = path.with_name(path.name + ".damaging")
    w = EventLogWriter(tmp, chunk_size=4096)
    # each log time made unique (+ its index, in ns): events may share one (a recorder writes what it asked for
    # at the file's latest time: services/recorder.py `_catch_up`), and the caller finds the event's chunk by it
    for i, r in enumerate(log.events):
        w.write(r.key, b'{"type":"broken"' if broken and r is first else r.payload, log_time_ns=r.log_time_ns + i,
                sequence=r.event.seq)
        if r is first:
            when = r.log_time_ns + i
    w.close()
    os.replace(tmp, path)
    return when


def _replace(path, data: bytes) -> None:
    """`path` holding `data`, whole at once: a process that reads it meanwhile (a verb reading its recording
    back) reads the file before or after, never one cut to nothing by a rewrite (`write_bytes` truncates first:
    the lab's read-back once saw the recording "truncated ... (byte 0)")."""
    tmp = path.with_name(path.name + ".damaging")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def damaged_when_written(monkeypatch, module, how: str, tag: str = "") -> None:
    """`module.run_session` (the one a verb or the study runner calls) made to damage (`damage`, `how` and `tag`
    as there) the recording the real session has just finished and closed, before its caller reads it back."""
    real = module.run_session

    def damaged_after_it_is_written(*args, **kwargs):
        path = real(*args, **kwargs)
        damage(path, how, tag)
        return path

    monkeypatch.setattr(module, "run_session", damaged_after_it_is_written)


# files a stream cannot judge (reader.stream_log: NotStreamed), each read whole by the verbs: where a lost part's or a
# bad message's events were, and whether a seq read again is a copy, is known only from what came before and after

def lost_part(path):
    """A real recording with a chunk damaged: its events lost."""
    small_chunked_session(path, "lost")
    damage(path, "chunk")


def undecodable(path):
    """A real recording with a message that does not decode."""
    small_chunked_session(path, "bad")
    damage(path, "undecodable")


def copies(path):
    """A real recording with every message stored twice."""
    from rewrite_mcap import rewritten

    rewritten(path, each=lambda channel, message: [message, message])
