"""Is this file a recording at all? The check every verb makes before it reads one.

Rule: a path given as a recording must name a readable, non-empty file that
starts with MCAP's magic bytes (MCAP specification: the file begins with
0x89 "MCAP0" CR LF); anything else is an `InputError` naming the path, raised
before anything is written. How much of a real MCAP file is intact is the
reader's business (reader.py); this only keeps what is not MCAP at all from
being read as an empty recording (a file of nothing whose recorder's journal is
beside it is named as `pairplay recover`'s to complete). A recording a verb folds, verifies,
replays, views, fits or recovers must also hold a session (its
SessionStarted): `read_session` refuses one that does not, saying what the
file is (only the magic, a header, another program's MCAP, a session that
never started) in the reader's words (reader.EventLog.no_session: the reader
decides what a file holds), for every such verb alike. A verb whose result is made of whole
rounds (rebuild's policy and curve, verify's verdict, a combiner's policy from a
recording) also refuses a session with no round recorded whole (`no_whole_round`):
a file cut, or a session stopped, before its first round ended gave a policy of 0
rounds, or "PASS as far as the file goes", with exit 0 (a new user's trial).
"""

from __future__ import annotations

from pathlib import Path

from pairplay.arguments import path_argument
from pairplay.errors import InputError, command_word
from pairplay.inputs import check_input
from pairplay.schemas.jsonfile import MCAP_MAGIC
from pairplay.numbers import counted



def recording_file(path: str | Path, function: str = "") -> Path:
    """`path` as a Path if it names a file: InputError "no such recording", "a folder" (every verb's
    words) or "is a named pipe (FIFO)..." (pairplay/inputs.py: anything but a regular file or a link to one)
    otherwise; given `function` (a public function's name), first an ArgumentError unless `path` is a path at all
    (pairplay/arguments.py: read_log(None) was a TypeError of pathlib's)."""
    path = path_argument(path, function) if function else Path(path)
    if not path.exists():
        from .wal import wal_path
        if wal_path(path).exists():  # the recording moved or removed, what its recorder took still beside it
            raise InputError(f"no such recording; its journal is here ({wal_path(path)}: what its recorder "
                             f"received): `touch {command_word(path)}` (an empty file, as a recorder killed before its first "
                             f"flush leaves one), then `pairplay recover {command_word(path)}` rebuilds the recording from it",
                             path)
        raise InputError("no such recording", path)
    if path.is_dir():
        raise InputError("a folder, not a recording (give the .mcap files)", path)
    check_input(path)  # a pipe, a device: opening one for reading blocked, or read endless zeros
    return path


def check_recording(path: str | Path, journal_ok: bool = False, function: str = "") -> Path:
    """`path` as a Path if it can be read as an MCAP recording; InputError saying why not.

    A recorder killed before its first flush leaves a file of nothing (0 bytes, or cut inside
    MCAP's magic) and what it received in its journal beside it (wal.py): such a file is refused
    naming `pairplay recover`, or taken with `journal_ok` (recover: the journal holds the recording).
    `function`: the public function given `path` (recording_file)."""
    path = recording_file(path, function)
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as err:
        raise InputError(f"cannot read the recording: {err.strerror}", path) from None
    if len(head) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(head):  # nothing of MCAP past (part of) its magic
        from .wal import wal_path
        if wal_path(path).exists():
            if journal_ok:
                return path
            what = "the file is empty (0 bytes)" if not head else f"cut inside MCAP's magic ({counted(len(head), 'byte')})"
            if none := journal_holds_no_session(wal_path(path)):  # recover would only say the same (trial34 E)
                raise InputError(f"{what}: its recorder stopped before it wrote a record, and the journal beside it "
                                 f"({wal_path(path).name}) {none}: no session was recorded (remove both to reuse "
                                 "its session id)", path)
            raise InputError(f"{what}: its recorder stopped before it wrote a record; the journal beside it "
                             f"({wal_path(path).name}) holds what it received: `pairplay recover {command_word(path)}`", path)
        if not head:
            raise InputError("the file is empty (0 bytes), not a recording", path)  # every input's words (jsonfile.empty)
    if head != MCAP_MAGIC:
        from .wal import SUFFIX, is_journal
        if is_journal(path):  # a recorder's journal left beside a recording it did not finish
            how = (f"`pairplay recover {command_word(str(path)[:-len(SUFFIX)])}` adds what it holds to the recording "
                   "beside it") if path.name.endswith(SUFFIX) else \
                "`pairplay recover RECORDING` adds what it holds to the recording it was written beside"  # renamed
            raise InputError(f"a recorder's write-ahead journal, not a recording: {how}", path)
        raise InputError("not a recording: not an MCAP file (it does not begin as one)", path)
    return path


def journal_holds_no_session(journal: Path) -> str:
    """What a recorder's journal holds when no session is in it ("holds nothing", "holds 3 messages but no
    SessionStarted"): the words `recover` would refuse it in; "" if it holds a session's start or cannot be read
    (recover reads it then, and says what it finds). Asked before a verb points to recover, or to a file's
    journal as what keeps a session id taken (cli/run.py)."""
    from .wal import NotAJournal, read_journal
    try:
        records = read_journal(journal).records
    except (NotAJournal, OSError):
        return ""
    if any(key.rsplit("/", 1)[-1] == "SessionStarted" for key, *_ in records):
        return ""
    return f"holds {counted(len(records), 'message')} but no SessionStarted" if records else "holds nothing"


def read_session(path: str | Path, only: frozenset[str] | None = None, function: str = ""):
    """The recording at `path` read (reader.read_log, `only` as there) if it holds a session;
    InputError naming the path and saying what the file is if not (reader.EventLog.no_session).
    `function`: the public function given `path` (recording_file)."""
    from .reader import read_any_log
    path = check_recording(path, function=function)
    log = read_any_log(path, only)
    if log.no_session:
        raise InputError(log.no_session, path)
    return log


def session_events(path: str | Path, only: frozenset[str] | None = None, function: str = ""):
    """`read_session` for a verb that needs a recording's events alone: (the EventLog, its events in file order),
    read as reader.events_of reads them (as they come: the file's records and each event's bytes are not kept;
    `EventLog.events` is empty but for a file read whole). InputError as `read_session`'s."""
    from .reader import events_of
    path = check_recording(path, function=function)
    log, events = events_of(path, only)
    if not any(type(e).__name__ == "SessionStarted" for e in events):  # (then read whole: reader.fold_log)
        raise InputError(log.no_session, path)
    return log, events


class RoundWatch:
    """What `no_whole_round` looks at, taken from a recording's events as they are read (a verb's fold:
    reader.fold_log), so nothing else of them is kept: `first`, the first SessionStarted, and `said`: that start,
    the game's first RoundEnded and its SessionEnded, in order (it stops at the first such RoundEnded, else says
    the last end). `no_whole_round(watch.said, ...)` is `no_whole_round` of every event."""

    def __init__(self) -> None:
        self.first = None
        self.said: list = []
        self.round_ended = False

    def take(self, events) -> None:
        for e in events:
            tag = type(e).__name__
            if tag not in _SAID:
                continue
            if tag == "SessionStarted":
                if self.first is None:
                    self.first = e
                    self.said.append(e)
            elif e.source == "game" and (tag == "SessionEnded" or not self.round_ended):
                self.round_ended = self.round_ended or tag == "RoundEnded"
                self.said.append(e)


_SAID = frozenset({"SessionStarted", "RoundEnded", "SessionEnded"})  # what `RoundWatch.said` keeps


def no_whole_round(events, truncated: bool = False, damaged: str = "") -> str:
    """Why the session of `events` (a recording's, in file order) has no round recorded whole, in
    words ("" if it has one: a RoundEnded of its game). `truncated`: the file is cut (reader.EventLog);
    `damaged`: what is damaged in it, in the words every verb uses (reader.EventLog.damaged: its
    damaged parts and the messages that do not decode), "" if nothing is. A damaged file is named as
    damaged, not as cut (a whole file whose chunks fail their CRC was "cut before round 1"), nor as a
    session that ended before its first round (its RoundEnded lost to the damage), whatever else it holds.

    Rounds are counted from 1, as the board shows them."""
    started = ended = None
    for e in events:
        tag = type(e).__name__
        if tag == "SessionStarted" and started is None:
            started = e
        elif getattr(e, "source", "") != "game":
            continue
        elif tag == "RoundEnded":
            return ""
        elif tag == "SessionEnded":
            ended = e
    of = f" of {started.config.rounds}" if started is not None else ""
    if ended is not None:
        how = f"{ended.reason}{f' ({ended.detail})' if ended.detail else ''}"
        where = f" in round 1{of} after {counted(ended.turns_in_round, 'turn')}" if ended.round >= 0 else " before round 1"
    if damaged:  # first: a round's end lost to the damage is no round that never ended (a new user's trial:
        # RoundEnded messages that did not decode were "the session ended (completed) before round 1")
        end = f"; its SessionEnded says {how}{where}" if ended is not None else ""
        return f"holds no whole round: the file is damaged ({damaged}), no round{of} ended in its intact parts{end}"
    if ended is not None:
        return f"holds no whole round: the session ended ({how}){where}"
    if truncated:
        return f"holds no whole round: the file is cut before round 1{of} ended"
    return f"holds no whole round: the recording stops before round 1{of} ended"
