"""The recorder: every event of a session into one MCAP file, loss bounded in time.

Rule: the recorder subscribes to `pairplay/<session>/**` and writes each
message's exact bytes to the channel of its key (replay/writer.py), after the
checks every service makes (it decodes, its key agrees with its envelope, right
session, sequence number above the last one on that key). What fails a
check is not written on a typed channel: the recorder publishes a
MessageRejected with the reason and an excerpt of the payload, and records that.
The file is flushed once its oldest unflushed message is 25 ms old (replay/writer.py),
and what waits in the inbox is taken in pieces (one lock each), a due flush done
between them at most every 5 ms (never held to a batch's end), so a SIGKILL loses
at most 0.1 s while the recorder keeps up with what arrives (`pairplay recover`
completes such a file); when it cannot, the file records how far behind a flush
was (BACKLOG_METADATA, and `max_flush_age_ms` at the end). That bound holds only for
what reached the writer: under load the writer falls behind and what waits in its inbox
(memory) would die with the process. So every message is made durable when it is received:
the thread that takes it off the bus appends it to the write-ahead journal beside the file (`<recording>.journal`,
replay/wal.py), which a thread writes to the OS every 5 ms; a SIGKILL then loses only what was
received in the last 5 ms + scheduling, whatever the backlog, and `pairplay recover` adds from
the journal what the cut file lacks, through the live checks (services/walmerge.py). The
journal is removed once the file is complete and fsync'd, in one step with the file's end that a signal
does not cut (`close`: a second Ctrl-C between them left a stale journal); a restarted recorder takes the
earlier file's journal too (`_continue`), if it is that file's (replay/wal.py `not_its`: another recording's of
the session id is left where it is, its events never merged). A close is done by its
deadline; what is still queued then is counted and recorded, not waited for. The session config, seed and software version
go into MCAP metadata ("pairplay.session") when SessionStarted passes, the
recorder's own into "pairplay.recorder". It answers restarting services with
the log so far (`pairplay/<session>/_query/recorder/log`, msgpack batches), and a
service about to leave with what it holds of each source (`.../_query/recorder/held`,
services/recorded.py): a source asked for twice while the file lacks its events is refilled at once.

A session id is taken once it has a recording: a NEW session whose recording
(`<session>.mcap` or any `<session>.<k>.mcap`) exists is refused before anything
starts (RecordingExists, `check_new_recording`); only a recorder restarted
within the same live session (`same_live_session`: the services on the bus now
sent the very events the earlier recording holds) continues it. What an earlier
recording holds is its file's readable messages and what its journal adds
(`earlier_records`): a recorder killed before its first flush leaves a file of
no message, everything it received in its journal; and a restart reads every
earlier recording of the session (`recorded_before`), as a restarted recorder's
copy of its predecessor's is neither received nor journaled. What an earlier file
lost that neither its journal nor the refill gives back (a damaged chunk, a file that
is itself a recovered one with recorded losses: `earlier_losses`) is recorded in the
new file as `pairplay recover` records a source's losses (reader.RECOVERED,
`carry_recovery`), so every verb says the session is partial; before, "this file alone
holds the whole session" was said of it, and every verb took the session as whole.
Behind a router that restarts (services/bus.py: Zenoh's advanced pub/sub recovers
what the outage held up) the recorder records each outage of its link (metadata
LINK_METADATA) and, once the link is back and Zenoh's recovery has had
`RELINK_SETTLE_S`, or at once when Zenoh reports messages lost for good, asks the
services for what they published after the last event of theirs it holds without
a gap (the restarted recorder's refill): what Zenoh could not bring back is
written then, and a RecordingGap (`earlier_file` "": this file) records it. The link is watched on
every bus, not only a recovering one (a plain bus loses what its queue held when a link closes under a
full queue, and Zenoh says nothing: test_netns lost 9 game events so, the file whole), and a jump in a
source's sequence numbers asks for the refill too. It is asked again while a hole is left (`REFILLS`,
each later and with a longer timeout: `REFILL_BACKOFF_S`), a restarted recorder's while a source of its
file on the bus has not answered (a live service busy past the ask's timeout), and what no refill gave back (the refills
given up, a service that did not answer or no longer had them, a recording closed before the refill
after an outage) is recorded when the file closes, as `pairplay recover` records a damaged file's
losses (reader.RECOVERED, `bus` "true": `_note_bus_lost`): every verb then says the session is partial.
A service that leaves the bus before the session has ended (its liveliness token
goes: a crash, a kill, its host's link) is an absence, recorded when it comes back
(metadata ABSENCE_METADATA: `service`, `left_ns`, `back_ns`, `absent_ms`) or, if it
never does, when the file closes (`back_ns` ""); tokens lost with the recorder's
own link to its router are that outage (LINK_METADATA), not absences.
"""

from __future__ import annotations

import bisect
import glob
import json
import logging
import os
from collections import Counter
import threading
import time
from pathlib import Path
from typing import Callable

import msgspec

from pairplay import __version__, signals, testpause
from pairplay.errors import OutputError
from pairplay.livelock import LIVE, hold, is_live, release
from pairplay.numbers import counted
from pairplay.outputs import REPLACED, set_aside_of, special_kind
from pairplay.replay.continued import recordings_of  # noqa: F401  (re-exported: tests, callers)
from pairplay.replay.reader import LOST_AT_KEY, RECOVERED, listed_values, carry_recovery, said_source_lost
from pairplay.replay.wal import RECORDER_METADATA, JournalWriter, NotAJournal, not_its, read_journal, wal_path
from pairplay.replay.writer import FLUSH_INTERVAL_NS, LOSS_BOUND_NS, EventLogWriter
from pairplay.schemas.checked import check_event
from pairplay.schemas.jsonfile import MCAP_MAGIC
from pairplay.schemas.events import RecordingGap, decode_event, encode_event, own_seq
from pairplay.schemas.envelope import Nanos, stamped
from pairplay.schemas.keys import alive_key, event_key, query_key, session_keys
from pairplay.schemas.trust import SOURCES

from pairplay.services.answers import sent_answers, stamp_of
from pairplay.services.bus import MISSED, HEARTBEAT_S, Bus, Deadline, Inbox, Outbox
from pairplay.services.guard import Guard, Refusals
from pairplay.services.recorded import HELD_QUERY, Held, asked_upto
from pairplay.services.runner import LOG_QUERY, SENT_QUERY
from pairplay.services.walmerge import admit

log = logging.getLogger("pairplay.recorder")
END_METADATA = "pairplay.recorder.end"  # how the recording ended (Recorder.close)
BATCH = 2000
CLOSE_S = 1.5  # Recorder.close finishes within this unless given a deadline
FINISH_S = 0.25  # of a close's time, kept to finish the file (end metadata, summary, index)
UNRECORDED_AT_EXIT = "still queued when the recording stopped"
UNREPORTED = "suggestion not reported, no RobotActed in the recording when it closed (lost on the bus, or with the bridge)"
TAKE = 256  # inbox items taken per lock (Inbox.get_many): ~3-10 ms of writing; a due flush waits at most that
BATCH_S = 0.02  # a backlog is written in batches of at most this long (step)
# a valid source's backlog the recorder keeps rather than sheds (the inbox's 64 MiB bound still holds):
# shedding loses events for sure, a backlog only if the recorder is killed before it catches up, and
# then the file records how far behind it was (a 100,000-event burst at 30-75k/s: 3-36k shed at 20,000)
PER_SOURCE = 200_000
# `pairplay run recorder`'s GIL switch interval (Python's default 5 ms): the thread that takes each event off
# the bus (its log time; a drained subscription, services/bus.py) waits at most this long for the GIL while the
# writing thread works through a backlog (best of 3 bursts, load 12-17: 0.97-1.56x the raw subscriber at 1 ms
# against 0.52-0.68x at 5 ms, with zenoh-python's callback thread; the writing thread then lags more: flushes
# 2.9-3.2 s after against 1.2-1.8 s)
RECORDER_SWITCH_S = 0.001
PIECE_FLUSH_S = 0.005  # within a batch, a flush due by age waits at most this long (step)
BACKLOG_METADATA = "pairplay.recorder.backlog"  # a flush older than the loss bound (_note_backlog)
# What a refused session id's line tells the user to do: it must name only options of the verb that
# shows it (tests/test_hints.py). NEW_SESSION_HINT names none a verb may lack (every verb that records
# has --session); `pairplay session`, which has --force, gives FORCE_SESSION_HINT (before, a recorder
# of `pairplay run recorder` refused with it, and `run` has no --force).
NEW_SESSION_HINT = "choose another --session (a recording is never replaced)"
FORCE_SESSION_HINT = "choose another --session, or --force to replace its recordings"
# a recording a live recorder holds (pairplay/livelock.py): --force cannot replace it, so no verb's hint names it
LIVE_SESSION_HINT = "choose another --session (a live session's recording is never replaced)"
JOURNAL_METADATA = "pairplay.recorder.journal"  # what a restarted recorder took from the earlier file's journal
ABSENCE_METADATA = "pairplay.recorder.absence"  # a service off the bus mid-session (_alive)
LINK_METADATA = "pairplay.recorder.link"  # an outage of the recorder's link to its router (_link)
HEAD_METADATA = "pairplay.recorder.head"  # a source's first events, sent before the recorder listened, asked for (_catch_up)
HEAD_ASKS = 3  # a source whose head did not come is asked this often (each later, as a refill: REFILL_BACKOFF_S)
LINK_SLACK_NS = 500_000_000  # a token may be reported gone this long before our own link is
RELINK_SETTLE_S = 4 * HEARTBEAT_S  # after the link is back: Zenoh's recovery first, then the refill
REFILL_QUIET_S = 3.0  # after a refill, a message repeating one refilled is skipped quietly (it was in flight)
REFILLS = 5  # a gap's refill is asked again this often while the file still has a hole below a source's last event
# each time later (RELINK_SETTLE_S doubled, at most this: ~23 s of asking in all) and with a longer timeout (at most
# REFILL_TIMEOUT_S * 2): at load 20 a service's answer came after the first ones, and the recorder gave up silently
REFILL_BACKOFF_S = 8.0
REFILL_TIMEOUT_S = 3.0
SAME_SESSION_ASKS = 3  # a restarted recorder asks a live session this often, while it is on the bus and silent
BUS_LOST = "lost on the bus"  # what the RECOVERED record of holes no refill gave back says (`_note_bus_lost`)
# what it says of the holes the recorder's own shedding at the exit left (`drain`): they came, and were counted among
# UNRECORDED_AT_EXIT (its MessageRejected count, `unrecorded_at_exit`); said once, under that cause
SHED_AT_EXIT = "shed at the exit"
# and of those a full inbox shed mid-session (a flood: Inbox.put, counted as its MessageRejected "inbox full" count)
# that no refill gave back: they came, and were counted there; said once, under that cause, as the exit's are
SHED_LIVE = "shed by its full inbox"
SHED_NOTED = 1_000_000  # shed seqs kept to say a hole's cause (`_take_shed`); past them a hole is said as the bus's


_stamp = stamp_of  # what a shed message's hole needs of it: its source and seq (a full decode cost 6x)
_REFILL = object()  # inbox control item: Zenoh reported messages lost for good


def latest_file(path: Path) -> Path | None:
    """The newest existing file of a session: `path` or its highest `<stem>.<n>.mcap`."""
    found = recordings_of(path)
    return found[-1] if found else None


def free_path(path: Path) -> Path:
    """`path`, or `<stem>.<n>.mcap` past every existing one: a recording is never overwritten
    (a recorder restarted after a crash must not destroy what the crash left)."""
    latest = latest_file(path)
    if latest is None:
        return path
    n = 1 if latest == path else int(latest.name[len(path.stem) + 1:len(latest.name) - len(path.suffix)]) + 1
    while wal_path(path.with_name(f"{path.stem}.{n}{path.suffix}")).exists():  # nor a journal
        n += 1
    return path.with_name(f"{path.stem}.{n}{path.suffix}")


class RecordingExists(OutputError):
    """A NEW session's recording (`<session>.mcap` or a `<session>.<k>.mcap`) is there already: the
    session id is taken. Only a recorder restarted within the same live session continues a file
    (Recorder's `restart`); a new session with that id would be recorded into the old session's file,
    its start refused as a repeat (the hang of the new-user trial)."""

    def __init__(self, existing: Path, session: str, hint: str = NEW_SESSION_HINT, live: bool = False):
        what = "a recording already" if not existing.name.endswith(".journal") else \
            "a recorder's journal already, its recording gone (what a recorder that did not finish received)"
        if live:  # no --force in the hint: nothing replaces a live recording (pairplay/livelock.py)
            what, hint = f"a recording that {LIVE}", LIVE_SESSION_HINT
        elif existing.name.endswith(REPLACED):  # --force or not: the only copy of an earlier recording
            original = existing.name[:-len(REPLACED)]
            what = ("a recording set aside by a `session --force` that was cut short before it settled (killed, or "
                    "a second Ctrl-C): it may be the only copy of the earlier session")
            hint = f"give it its name back (mv {existing.name} {original}{standing(existing.with_name(original))}) or remove it"
        super().__init__(f"session {session} has {what}; {hint}", existing)
        self.existing, self.live = existing, live
        self._has, self._hint = what, hint

    def in_python(self) -> None:
        """The words of the Python API (pairplay/arguments.py python_words): run_session's `path`, not a
        session id, names the file (`SessionConfig(session="a")` to "r3.mcap" was "session r3 has a recording
        already; choose another --session"), and a function has no --session."""
        self.what = f"the path given has {self._has} ({self.existing.name}); {self._hint.replace('--session', 'path')}"


def standing(original: Path) -> str:
    """", after removing X and its journal X.journal" (what of them is there; "" if nothing): what stands where a
    file set aside (*.replaced) gets its name back. The journal is named: left beside the earlier file, it is
    another recording's, and `pairplay recover` took it for the file's (a new user's trial: "after removing what
    stands there" was followed, the journal left)."""
    there = [p for p in (original, wal_path(original)) if p.exists()]
    if not there:
        return ""
    names = there[0].name if len(there) == 1 else f"{there[0].name} and its journal {there[1].name}"
    return f", after removing {names}"


def journals_of(path: Path) -> list[Path]:
    """The write-ahead journals (replay/wal.py) of a session's recordings, `path`'s and every
    `<stem>.<k>.mcap`'s, whether or not the recording is still there."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    found = [wal_path(path)] + sorted(path.parent.glob(f"{glob.escape(path.stem)}.*{glob.escape(path.suffix)}.journal"))
    return [p for p in found if p.exists()]


def check_not_folders(path: str | Path) -> None:
    """OutputError naming it if the recording `path`, one of its `<stem>.<k>.mcap`, a journal or a file set
    aside of the session is a folder, a device, a pipe, a socket or a link (outputs.special_kind): it is no
    recording, and not pairplay's to replace or rename, --force or not. Called before anything starts:
    `session --force` ran the whole session, then exited 2, the folder renamed `<id>.mcap.replaced`; without
    --force it said "has a recording already; --force replaces it", which did not."""
    path = Path(path)
    for p in [path, *recordings_of(path), *journals_of(path), *set_aside_of(path)]:
        kind = special_kind(p)  # a device, pipe, socket or link: `session --force` renamed it aside, then removed it
        if p.is_dir() or kind:  # which file it stands for, by its name (a `.replaced` was called the recording)
            what = (f"`session --force` keeps the earlier recording (named *{REPLACED})" if p.name.endswith(REPLACED)
                    else "a killed recorder's journal is kept" if p.name.endswith(".journal")
                    else "the session's recording is written")
            kind = kind or "a folder"
            raise OutputError(f"is {kind} where {what}; only a regular file is ever replaced or renamed, --force or "
                              "not: remove or rename it", p)


def check_new_recording(path: str | Path, hint: str = NEW_SESSION_HINT, set_aside_too: bool = True) -> Path:
    """`path` for a new session's recording, refused (RecordingExists, naming the file) if the session
    has a recording already, or a recording's journal (what a killed recorder received), a live one
    with LIVE_SESSION_HINT (call it before anything starts, after every other check of the options).
    `session --force` sets them aside instead (`set_aside`): nothing removes them before the new
    recording holds a session; one a cut-short --force left set aside keeps the id taken too
    (`set_aside_too`)."""
    path = Path(path)
    check_not_folders(path)
    existing = recordings_of(path) + journals_of(path)
    live = [p for p in existing if is_live(p)]
    if live:
        raise RecordingExists(live[0], path.stem, live=True)
    # named first: the one file whose loss --force would not undo; not by the Recorder (`set_aside_too`
    # False), which a running `session --force` makes beside the files it has just set aside itself
    aside = set_aside_of(path) if set_aside_too else []
    if aside:
        raise RecordingExists(aside[0], path.stem)
    if existing:
        raise RecordingExists(existing[0], path.stem, hint)
    return path


def set_aside(path: str | Path) -> list[tuple[Path, Path]]:
    """`session --force`: the session's recordings and journals renamed `<name>.replaced` (no longer the
    session's: the new recording takes `path`), as (original, aside) pairs; refused as
    `check_new_recording` refuses one a live recorder holds. They are kept until the new recording holds
    a session (`settle_aside`): a session stopped before its game started (a Ctrl-C while it waited for
    its services) gives them back, as `study --force` and `rebuild --force` keep their old outputs until
    the new ones are complete (before, --force removed them first, and such a stop lost them)."""
    path = Path(path)
    check_not_folders(path)  # (the caller checked before its work; a folder made meanwhile is not renamed either)
    existing = recordings_of(path) + journals_of(path)
    live = [p for p in existing if is_live(p)]
    if live:
        raise RecordingExists(live[0], path.stem, live=True)
    left = set_aside_of(path)  # an earlier --force cut short: renaming onto it would lose the earlier session
    if left:
        raise RecordingExists(left[0], path.stem)
    aside = []
    for p in existing:
        kept = p.with_name(p.name + REPLACED)
        os.replace(p, kept)
        aside.append((p, kept))
    return aside


def earlier_outputs(path: str | Path) -> list[str]:
    """What other verbs made of an earlier session's recordings that stays beside `path`, the new session's, in
    words ("X.recovered.mcap, recover's output of the earlier session"): `pairplay recover`'s copies
    (`<stem>.recovered.mcap`, `<stem>.<k>.recovered.mcap`, recovered again) and `pairplay view`'s default
    output (`<stem>.rrd`). `session --force` replaces the session's recordings and their journals, never the
    user's outputs (a new user's trial: recover's copy stayed beside the new file, unnamed); said once a new
    session is recorded, when nothing of the new one can have made them yet."""
    path = Path(path)
    stem = glob.escape(path.stem)
    recovered = sorted(path.parent.glob(f"{stem}.recovered.mcap")) + sorted(
        path.parent.glob(f"{stem}.*.recovered.mcap"))
    views = sorted(path.parent.glob(f"{stem}.rrd"))
    return ([f"{p.name}, recover's output of the earlier session" for p in dict.fromkeys(recovered)]
            + [f"{p.name}, view's output of the earlier session" for p in views])


def settle_aside(aside: list[tuple[Path, Path]], path: str | Path, replaced: bool | None) -> None:
    """The end of `set_aside`: `replaced` (the new recording holds a session), the earlier files are
    removed; False, the new recording and its journal, which hold no session, are removed and the earlier
    files get their names back; None (not known: a second Ctrl-C cut the shutdown short), both are kept."""
    if replaced is None:
        return
    if replaced:
        for _, kept in aside:
            kept.unlink(missing_ok=True)
        return
    if not aside:
        return
    for p in recordings_of(Path(path)) + journals_of(Path(path)):
        if not is_live(p):
            p.unlink(missing_ok=True)
    for original, kept in aside:
        if kept.exists() and not original.exists():
            os.replace(kept, original)


def earlier_records(earlier: Path, session: str, before: list[tuple[str, bytes, int]] = (), say: bool = True
                    ) -> tuple[list[tuple[str, bytes, int]], dict | None, dict]:
    """What an earlier recording of `session` holds: every readable message of the file (a crash may
    have cut it: what was read before the cut) as (key, payload, log_time_ns) in file order, then
    what its journal (`<earlier>.journal`, replay/wal.py) holds that the file lacks, decided by the
    live checks as `pairplay recover` decides it (services/walmerge.py; refusals included); the
    journal's account (JOURNAL_METADATA's fields), or None if no journal is beside it; and what the
    file lost that its journal does not give back (`earlier_losses`: {} if nothing). A recorder
    killed before its first flush leaves a file of no message: all it received is in its journal.
    `before`: what the session's recordings older than `earlier` hold (`recorded_before`), which
    the journal's records are checked after, as the live recorder checked them. `say`: log what is not read or
    taken (False for a look that the continuing recorder's own reading follows: `recorded_before`)."""
    from mcap.records import Channel, Message
    warn, inform = (log.warning, log.info) if say else (_unsaid, _unsaid)
    from pairplay.replay.mcapscan import scan
    topics: dict[int, str] = {}
    held: list[tuple[str, bytes, int]] = []
    try:
        checked = scan(earlier)
    except OSError as err:  # gone or unreadable since it was listed: nothing of it is held
        warn("recorder: %s is not read: %s", earlier, err)
        return held, None, {}
    records = checked.summary_records + checked.records
    at_message: list[int] = []  # for each record, how many messages of the file come before it
    for record in records:
        at_message.append(len(held))
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message) and record.channel_id in topics:
            held.append((topics[record.channel_id], record.data, record.log_time))
    if checked.truncated:  # the cut of a crashed file: everything before it is kept
        inform("recorder: %s ends early (%s); %d messages read", earlier, checked.describe(), len(held))
    beside = wal_path(earlier)
    journal, account, added = None, None, []
    if beside.exists():
        try:
            journal = read_journal(beside)
        except (NotAJournal, OSError) as err:
            warn("recorder: the journal %s is not read: %s", beside, err)
            account = {"earlier_journal": beside.name, "not_read": str(err)}
        else:
            # another recording's (of the session id, not of this file) is never taken: its events are not the file's
            other = (f"of session {journal.session!r}" if journal.session != session
                     else not_its(journal, next((dict(r.metadata) for r in checked.metadata_records
                                                 if r.name == RECORDER_METADATA), {})))
            if other:
                warn("recorder: the journal %s is not taken: %s (it is left there)", beside, other)
                account = {"earlier_journal": beside.name, "not_read": other}
                journal = None
            else:
                admitted = admit(session, [(k, p) for k, p, _ in (*before, *held)], journal.records)
                added = [(k, p, ns) for k, p, ns, _seq in admitted.items]
                account = {"earlier_journal": beside.name, "taken": str(admitted.taken),
                           "refused": str(admitted.refused), "torn": journal.torn}
    lost = earlier_losses(earlier, checked, records, at_message, held, journal, added)
    return held + added, account, lost


def earlier_losses(earlier: Path, checked, records: list, at_message: list[int], held: list[tuple[str, bytes, int]],
                   journal, added: list[tuple[str, bytes, int]]) -> dict[str, str]:
    """What an earlier recording lost that its journal does not give back, as `pairplay recover` records a damaged
    file's losses (the RECOVERED metadata's fields, reader.carry_recovery's format; {} if it lost none): its
    damaged parts that lost messages, and, if it is itself a recovered file (renamed into the session), the
    losses its record carries. Each loss is placed by the message read after it ((key, payload); None at the
    file's end: `_marks`), which the continuing recorder turns into its own count (`Recorder._continue`). A part's
    loss is given back only when the journal beside the file (every message its recorder received, in order)
    holds what it held and the live checks took it (`added`): the records received between the messages read
    around the part that the file lacks. A part in the middle is not: the live checks refuse its events as out of
    order after the later ones the file holds (recorded as refusals, not events). A damage that lost no message
    (an index, a CRC) is no loss."""
    from pairplay.replay.reader import folded_recovery, recovered_losses, recovered_lost
    order: dict[tuple[str, bytes], int] = {}  # each journal record's first place (received order)
    for i, r in enumerate(journal.records if journal is not None else ()):
        order.setdefault((r[0], r[1]), i)
    in_file = {(k, p) for k, p, _ in held}
    taken = {(k, p) for k, p, _ in added}

    def message_at(index: int) -> tuple[str, bytes] | None:
        n = at_message[index] if index < len(at_message) else len(held)
        return held[n][:2] if n < len(held) else None

    def given_back(at: int, count: int | None) -> bool:
        """The journal holds what the part held and it was taken: the records received between the messages
        read around it (all of the journal's after the last read before it, for a part at the end of a journal
        not torn) that the file lacks, as many as the part held if that is known, every one in the copy."""
        if journal is None:
            return False
        n = at_message[at] if at < len(at_message) else len(held)
        before, after = (held[n - 1][:2] if n else None), message_at(at)
        if (before is not None and before not in order) or (after is not None and after not in order) or (
                after is None and journal.torn):
            return False
        start, end = order[before] + 1 if before is not None else 0, order[after] if after is not None else len(journal.records)
        between = [(r[0], r[1]) for r in journal.records[start:end] if (r[0], r[1]) not in in_file]
        return (count is None or len(between) >= count) and all(x in taken for x in between)

    own = [(len(checked.summary_records) + at, n) for at, n in checked.losses()]
    parts, marks = [], []
    lost_parts = [d for d in checked.damage if d.lost_at >= 0]
    for d, (at, n) in zip(lost_parts, own):
        if given_back(at, n):
            continue  # its journal gave back what the part held
        parts.append(d)
        marks.append(message_at(at))
    recovered = folded_recovery(records)
    carried = recovered_lost(recovered)
    if carried:  # the losses a recovered file's record carries, where they fall among its records
        marks += [message_at(i) for i in (recovered_losses(records, own, recovered) or [len(records)])]
    if not parts and not carried:
        return {}
    # (its cut, if a crash left one, is not what is recorded: its journal and the refill give that back)
    mine = {"source": earlier.name, "truncated": "false", "data_complete": "true", "reason": checked.describe(),
            "damaged": json.dumps([str(d) for d in parts]), "lost": json.dumps([f"{d.part}: {d.lost}" for d in parts]),
            "lost_chunks": str(sum(1 for c in checked.lost_chunks if any(d.offset == c.offset for d in parts))),
            "continued": "copied by a restarted recorder, which records what its predecessor lost"}
    if not parts:
        mine["damaged"] = mine["lost"] = "[]"
    folded = carry_recovery(recovered, mine) if carried else mine
    folded["_marks"] = marks  # where each loss was, by the message read after it (popped by Recorder._continue)
    return folded


def _unsaid(*_args) -> None:
    """A log call not made (`earlier_records`'s `say`)."""


def recorded_before(path: Path, session: str, until: Path | None = None, say: bool = True
                    ) -> tuple[list[tuple[str, bytes, int]], list[dict], list[dict]]:
    """What the session's recordings at `path` hold together (`recordings_of`, oldest first up to
    `until` if given, each read by `earlier_records`), each message once (a restarted recorder's file
    starts with copies of its predecessor's, byte for byte), the account of every journal read
    (JOURNAL_METADATA's fields) and what each file lost that its journal does not give back
    (`earlier_losses`). Returns ([(key, payload, log_time_ns)], [account], [losses]). The newest file alone
    is not enough: a restarted recorder's copy reaches its disk only at its flushes and is not in
    its journal (which holds what it received), so killed before its first flush it leaves only
    what came live, and the older files still hold the rest. `say`: as `earlier_records`'s."""
    held: list[tuple[str, bytes, int]] = []
    seen: set[tuple[str, bytes]] = set()
    journals, losses = [], []
    for earlier in recordings_of(path):
        records, journal, lost = earlier_records(earlier, session, held, say)
        for key, payload, log_ns in records:
            if (key, payload) not in seen:
                seen.add((key, payload))
                held.append((key, payload, log_ns))
        if journal is not None:
            journals.append(journal)
        if lost:
            losses.append(lost)
        if earlier == until:
            break
    return held, journals, losses


def same_live_session(bus: Bus, session: str, path: Path, timeout_s: float = 3.0,
                      stop: threading.Event | None = None) -> bool:
    """Whether the services of `session` on the bus now are the ones its recordings at `path` recorded:
    each one that answers (SENT_QUERY) sent, under the sequence number of its first event in them (the
    files and what their journals add: `recorded_before`), the very bytes they hold (a ServiceStarted
    carries its service's start time, so a new session that reuses the id differs). False if the
    recording holds no event of another service, or nobody answers. Nobody answering while a service of the
    session is on the bus (its token) is asked again (SAME_SESSION_ASKS, each ask longer): a live service
    busy past the ask's timeout (load 40-66) had the restarted recorder refuse its own session; with none on
    the bus the refusal is at once. `stop` set: no more asks. Several sessions answering as one source are
    weighed by `_same_answers` (an empty answer never outvotes the source's bytes: trial34 O)."""
    first: dict[str, tuple[int, bytes]] = {}
    # (unsaid: a recorder that continues reads them again and says what it does not take; said here too, each
    # warning came twice)
    for key, data, _ in recorded_before(path, session, say=False)[0]:
        source = key.split("/")[2] if key.count("/") == 3 else ""
        if source and source != Recorder.name:
            try:
                seq = decode_event(data).seq
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
            if source not in first or seq < first[source][0]:
                first[source] = (seq, data)
    if not first:
        return False
    after = ",".join(f"{s}:{seq - 1}" for s, (seq, _) in sorted(first.items()))
    for ask in range(SAME_SESSION_ASKS):
        answers = sent_answers(bus.query_replies(f"{query_key(session, '*', SENT_QUERY)}?after={after}",
                                                 timeout_s * min(2, 1 + ask), stop, with_key=True))
        same = _same_answers(first, answers)
        if same is not None:
            return same
        if stop is not None and stop.is_set():
            return False
        if not bus.alive_now(alive_key(session, "*"), stop=stop) - {alive_key(session, Recorder.name)}:
            return False  # nobody of the session on the bus: nobody to wait for
    return False


def _same_answers(first: dict[str, tuple[int, bytes]], answers) -> bool | None:
    """What the answers (services/answers.py `Sent`) say of the recordings whose first event of each source is
    `first`: True if a source sent those very bytes under that seq; False if a source answered and none of its
    answers holds them (a new session under the id: its service has other bytes there, or none); None if no
    source of the file answered. A source whose answers differ at that seq (one sent the file's bytes, another
    other bytes) counts as not answering: one of them is not the source (said, a warning naming both); an empty
    answer beside one that holds the bytes is no answer, never a "no" (trial34 O, addendum: a forger's empty
    answer made the restarted recorder refuse its own live session)."""
    verdict = None
    for name, (seq, data) in sorted(first.items()):
        given = {(replier, p) for replier, source, items in answers.replies if source == name
                 for _, p in items if _seq_of(p) == seq}
        if not any(source == name for _, source, _ in answers.replies):
            continue  # a service that joined after the earlier file stopped: nothing to compare
        if any(p == data for _, p in given) and any(p != data for _, p in given):
            log.warning("recorder: forged answer: sessions %s answered as %s with other bytes at seq %d than %s, "
                        "which sent the recording's: one of them is not %s's; its answer not taken",
                        ", ".join(sorted({r for r, p in given if p != data})), name, seq,
                        ", ".join(sorted({r for r, p in given if p == data})), name)
            continue
        if any(p == data for _, p in given):
            verdict = True if verdict is None else verdict
        else:
            return False
    return verdict


def _seq_of(data: bytes) -> int | None:
    try:
        return _stamp(data).seq
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None


def _runs(first: int, last: int, marked: list[tuple[int, str]]) -> list[tuple[int, int, str]]:
    """seqs `first`..`last` as maximal runs (a, b, the cause they are `marked` with, "" for none: `marked` is
    (seq, cause), sorted, each seq within the range and once), in order; as many steps as `marked` has, whatever
    the range (a forged seq may leave a hole of billions)."""
    out: list[tuple[int, int, str]] = []
    at = first
    for q, cause in marked:
        if q > at:
            out.append((at, q - 1, ""))
        if out and out[-1][2] == cause and out[-1][1] == q - 1:
            out[-1] = (out[-1][0], q, cause)
        else:
            out.append((q, q, cause))
        at = q + 1
    if at <= last:
        out.append((at, last, ""))
    return out


def _shed_stamp(key: str, payload: bytes) -> tuple[str, int] | None:
    """(source, seq) of a message the recorder shed, if its payload says the source its key names; else None."""
    source = key.split("/")[2] if key.count("/") == 3 else ""
    try:
        stamp = _stamp(payload)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None
    return (source, stamp.seq) if stamp.source == source and source else None


def _holes(seen: dict[str, set[int]]) -> dict[str, list[tuple[int, int]]]:
    """Per source with a hole, each (a, b): seqs a and b are held, none between (a source's events before its
    first one held are not counted: a recorder that joined late never had them)."""
    out: dict[str, list[tuple[int, int]]] = {}
    for source, seqs in seen.items():
        ordered = sorted(seqs)
        found = [(a, b) for a, b in zip(ordered, ordered[1:]) if b > a + 1]
        if found:
            out[source] = found
    return out


def _missing(seqs: set[int]) -> list[tuple[int, int]]:
    """The seqs missing from 1 up to the highest of `seqs`, as (first, last) runs (a source's head too: what it
    published before the recorder listened, while it is not caught up)."""
    out, at = [], 1
    for q in sorted(seqs):
        if q > at:
            out.append((at, q - 1))
        at = q + 1
    return out


def finished_whole(path: str | Path) -> bool:
    """Whether the recording at `path` was finished by its recorder (Recorder.close): its end written (the
    file ends with MCAP's magic) and no journal beside it (removed in the same step as the end's fsync). What
    a verb says of a recording after a second signal cut its shutdown (cli/session.py `cut_line`): read from
    the disk, not from what the cut shutdown got to note."""
    path = Path(path)
    if wal_path(path).exists():
        return False
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() < 2 * len(MCAP_MAGIC):
                return False
            f.seek(-len(MCAP_MAGIC), os.SEEK_END)
            return f.read() == MCAP_MAGIC
    except OSError:
        return False


def finished_count(path: str | Path) -> int | None:
    """The number of messages (events) a recording `finished_whole` holds, as its end (MCAP's statistics) says;
    None if it cannot be read. What a verb's line after a second signal counts (cli/session.py `cut_line`):
    from the disk, the same for every verb (the summary a cut shutdown got to fill had it for `session` and
    not for `lab`: a new user's trial)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            statistics = make_reader(f).get_summary().statistics
    except Exception:  # (mcap raises its own errors, and AttributeError for a summary without statistics)
        return None
    return None if statistics is None else statistics.message_count


def _fsync(path: Path) -> None:
    """Push a closed file's data to the disk (before its journal goes)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class RecordingFailed(Exception):
    """The recorder could not write its file (disk full, file size limit, a writer error)."""

    def __init__(self, reason: str, path: Path | None = None):
        super().__init__(reason)
        self.reason, self.path = reason, path


class Recorder:
    name = "recorder"

    def __init__(self, bus: Bus | None, session: str, path: str | Path, *, clock: Callable[[], int] = time.time_ns,
                 flush_interval_ns: int = FLUSH_INTERVAL_NS, on_failure: Callable[[str], None] | None = None,
                 restart: bool = False):
        """A recorder of a NEW session refuses (RecordingExists) a `path` the session has recordings at
        (`check_new_recording`); one `restart`ed within the same live session (`same_live_session`)
        continues the newest of them in a file of its own (`free_path`)."""
        earlier = latest_file(Path(path)) if restart else None
        base = Path(path)
        if earlier is not None and is_live(earlier):  # its recorder still writes it: this would be a second
            raise RecordingExists(earlier, session, live=True)  # one, each recording what the other lacks
        if not restart:  # (the verbs check what a cut-short --force set aside before they start: cli/session.py)
            check_new_recording(path, set_aside_too=False)
        self.bus, self.session, self.path, self.clock = bus, session, free_path(Path(path)), clock
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:  # the file is ours (created, not found) and locked for our life (pairplay/livelock.py)
            self._hold: int | None = hold(self.path, create=True)
        except FileExistsError:  # made since the check: another recorder of this id started with us
            raise RecordingExists(self.path, session, live=is_live(self.path)) from None
        try:
            self.on_failure = on_failure
            self.failure: str | None = None  # why the file stopped being written
            self.writer = EventLogWriter(self.path, flush_interval_ns=flush_interval_ns)
        except BaseException:
            self.release()
            raise
        self.started_ns = clock()  # in the file's metadata and its journal's header: which file a journal is of
        self._guarded(self.writer.add_metadata, RECORDER_METADATA,
                      {"session": session, "software_version": __version__, "started_ns": str(self.started_ns)})
        self.journal: JournalWriter | None = None  # made by start (a recorder on a bus)
        self._journal_add = None
        self.inbox = Inbox(clock=clock, per_source=PER_SOURCE)
        self.outbox = Outbox(bus, self.name) if bus is not None else None
        # its own refusals are written directly (_publish); it writes the bytes it checked and needs
        # only their envelope: the checked twin of each event (schemas/checked.py), not the event
        # the whole session, in each publisher's order unless the bus recovers an outage per key (guard.py `whole`)
        self.guard = Guard(session, own=self.name, decode=check_event, whole=bus is None or not bus.options.recovers)
        self.refusals = Refusals()
        self.kept: list[tuple[str, bytes]] = []
        self.seq = 0
        self.ended = False
        self.holds_session = False  # a SessionStarted was written (`pairplay run recorder`: else its line says so)
        self.whole = False  # its end written and on disk, its journal removed (close)
        self._lock = threading.Lock()
        self._overlap = 0
        self._backlog_noted_ns = -10**18
        self.continued: dict | None = None
        # a restarted recorder's refill asked again for the sources that did not answer yet (`refill`): what the
        # asks so far gave (resumed_ns, refilled, answered), until its RecordingGap is recorded
        self._continuing: dict | None = None
        self._earlier_lost: dict | None = None  # what the earlier recordings lost, until recorded (_note_earlier_lost)
        self._link_lost_ns: int | None = None  # when the link to the router went, until the refill after it
        self._refill_at: float | None = None  # monotonic time of the next refill (relink), if one is due
        self._quiet_until_ns = 0
        self._link_down = False
        self._refills_left = REFILLS
        self._asked: set[str] = set()  # sources a `held` question found lacking (_answer_held): asked again, refilled
        self._outage_pending = False  # a link outage no refill has been answered after yet (its tail not known)
        self._last_seq: dict[str, int] = {}  # per source, its highest seq written (a jump past it: a hole, refilled)
        # per source first heard past its seq 1 (it published before this recorder listened): its first live seq and
        # the asks left, until its head is held (`_catch_up`)
        self._heads: dict[str, list[int]] = {}
        self._forged: set[tuple] = set()  # answers that differ, recorded once each though asked again (`_undisputed`)
        self._disputed: set[tuple[str, int]] = set()  # (source, seq) two answers gave differently: taken from nobody
        self._head_at: float | None = None  # monotonic time of the next ask for a head, if one is due
        self._recv_ns: dict[str, int] = {}  # per source, when its latest event was taken (a tail lost: `_tails`)
        self._back_ns = 0  # when the link to the router last came back from an outage
        self._earlier_recorded = False  # what the earlier recordings lost is recorded in the file (_note_earlier_lost)
        self._copied_top: dict[str, int] = {}  # per source, its highest seq copied from the earlier recordings
        self._shed_at_exit: list[tuple[str, bytes]] = []  # (key, payload) `drain` shed: their holes are not the bus's
        self._shed_live: dict[str, set[int]] = {}  # per source, the seqs its full inbox shed (`_take_shed`): nor these
        self._shed_live_n = 0
        self.inbox.shed_items = []  # (what it sheds kept for `_take_shed`)
        self._held: dict[str, set[int]] = {}  # per source but ours, the seqs written (`_seen`: none decoded again)
        self.links: list[dict] = []  # the outages recorded (LINK_METADATA)
        self._ended_ns: int | None = None
        self._absent: dict[str, int] = {}  # service -> when its token went, until it is back (_alive)
        self.absences: list[dict] = []  # recorded (ABSENCE_METADATA)
        if earlier is not None:
            self._continue(base, earlier)

    def release(self) -> None:
        """Let go of the recording's lock (pairplay/livelock.py); close does it last."""
        if self._hold is not None:
            release(self._hold)
            self._hold = None

    # -- a restarted recorder: continue the session's record ----------------
    def _continue(self, base: Path, earlier: Path) -> None:
        """Copy every event the session's earlier recordings hold (`recorded_before`: each file's
        readable messages, a crash may have cut it, then what its journal adds: the inbox its recorder
        died with; `earlier` is the newest) into this one, so this file alone holds the whole session;
        what each journal gave is counted (metadata JOURNAL_METADATA). The journals are left where they are."""
        held, journals, losses = recorded_before(base, self.session, until=earlier)  # (not this file, made already)
        copied, last_ns = 0, 0
        first = {}  # each message's first place in the copy: where a loss before it is marked
        for i, (key, payload, _) in enumerate(held):
            first.setdefault((key, payload), i)
        written = []  # messages in this file before each of `held` was copied
        for key, payload, log_ns in held:
            written.append(len(self.kept))
            if self._copy(key, payload, log_ns):
                copied += 1
                last_ns = max(last_ns, log_ns)
        if losses:  # what the earlier files lost that no journal gives back: recorded as recover records it
            # a later file that continued an earlier one carries its losses already (named in its `earlier`)
            carried = {Path(e).name for one in losses for e in listed_values(one.get("earlier"))}
            losses = [one for one in losses if Path(one.get("source", "")).name not in carried]
            lost: dict = {}
            marks = []
            for one in losses:
                marks += one.pop("_marks")
                lost = carry_recovery(lost, one)
            lost[LOST_AT_KEY] = json.dumps(sorted(
                written[first[m]] if m is not None and m in first else len(self.kept) for m in marks))
            lost["messages"] = str(len(self.kept))
            self._earlier_lost = lost
            if self.bus is None:  # no refill to come (with a bus, `refill` records it: the services may give it back)
                self._note_earlier_lost(False)
        for journal in journals:
            self._guarded(self.writer.add_metadata, JOURNAL_METADATA, journal)
            log.info("recorder: %s events taken from %s (%s refused)", journal.get("taken", 0),
                     journal["earlier_journal"], journal.get("refused", 0))
        self._copied_top = {source: max(seqs) for source, seqs in self._held.items()}
        self.continued = {"earlier_file": earlier.name, "copied": copied, "last_copied_ns": last_ns}
        log.info("recorder: continuing %s (%d events) in %s", earlier, copied, self.path)

    def _note_earlier_lost(self, refilled: bool) -> None:
        """Record what the earlier recordings lost (`_continue`), unless the refill gave it back: `refilled`, every
        source in the file answered it, and no source's sequence numbers in the file (the recorder's own too: its
        refusals are asked of nobody) have a hole left below their last (the lost events came back by `record`
        or `_fill_hole`: counting only the holes filled missed those above the last one of their key)."""
        lost, self._earlier_lost = self._earlier_lost, None
        if not lost:
            return
        seen = self._seen()
        with self._lock:
            seen[self.name] = {own_seq(p) for k, p in self.kept if k.split("/")[2] == self.name}
        holes = any(seqs and len(seqs) < max(seqs) for seqs in seen.values())
        if refilled and not holes:
            log.info("recorder: what the earlier recording lost was refilled by the services")
            return
        self._guarded(self.writer.add_metadata, RECOVERED, lost)
        self._earlier_recorded = True  # its holes are said there: not again as the bus's (`_note_bus_lost`)
        log.warning("recorder: continuing a session whose earlier recording lost messages: %s", said_source_lost(lost))

    def _copy(self, key: str, payload: bytes, log_time_ns: int) -> bool:
        source = key.split("/")[2] if key.count("/") == 3 else ""
        if source != self.name:
            return self.record(key, payload, log_time_ns, quiet=True)
        event = decode_event(payload)  # our own earlier refusals and gaps: kept as they are
        self._guarded(self.writer.write, key, payload, log_time_ns=log_time_ns, sequence=event.seq)
        self.guard.note(key, event)
        self.seq = max(self.seq, event.seq)
        with self._lock:
            self.kept.append((key, payload))
        return True

    def _seen(self) -> dict[str, set[int]]:
        """Per source, the sequence numbers the file holds (kept as they are written: `record`, `_fill_hole`;
        before, every event in the file was decoded again for each refill and the close)."""
        return {source: set(seqs) for source, seqs in self._held.items()}

    def _contiguous(self, seen: dict[str, set[int]] | None = None) -> dict[str, int]:
        """Per source, the last sequence number up to which the file has every event (a source's
        events published before any recorder listened are asked for too)."""
        seen = self._seen() if seen is None else seen
        out = {}
        for source, seqs in seen.items():
            n = 0
            while n + 1 in seqs:
                n += 1
            out[source] = n
        return out

    def refill(self, timeout_s: float | None = None, since_ns: int | None = None) -> None:
        """Ask every service for what it published after the file's last event of it without a gap
        (a restarted recorder: the earlier file's), write that, then record the gap (RecordingGap).
        `since_ns`: a gap in this file's own stream (the link to the router was down from then, or
        Zenoh reported messages lost): recorded only if something had to be refilled."""
        if (self.continued is None and since_ns is None) or self.bus is None:
            return
        resumed_ns = self.clock()
        tries = REFILLS - self._refills_left  # asked again: a loaded service may answer late (REFILL_BACKOFF_S)
        timeout_s = timeout_s if timeout_s is not None else REFILL_TIMEOUT_S * min(2, 1 + tries)
        seen = self._seen()
        sources = self._contiguous(seen)
        after = ",".join(f"{s}:{n}" for s, n in sorted(sources.items()))
        refilled = 0
        answers = sent_answers(self.bus.query_replies(f"{query_key(self.session, '*', SENT_QUERY)}?after={after}",
                                                      timeout_s, with_key=True),
                               lambda err: log.warning("recorder: unreadable refill: %s", err), self._foreign)
        answered = answers.answered
        for key, data in self._undisputed(answers):  # (two that differ: neither; the seq stays a hole, said)
            try:
                event = decode_event(data)
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
            if self.record(key, data, self.clock(), quiet=True):
                refilled += 1
            elif event.seq not in seen.get(event.source, ()) and self._fill_hole(key, data):
                refilled += 1  # below what came live on its key since: a hole Zenoh did not close
            seen.setdefault(event.source, set()).add(event.seq)
        self._overlap = len(self.inbox)  # what came meanwhile may repeat the refill: no rejections for that
        self._quiet_until_ns = self.clock() + int(REFILL_QUIET_S * 1e9)  # nor for what was still on its way
        if since_ns is not None:
            if answered and not self._link_down:
                self._outage_pending = False  # what each answer holds is known; a hole left is counted at the close
            log.info("recorder: after the gap from %d, %d events refilled from %s", since_ns, refilled,
                     ", ".join(answered) or "nobody")
            # every source with a hole, answered or not (one that did not answer in time under load may next time:
            # before, only those that answered were asked again, and a hole of one that had not stayed unasked)
            # (a head not held, of a source that joined before the recorder, only of one that answers: it had none)
            between = _holes(seen)
            holes = [src for src, n in self._contiguous(seen).items()
                     if src in between or (src in answered and n < max(seen[src]))]
            if holes and self._refills_left > 0:  # what was still on its way when they answered: ask again
                self._refills_left -= 1
                self._refill_at = time.monotonic() + min(REFILL_BACKOFF_S, RELINK_SETTLE_S * 2 ** tries)
                self._link_lost_ns = since_ns
            else:
                if holes:  # given up: the file records the holes when it closes (`_note_bus_lost`), never silently
                    log.warning("recorder: holes left after %d refills in %s: recorded as lost when the file closes",
                                REFILLS + 1, ", ".join(holes))
                self._refills_left = REFILLS
            if not refilled:
                return answered  # Zenoh brought everything back: the outage is in LINK_METADATA
            gap = RecordingGap(earlier_file="", copied=0, last_copied_ns=Nanos(since_ns), resumed_ns=Nanos(resumed_ns),
                               refilled=refilled, refilled_from=sorted(answered),
                               unanswered=sorted(set(sources) - set(answered)))
            self._publish([gap])
            return answered
        # a restarted recorder's refill: a source of the file that did not answer, on the bus, is asked again (`REFILLS`, each
        # later and longer, as after an outage); one RecordingGap says what all the asks gave. Before, one ask of
        # REFILL_TIMEOUT_S decided: at load 40-66 a live service answered after it, and what it would have given
        # back (the events of the predecessor's damaged chunk, the gap's) was recorded as lost, or missing
        done = self._continuing or {"resumed_ns": resumed_ns, "refilled": 0, "answered": set()}
        done["refilled"] += refilled
        done["answered"].update(answered)
        unanswered = sorted(set(sources) - done["answered"])
        if unanswered and self._refills_left > 0 and self._on_bus(unanswered):
            self._continuing = done
            self._refills_left -= 1
            self._refill_at = time.monotonic() + min(REFILL_BACKOFF_S, RELINK_SETTLE_S * 2 ** tries)
            log.info("recorder: no answer yet from %s to the restart's refill: asked again", ", ".join(unanswered))
            return answered
        self._continuing = None
        self._refills_left = REFILLS
        self._continued_gap(done, unanswered)
        return answered

    def _foreign(self, why: str, key: str, data: bytes, source: str, seq: int) -> None:
        """An answer's event of another source than the one its reply was sent as (services/answers.py): refused
        and recorded, once per (source, seq, key)."""
        if (source, seq, key) not in self._forged:
            self._forged.add((source, seq, key))
            self._reject(why, key, data, source=source, seq=seq)

    def _undisputed(self, answers) -> list[tuple[str, bytes]]:
        """The events of `answers` (services/answers.py `Sent`) that may be taken: each pair of answers that differ
        for one event is recorded (a MessageRejected naming both sessions, once) and that (source, seq) is taken
        from nobody after, a later answer from one session alone included (trial34 O, old config: the learner gone,
        the forger's lone answer to the next refill was taken); it stays a hole, which the file says."""
        for c in answers.conflicts:
            self._disputed.add((c.source, c.seq))
            pair = (c.source, c.seq, frozenset((c.replier, c.other)))  # (asked again, they may come in the other order)
            if pair not in self._forged:
                self._forged.add(pair)
                self._reject(c.said(), c.key, c.data, source=c.source, seq=c.seq)
        taken = []
        for key, data in answers.events:
            stamp = _stamp(data)  # (every event of `answers` decodes so far: services/answers.py)
            if (stamp.source, stamp.seq) not in self._disputed:
                taken.append((key, data))
        return taken

    def _on_bus(self, services: list[str]) -> bool:
        """Whether any of `services` is on the bus now (its token): only such a one may still answer."""
        alive = self.bus.alive_now(alive_key(self.session, "*"))
        return any(alive_key(self.session, s) in alive for s in services)

    def _continued_gap(self, done: dict, unanswered: list[str]) -> None:
        """Record the restart's gap (RecordingGap of `earlier_file`) as the refill's asks `done` gave it, and what the
        earlier recordings lost unless they gave it back (`_note_earlier_lost`)."""
        self._note_earlier_lost(not unanswered)  # unless this gave it back
        answered = sorted(done["answered"])
        gap = RecordingGap(earlier_file=self.continued["earlier_file"], copied=self.continued["copied"],
                           last_copied_ns=Nanos(self.continued["last_copied_ns"]), resumed_ns=Nanos(done["resumed_ns"]),
                           refilled=done["refilled"], refilled_from=answered, unanswered=unanswered)
        self._publish([gap])
        log.info("recorder: gap recorded: %d events refilled from %s", done["refilled"], ", ".join(answered) or "nobody")

    def _last_refill(self, deadline: Deadline) -> list[str] | None:
        """At close, the refill still due (an outage or a jump too recent to have been asked about, or one asked
        again) is asked now, in what the close's deadline leaves: the sources that answered; None if none was due
        or it could not be asked (the link down, no time left: then every source's tail is unknown)."""
        if self.bus is None or self.failure is not None:
            return None
        if self._continuing is not None:  # the restart's refill, asked again: a last ask in what the deadline leaves
            self._refill_at, self._refills_left = None, 0
            left = deadline.left(FINISH_S, cap=REFILL_TIMEOUT_S)
            try:
                if self._link_down or left < 0.05:
                    self._continued_gap(self._continuing, sorted(set(self._contiguous()) - self._continuing["answered"]))
                    self._continuing = None
                else:
                    self.refill(timeout_s=left)
            except RecordingFailed:
                return None
        if self._refill_at is None and self._link_lost_ns is None:
            return None
        if not self._bus_holes() and not self._tails():
            return None  # (a jump that closed by itself, an outage after which every source was heard: nothing to ask)
        left = deadline.left(FINISH_S, cap=REFILL_TIMEOUT_S)
        if self._link_down or left < 0.05:
            return None
        since = self._link_lost_ns if self._link_lost_ns is not None else self.clock()
        self._refill_at = self._link_lost_ns = None
        self._refills_left = 0  # no asking again: the file closes
        try:
            return self.refill(timeout_s=left, since_ns=since)
        except RecordingFailed:
            return None

    def _bus_holes(self) -> dict[str, list[tuple[int, int]]]:
        """The holes in the file's sequence numbers (`_holes`) but those of the earlier recordings' losses when
        the file records them (`_note_earlier_lost`: a hole that starts in what was copied of them)."""
        holes = _holes(self._seen())
        if self._earlier_recorded:
            holes = {s: kept for s, h in holes.items()
                     if (kept := [(a, b) for a, b in h if a >= self._copied_top.get(s, 0)])}
        return holes

    def _tails(self) -> list[str]:
        """The sources whose last events may be lost with no hole to show it: after a link outage no refill
        was answered after (`_outage_pending`), those not heard from since the link came back (all, if it is
        down): what was on the closed link's way was their last. One heard since shows a loss as a hole."""
        if not self._outage_pending:
            return []
        return sorted(s for s in self._held if self._link_down or self._recv_ns.get(s, 0) < self._back_ns)

    def _note_bus_lost(self, due: bool, answered: list[str] | None) -> None:
        """Record in the file what it lacks that no refill gave back (the refills gave up, a service did not
        answer or no longer had them, the recording closed first), as `pairplay recover` records a damaged
        file's losses (RECOVERED metadata, `bus` "true"), so every verb says the session is partial: every hole
        in a source's sequence numbers (between its first and last event in the file), and, when a refill was
        still `due` at the close and a source did not `answer` it (None: it could not be asked), that source's
        events after its last one in the file, how many not known. Before, the refill gave up silently: a
        recorder cut off for 5 s at load 20 lost 9 game events and the file said it was whole (test_netns).
        A hole's events that came and were shed at the exit (`drain`: a flood, or the deadline passed) are said
        apart, as SHED_AT_EXIT (`shed` "true", `shed_count`): they are counted among UNRECORDED_AT_EXIT already,
        and were said to be lost on the bus, and counted as lost too (an external `run recorder`'s close). So are
        those its full inbox shed mid-session (a flood, `_take_shed`), as SHED_LIVE (`flood` "true", `shed_count`):
        counted in its "inbox full" MessageRejected count already. One cause per missing event, each counted once:
        `lost_count` the bus's, `shed_count` the recorder's own."""
        seen = self._seen()
        holes = self._bus_holes()
        tails = [s for s in self._tails() if s not in (answered or ())] if due else []
        if not holes and not tails:
            return  # (the usual close: nothing decoded)
        with self._lock:
            kept = list(self.kept)
        where: dict[tuple[str, int], int] = {}  # (source, seq) -> its message's index in the file
        for i, (key, payload) in enumerate(kept):
            source = key.split("/")[2]
            if source in holes:
                where.setdefault((source, decode_event(payload).seq), i)
        shed = self._shed_seqs(holes)
        parts, marks, count = [], [], 0
        shed_parts, shed_count, causes = [], 0, set()
        for source in sorted(seen):
            for a, b in holes.get(source, ()):
                ordered = shed.get(source, [])
                inside = ordered[bisect.bisect_right(ordered, (a, "\uffff")):bisect.bisect_left(ordered, (b, ""))]
                for first, last, cause in _runs(a + 1, b - 1, inside):
                    n = last - first + 1
                    what = f"seq {first}" if n == 1 else f"seqs {first}-{last}"
                    if cause:  # it came, and the recorder shed it: counted there (its MessageRejected count), not again
                        shed_count += n
                        causes.add(cause)
                        shed_parts.append((cause, f"{source} {what} ({counted(n, 'event')} {cause})"))
                    else:
                        count += n
                        parts.append(f"{source} {what} ({counted(n, 'event')})")
                marks.append(where.get((source, b), len(kept)))
            seqs = seen[source]
            if source in tails:
                parts.append(f"{source}: what it published after seq {max(seqs)} (how many not known: the link to the router "
                             "was down, and no refill was answered after it before the recording closed)")
                marks.append(len(kept))
        if not parts and not shed_parts:
            return
        if parts:
            log.warning("recorder: not refilled, recorded as lost: %s", "; ".join(parts))
        if shed_parts:
            log.warning("recorder: recorded as shed by the recorder: %s", "; ".join(p for _, p in shed_parts))
        record = {"source": self.path.name, "truncated": "false", "data_complete": "true"}
        if parts:
            record["bus"] = "true"
        # (`shed_count` of them are among its MessageRejected counts, `unrecorded_at_exit` the exit's: not in `lost_count`)
        if SHED_AT_EXIT in causes:
            record["shed"] = "true"
        if SHED_LIVE in causes:
            record["flood"] = "true"
        reasons = [f"{BUS_LOST}, not refilled"] * bool(parts) + [c for c in (SHED_AT_EXIT, SHED_LIVE) if c in causes]
        self._guarded(self.writer.add_metadata, RECOVERED, {
            **record, "reason": "; ".join(reasons),
            "damaged": json.dumps([f"{BUS_LOST}: {p}" for p in parts] + [f"{c}: {p}" for c, p in shed_parts]),
            "lost": json.dumps(parts + [p for _, p in shed_parts]), "lost_count": str(count), "shed_count": str(shed_count),
            "lost_chunks": "0", LOST_AT_KEY: json.dumps(sorted(marks)), "messages": str(len(kept))})

    def _shed_seqs(self, holes: dict[str, list[tuple[int, int]]]) -> dict[str, list[tuple[int, str]]]:
        """Per source with a hole in the file, the seqs of its messages the recorder shed, each with its cause:
        SHED_LIVE, its full inbox mid-session (`_shed_live`), or SHED_AT_EXIT, `drain` at the exit (decoded only
        then: a flood's shed messages cost nothing more at the usual close; one that does not decode is none).
        A seq shed twice (a repeat) is said under the later cause."""
        out: dict[str, dict[int, str]] = {}
        for source, seqs in self._shed_live.items():
            if source in holes:
                out[source] = dict.fromkeys(seqs, SHED_LIVE)
        for key, payload in self._shed_at_exit:
            stamp = _shed_stamp(key, payload)
            if stamp is not None and stamp[0] in holes:
                out.setdefault(stamp[0], {})[stamp[1]] = SHED_AT_EXIT
        return {source: sorted(seqs.items()) for source, seqs in out.items()}  # (sorted: each hole's share by bisection)

    def _fill_hole(self, key: str, payload: bytes, log_time_ns: int | None = None) -> bool:
        """Write a refilled event older than the last one of its key in the file (every check but
        the order; MCAP sequence 0, "not given", as the file's per-channel order cannot hold it), at
        `log_time_ns` (default: now; the writer keeps log times monotonic, so 0 is the file's latest)."""
        verdict = self.guard.check(key, payload, overlap=True)
        if verdict.event is None or verdict.reason is not None or verdict.event.source == self.name:
            return False
        at = self.clock() if log_time_ns is None else log_time_ns
        self._guarded(self.writer.write, key, payload, log_time_ns=at, sequence=0)
        with self._lock:
            self.kept.append((key, payload))
        self._held.setdefault(verdict.event.source, set()).add(verdict.event.seq)
        self._noted(verdict.event, self.clock())
        return True

    @property
    def top_seq(self) -> dict[str, int]:
        return self.guard.top_seq

    @property
    def rejected(self) -> int:
        return self.refusals.total

    # -- bus side (Zenoh threads: hand over, never wait) --------------------
    def start(self) -> None:
        """Open the journal (FileExistsError if one is there: never replaced), then subscribe."""
        self.journal = JournalWriter(self.path, self.session, software_version=__version__, clock=self.clock,
                                     on_failure=self._on_journal_failure, recording_started_ns=self.started_ns)
        self._journal_add = self.journal.add
        self.journal.start()
        self.bus.subscribe(session_keys(self.session), self.enqueue, self._on_miss, drain=True)
        self.bus.queryable(query_key(self.session, self.name, LOG_QUERY), self.inbox.control)
        # a service about to leave asks whether we hold what it published (services/recorded.py): answered in turn
        self.bus.queryable(query_key(self.session, self.name, HELD_QUERY), lambda q: self.inbox.control(("held", q)))
        # the link to the router watched on every bus: a plain one loses what its queue held when the link closes
        # (a 5 s cut under load: test_netns); before, only a recovering bus, and such an outage passed for every
        # service's absence, with no refill
        self.bus.on_router_link(self._on_link)
        self.bus.watch_alive(alive_key(self.session, "*"), self._on_alive)
        self.bus.alive(alive_key(self.session, self.name))
        self.refill()

    def enqueue(self, key: str, payload: bytes) -> None:
        # durable when received (the journal), whatever waits before it in the inbox; a message the
        # inbox sheds is only counted, as live, so it is not journaled either
        if self.inbox.put(key, payload) and self._journal_add is not None:
            self._journal_add((key, payload))

    def _on_journal_failure(self, why: str) -> None:
        self.inbox.control(("journal", why))

    def _on_miss(self, publisher: str, n: int) -> None:
        self.inbox.lost(f"publisher {publisher}", MISSED, n)  # recorded as a count, then refilled
        self.inbox.control(_REFILL)

    def _on_link(self, up: bool, router: str) -> None:
        self.inbox.control(("link", up, router, self.clock()))

    def _on_alive(self, key: str, up: bool) -> None:
        self.inbox.control(("alive", key.rsplit("/", 1)[-1], up, self.clock()))

    def _answer_log(self, query) -> None:
        """Everything recorded so far, including what was queued when the query came
        (the query waited its turn in the inbox); answered from the outbox thread."""
        with self._lock:
            items = list(self.kept)
        batches = [msgspec.msgpack.encode((i // BATCH, items[i:i + BATCH])) for i in range(0, len(items), BATCH)]
        if self.outbox is not None:
            self.outbox.call(lambda: Bus.answer(query, batches))

    def _answer_held(self, query) -> None:
        """What we hold (services/recorded.py `Held`), after everything taken before the question. A source
        asked for again while we still lack its events up to the seq it asks (`upto`) is refilled now: it is
        on the bus, about to leave with its record of what it sent (the first ask may overtake its last events
        on their way, which then need no refill)."""
        seen = self._seen()
        contiguous = self._contiguous(seen)
        # (the services' names, or a source the file holds: made-up names in a query's parameters are not kept)
        upto = {source: seq for source, seq in asked_upto(str(query.parameters)).items()
                if source != self.name and (source in SOURCES or source in contiguous)}
        lacking = {source for source, seq in upto.items() if contiguous.get(source, 0) < seq}
        if lacking & self._asked and (self._refill_at is None or self._refill_at > time.monotonic()):
            self._refill_at = time.monotonic()
        self._asked = (self._asked - set(upto)) | lacking  # (several services ask in turn: each its own)
        held = Held(contiguous=contiguous, top={s: max(q) for s, q in seen.items() if q},
                    holes={s: h for s, q in seen.items() if (h := _missing(q))})
        payload = msgspec.msgpack.encode(held)
        if self.outbox is not None:
            self.outbox.call(lambda: Bus.answer(query, [payload]))

    # -- writer side (one thread) -----------------------------------------
    def _guarded(self, fn, *args, **kwargs):
        """Call a writer method; any error ends the recording (RecordingFailed), never silently."""
        if self.failure is not None:
            raise RecordingFailed(self.failure)
        try:
            return fn(*args, **kwargs)
        except Exception as err:
            self._fail(f"{type(err).__name__}: {err}" if str(err) else type(err).__name__)
            raise RecordingFailed(self.failure) from err

    def _fail(self, why: str) -> None:
        if self.failure is None:
            self.failure = why
            log.error("recorder: cannot write %s: %s", self.path, why)
            if self.on_failure is not None:
                self.on_failure(why)

    def step(self, timeout_s: float = 0.05) -> bool:
        """Take what waits in the inbox (or wait for it until the next flush is due), then flush if due.

        What waits is taken in pieces of `TAKE` (one lock each) for at most `BATCH_S`; a flush
        due by age is done between pieces, at most every `PIECE_FLUSH_S`: flushing by age, a
        recorder that had fallen `flush_interval` behind flushed after every message, a chunk
        each, and fell further behind (20,000 one-message chunks for 20,000 events: 300
        events/s); flushing only at a batch's end let a due flush wait up to `BATCH_S` more."""
        due = self.writer.due_in_ns(self.clock())
        wait = timeout_s if due is None else min(timeout_s, due / 1e9)
        items = self.inbox.get_many(max(wait, 0.0005), TAKE)
        try:
            self._publish(self.refusals.tick(self.clock()) if self.refusals.pending() else [])
            self._take_shed()
            took = bool(items)
            if took:
                started = time.monotonic()
                batch_end, flush_check = started + BATCH_S, started + PIECE_FLUSH_S
                take = self._take
                while items:
                    for item in items:
                        take(item)
                    now = time.monotonic()
                    # a flush due by age is done between pieces, not held to the batch's end; at most
                    # every PIECE_FLUSH_S (behind its inbox, every piece is due: a chunk per piece of a
                    # few messages cost 24% of the recorder's time in zstd contexts, measured)
                    if now >= flush_check:
                        flush_check = now + PIECE_FLUSH_S
                        if self._guarded(self.writer.maybe_flush, self.clock()):
                            self._note_backlog()
                    if now >= batch_end:
                        break
                    items = self.inbox.get_many(0, TAKE)
            if self._guarded(self.writer.maybe_flush, self.clock()):
                self._note_backlog()
            self._maybe_refill()
        except RecordingFailed:
            return False
        return took

    def _take_shed(self) -> None:
        """What the inbox shed since the last step, recorded as a MessageRejected count (`refusals`), and, of a
        known source's, its seq noted (`_shed_live`, at most SHED_NOTED): a hole no refill gives back there is
        said under that cause when the file closes (`_note_bus_lost`), counted once; it was said to be lost on the
        bus too, and counted as shed and as lost."""
        shed = self.inbox.take_shed()
        if shed:
            self.refusals.shed(shed)
        for key, payload in self.inbox.take_shed_items():
            stamp = _shed_stamp(key, payload) if self._shed_live_n < SHED_NOTED else None
            if stamp is not None:
                self._shed_live.setdefault(stamp[0], set()).add(stamp[1])
                self._shed_live_n += 1

    def _note_backlog(self) -> None:
        """A flush whose oldest message waited longer than the loss bound (the recorder fell
        behind its inbox) is recorded in the file (metadata BACKLOG_METADATA, at most once a
        second): a SIGKILL then could have lost messages that old, and the file says so."""
        age = self.writer.last_flush_age_ns
        now = self.clock()
        if age <= LOSS_BOUND_NS or now - self._backlog_noted_ns < 1_000_000_000:
            return
        self._backlog_noted_ns = now
        # INFO: nothing was lost and the file says it (README's logging rule); a loss is a WARNING elsewhere
        log.info("recorder: behind its inbox: flushed messages %.0f ms old, %d waiting", age / 1e6, len(self.inbox))
        self._guarded(self.writer.add_metadata, BACKLOG_METADATA, {
            "at_ns": str(now), "flush_age_ms": f"{age / 1e6:.1f}", "waiting": str(len(self.inbox)),
            "max_flush_age_ms": f"{self.writer.max_flush_age_ns / 1e6:.1f}"})

    def _take(self, item) -> None:
        key, payload, received_ns = item
        if key is None:
            if payload is _REFILL:  # Zenoh lost messages for good: refill now
                self._refill_at = time.monotonic()
            elif isinstance(payload, tuple) and payload[0] == "journal":  # its write failed: so has the recording
                self._fail(payload[1])
                raise RecordingFailed(payload[1])
            elif isinstance(payload, tuple) and payload[0] == "alive":
                self._alive(*payload[1:])
            elif isinstance(payload, tuple) and payload[0] == "held":
                self._answer_held(payload[1])
            elif isinstance(payload, tuple):
                self._link(*payload[1:])
            else:  # a query for the log
                self._answer_log(payload)
            return
        if self._overlap:  # (what came while a refill was answered may repeat it)
            self._overlap -= 1
            self.record(key, payload, received_ns, True)
        else:
            self.record(key, payload, received_ns, received_ns < self._quiet_until_ns)

    def _link(self, up: bool, router: str, at_ns: int) -> None:
        """The link to the router went (note when) or came back (record the outage, refill after
        Zenoh's own recovery has had its time)."""
        if not up and self.ended and not self._link_down:
            # the session's end recorded, then the router goes: the session's process (a `pairplay session` is
            # the router) ended, not an outage: nothing to refill after it (test_netns: every source's tail
            # was recorded as not known). A refill still due is asked at the close (`_last_refill`).
            log.info("recorder: the router %s left after the session's end", router)
            return
        self._link_down = not up
        if not up:
            self._outage_pending = True
            if self._link_lost_ns is None:
                self._link_lost_ns = at_ns
                log.warning("recorder: lost the link to router %s", router)
            return
        if self._link_lost_ns is None:
            return  # the first connection, not a return
        for service, left_ns in list(self._absent.items()):  # the link's outage, not the services'
            if left_ns >= self._link_lost_ns - LINK_SLACK_NS:
                del self._absent[service]
        outage = {"lost_ns": str(self._link_lost_ns), "back_ns": str(at_ns), "router": router,
                  "outage_ms": f"{(at_ns - self._link_lost_ns) / 1e6:.0f}"}
        self.links.append(outage)
        log.warning("recorder: the link to router %s is back after %s ms", router, outage["outage_ms"])
        self._guarded(self.writer.add_metadata, LINK_METADATA, outage)
        self._back_ns = at_ns
        self._refill_at = time.monotonic() + RELINK_SETTLE_S

    def _alive(self, service: str, up: bool, at_ns: int) -> None:
        """A service's token went or came back (see rule): an absence is recorded on its return."""
        if service == self.name:
            return
        if not up:
            if not self.ended and not self._link_down:
                self._absent.setdefault(service, at_ns)
            return
        left = self._absent.pop(service, None)
        if left is not None:
            self._note_absence(service, left, at_ns)

    def _note_absence(self, service: str, left_ns: int, back_ns: int | None) -> None:
        absence = {"service": service, "left_ns": str(left_ns), "back_ns": "" if back_ns is None else str(back_ns),
                   "absent_ms": "" if back_ns is None else f"{(back_ns - left_ns) / 1e6:.0f}"}
        self.absences.append(absence)
        log.warning("recorder: %s was off the bus %s", service,
                    f"for {absence['absent_ms']} ms" if back_ns is not None else "and did not come back")
        self._guarded(self.writer.add_metadata, ABSENCE_METADATA, absence)

    def _catch_up(self, timeout_s: float = REFILL_TIMEOUT_S) -> None:
        """Ask each source first heard past its seq 1 for what it sent before (`.../_query/<source>/sent?after=
        <source>:0`, the refill's query) and write it (`_fill_hole`: below what came live). A head that came is
        recorded (HEAD_METADATA: source, first_live, caught_up); one that did not is asked again (HEAD_ASKS, each
        later), then left: the reader says the file lacks it, as it does."""
        self._head_at = None
        due = {s: v for s, v in self._heads.items() if min(self._held.get(s, {v[0]})) > 1}
        for source in set(self._heads) - set(due):
            del self._heads[source]  # held meanwhile (a refill's answer)
        for source, (first_live, _) in sorted(due.items()):
            got = 0
            answers = sent_answers(
                self.bus.query_replies(f"{query_key(self.session, source, SENT_QUERY)}?after={source}:0", timeout_s,
                                       with_key=True),
                lambda err: log.warning("recorder: unreadable answer for %s's first events: %s", source, err),
                self._foreign)
            for key, data in self._undisputed(answers):  # (two that differ: neither; the head stays a hole, said)
                stamp = _stamp(data)  # (what does not decode is not among the events: `_fill_hole` would refuse it)
                if stamp.source != source or not 0 < stamp.seq < first_live or stamp.seq in self._held.get(source, ()):
                    continue
                # at the file's latest log time, not now: now would lift the log times of the live events
                # taken after it, which the writer keeps monotonic (a pilot's board start made 4 events of
                # one log time so, and tests/damageutil found two chunks holding "the" event of a time)
                got += self._fill_hole(key, data, log_time_ns=0)
            if got:  # what was in flight meanwhile repeats it: skipped quietly, as after a refill
                self._quiet_until_ns = self.clock() + int(REFILL_QUIET_S * 1e9)
            held = self._held.get(source, set())
            if all(n in held for n in range(1, first_live)):
                del self._heads[source]
                log.info("recorder: %s's first %d event(s), sent before this recorder listened, asked for and recorded",
                         source, got)
                self._guarded(self.writer.add_metadata, HEAD_METADATA,
                              {"source": source, "first_live": str(first_live), "caught_up": str(got)})
            elif self._heads[source][1] > 1:
                self._heads[source][1] -= 1
                self._head_at = time.monotonic() + REFILL_BACKOFF_S / 4
            else:  # left: the file lacks them, and every verb says so (replay/reader.py: a hole at the start)
                del self._heads[source]
                log.warning("recorder: %s's events before its seq %d, sent before this recorder listened, did not come "
                            "when asked %d times", source, first_live, HEAD_ASKS)

    def _maybe_refill(self) -> None:
        if self._head_at is not None and time.monotonic() >= self._head_at and not self._link_down:
            self._catch_up()
        if self._refill_at is None or time.monotonic() < self._refill_at or self._link_down:
            return  # (the link's return schedules one anyway)
        if self._continuing is not None:  # the restart's refill asked again (it asks for every hole: an outage's too)
            self._refill_at = None
            self.refill()
            if self._refill_at is None and self._link_lost_ns is not None:
                self._refill_at = time.monotonic()  # an outage's own refill, next (its records: LINK_METADATA)
            return
        since = self._link_lost_ns if self._link_lost_ns is not None else self.clock()
        self._refill_at = self._link_lost_ns = None
        self.refill(since_ns=since)

    def record(self, key: str, payload: bytes, received_ns: int, quiet: bool = False) -> bool:
        """Check and write one message; False (and a recorded rejection) if it fails a check.
        `quiet`: it may repeat what was copied or refilled; a repeat is skipped, not refused.
        Raises RecordingFailed if the file cannot be written."""
        event, reason, skip = self.guard.check(key, payload, quiet)
        if self.guard.notices:  # a start or end taken earlier was contradicted (services/guard.py _conflict)
            for why, k, source, seq in self.guard.notices:
                self._reject(why, k, b"", source=source, seq=seq)
            self.guard.notices.clear()
            self.ended = self.ended and "SessionEnded" in self.guard.once
        if skip:
            return False  # our own refusal coming back: written already
        if reason is not None:
            return self._reject(reason, key, payload, event)
        # the recorder's own times: log time = when it took the message (its clock, monotonic in the file),
        # publish time = the same; the envelope's time_ns is the publisher's claim and stays in the payload.
        # (The writer is called directly, not through _guarded: this runs once per message.)
        if self.failure is not None:
            raise RecordingFailed(self.failure)
        try:
            self.writer.write(key, payload, log_time_ns=received_ns, sequence=event.seq)
        except Exception as err:
            self._fail(f"{type(err).__name__}: {err}" if str(err) else type(err).__name__)
            raise RecordingFailed(self.failure) from err
        self.kept.append((key, payload))  # one append is atomic; readers copy it under self._lock
        self._held.setdefault(event.source, set()).add(event.seq)
        self._recv_ns[event.source] = received_ns
        last = self._last_seq.get(event.source)
        if last is None and event.seq > 1 and self.bus is not None and self.continued is None:
            # its first events went out before this recorder listened (a service started before it: docs/bus.md
            # "Starting in any order"): nothing was lost, they are in its own record; asked for now, as a late
            # joiner catches up. Before, the file lacked them and every verb called it damaged (trial33 F).
            # (A restarted recorder's refill asks for every source's head already: `refill`.)
            self._heads[event.source] = [event.seq, HEAD_ASKS]
            if self._head_at is None:  # asked at once: a scripted board's node answers between its turns, and
                # is busy thinking later (asked 0.5 s on, no pilot's board answered); one still on its way on
                # another key comes after it as a repeat, skipped quietly (`_quiet_until_ns`)
                self._head_at = time.monotonic()
        if last is None or event.seq > last:
            self._last_seq[event.source] = event.seq
            if last is not None and event.seq > last + 1 and self._refill_at is None and self.bus is not None:
                # a jump: what is between was lost on the way (a link closed under a full queue loses what it
                # held, with no word from Zenoh when the bus does not recover: test_netns), or is still on its
                # way (another key): asked for once the way has had its time; refill asks only if a hole is left
                self._refill_at = time.monotonic() + RELINK_SETTLE_S
        self._noted(event, received_ns)
        return True

    def _noted(self, event, received_ns: int) -> None:
        """What a session's start or end written to the file tells the recorder, whichever way it came: live
        (`record`), or asked for (`_fill_hole`: a head caught up, a refill). Only the live way set these before,
        so a recorder that first heard the game past its seq 1 wrote the whole session and then said the file
        "holds no session" and to remove it, with exit 1, and the file had no "pairplay.session" (trial34 K)."""
        tag = type(event).__name__
        if tag == "SessionStarted":
            self.holds_session = True
            c = event.config  # a SessionConfig in the twin too (only Nanos fields differ)
            self._guarded(self.writer.add_metadata, "pairplay.session", {
                "config": msgspec.json.encode(c).decode(), "session": c.session, "participant": c.participant,
                "persona": c.persona, "seed": str(c.seed), "game_index": str(c.game_index),
                "algorithm": c.algorithm, "software_version": c.software_version or __version__,
                "streams": str(c.streams)})
        elif tag == "SessionEnded":
            self.ended = True
            # when the session ended: the game's stamp if earlier than our receipt. A service leaves once it
            # saw the end, but its token's drop (Zenoh control traffic) can reach us before the end itself
            # (data queued behind a backlog): by receipt time it looked absent and never back (_close_absences)
            stamp = event.time_ns if isinstance(event.time_ns, int) else event.time_ns.sec * 10**9 + event.time_ns.nsec
            self._ended_ns = min(received_ns, stamp)

    def _reject(self, reason: str, key: str, payload: bytes, event=None, source: str = "", seq: int = 0) -> bool:
        out = self.refusals.refuse(self.clock(), reason, key, getattr(event, "source", source),
                                   getattr(event, "seq", seq), payload)
        if self.refusals.recorded:
            log.warning("recorder rejected %s: %s", key, reason[:300])
        self._publish(out)
        return False

    def _publish(self, rejections: list) -> None:
        """Write our own events (refusals, gaps) into the file and tell the bus (the echo is ignored)."""
        for r in rejections:
            self.seq += 1
            now = self.clock()
            r = stamped(r, session=self.session, source=self.name, seq=self.seq, time_ns=now)
            key, payload = event_key(self.session, self.name, type(r).__name__), encode_event(r)
            if self.failure is None:
                self._guarded(self.writer.write, key, payload, log_time_ns=now, sequence=self.seq)
                self.guard.note(key, r)
                with self._lock:
                    self.kept.append((key, payload))
            if self.outbox is not None:
                self.outbox.send(key, payload)

    def drain(self, deadline: Deadline, own=()) -> int:
        """Write what is queued until `deadline` (keeping `FINISH_S` of it to finish the file: a
        flood must not hold up the exit); what still waits then is shed, counted under
        UNRECORDED_AT_EXIT and recorded as a MessageRejected count, but for the session's end
        (SessionEnded) and what this process's own services published (`own`, Recorder.close),
        written whatever the deadline left: they are in hand, and without them the file does not
        say how its session ended, or has a hole below its end. Returns how many were shed."""
        n: int | None = None  # shed, once the deadline has passed
        # at most as many of a source's as it has in `own` (a message on its key that is not its own, a forger's
        # flood, is shed as before)
        ours = Counter(key.split("/")[2] for key, _ in own)

        def keep(key: str) -> bool:
            source = key.split("/")[2]
            if ours[source] > 0:
                ours[source] -= 1
                return True
            return key.endswith("/SessionEnded")

        while self.failure is None:
            if n is None and deadline.passed(FINISH_S):
                n = self.inbox.discard(UNRECORDED_AT_EXIT, keep=keep, into=self._shed_at_exit)
            item = self.inbox.get(0)
            if item is None:
                break
            try:
                self._take(item)
            except RecordingFailed:
                break
        n = n or 0
        if n:
            log.warning("recorder: %d messages still queued at the exit are not recorded (counted)", n)
        return n

    def run(self, stop: threading.Event) -> None:
        """Record until `stop`; a failure of any kind ends the recording loudly (on_failure)."""
        try:
            while not stop.is_set() and self.failure is None:
                self.step()
        except Exception as err:  # a bug: the file stops here, the session is told, nothing goes on unrecorded
            log.exception("recorder failed")
            self._fail(f"recorder error {type(err).__name__}: {err}")

    def _unreported_suggestions(self) -> int:
        """In a session with a robot (its ServiceStarted or a RobotActed is in the file): the
        suggestions with no RobotActed in the file and not already counted as not reported or
        not received (by the bridge, the session, or a restarted bridge). A RobotActed lost on
        the bus (the robot's link cut: 359 of 902 in the four-host test) or a suggestion that
        never reached the bridge is then counted in the file, never lost silently."""
        with self._lock:
            items = list(self.kept)
        made, acted, counted, robot = set(), set(), 0, False
        for key, payload in items:
            tag = key.rsplit("/", 1)[-1]
            if tag not in ("SuggestionMade", "RobotActed", "ServiceStarted", "MessageRejected"):
                continue
            e = decode_event(payload)
            if tag == "SuggestionMade":
                made.add(e.seq)
            elif tag == "RobotActed":
                robot = True
                acted.add(e.suggestion_seq)
            elif tag == "ServiceStarted":
                robot = robot or e.source == "robot"
            elif (e.offending_source == "robot" and ("not reported" in e.reason or "not received" in e.reason)
                  and e.reason.split(" ", 1)[0].isdigit()):
                counted += int(e.reason.split(" ", 1)[0])
        return max(0, len(made - acted) - counted) if robot else 0

    def close(self, stopped_by: str = "", deadline: Deadline | None = None, own=()) -> str | None:
        """Write what is queued, finish the file; never raises. The failure, if the
        file could not be written (it is then readable up to it: `pairplay recover`).

        The file's last record says how the recording ended (metadata
        "pairplay.recorder.end": `session_ended` "true" when the session's
        SessionEnded is in it; `stopped_by` the signal or stop that ended the
        recording, "" when the session ended by itself), so even a recording
        stopped before its game started says why it holds no session, and how many messages
        were still queued when it stopped (`unrecorded_at_exit`, also recorded as a count).

        Done by `deadline` (default `CLOSE_S` from now): the queue is written while
        `FINISH_S` of it is left, the rest counted (`drain`). `own`: (key, payload) of what
        this process's services published that the file lacks, the session's own end included
        (services/session.py own_tail), or a function giving them, called now: written after
        the queue, whatever the deadline left,
        unless the bus brought it already (a repeat is skipped): the file says how the session
        ended, with no hole below its end, even when the signal's deadline passed before the bus
        brought them (a starved machine)."""
        testpause.pause("recorder-closing")  # (a test's first signal lands here: the session has ended)
        deadline = deadline or Deadline(CLOSE_S)
        unrecorded = 0
        try:
            own = own() if callable(own) else own  # (taken now: services/session.py close_all)
            unrecorded = self.drain(deadline, own)
            for key, payload in own:
                if self.failure is None:
                    self.record(key, payload, self.clock(), quiet=True)
        except RecordingFailed:
            pass
        except Exception as err:
            log.exception("recorder failed")
            self._fail(f"recorder error {type(err).__name__}: {err}")
        self._take_shed()
        if self.failure is None:  # off the bus mid-session and never back
            for service, left_ns in sorted(self._absent.items()):
                if self._ended_ns is None or left_ns < self._ended_ns - LINK_SLACK_NS:  # (slack: the hosts' clocks)
                    try:
                        self._note_absence(service, left_ns, None)
                    except RecordingFailed:
                        break
            self._absent.clear()
        if self.refusals.pending() and self.failure is None:
            try:
                self._publish(self.refusals.tick(self.clock(), force=True))
            except RecordingFailed:
                pass
        unreported = self._unreported_suggestions() if self.failure is None else 0
        if unreported:
            log.warning("recorder: %d suggestion(s) have no RobotActed in the recording", unreported)
            self.refusals.shed(Counter({("robot", UNREPORTED): unreported}))
            try:
                self._publish(self.refusals.tick(self.clock(), force=True))
            except RecordingFailed:
                pass
        if self.failure is None:
            try:
                if self._heads and not self._link_down:  # a head still due: asked once more in what the deadline leaves
                    left = deadline.left(FINISH_S, cap=REFILL_TIMEOUT_S)
                    if left >= 0.05:
                        for v in self._heads.values():
                            v[1] = 1
                        self._catch_up(timeout_s=left)
                due = self._outage_pending
                answered = self._last_refill(deadline)
                self._note_earlier_lost(False)  # (closed before its refill: what the earlier recordings lost, still)
                self._note_bus_lost(due, answered)
                self._guarded(self.writer.add_metadata, END_METADATA, {
                    "ended_ns": str(self.clock()), "session_ended": str(self.ended).lower(), "stopped_by": stopped_by,
                    "unrecorded_at_exit": str(unrecorded),
                    "max_flush_age_ms": f"{self.writer.max_flush_age_ns / 1e6:.1f}"})
            except RecordingFailed:
                pass
        testpause.pause("recorder-ending")  # (a test's second signal lands here: before the file's end is written)
        # The file's end, its fsync and its journal's removal are one step a signal does not cut (pairplay/signals.py
        # `held`: milliseconds): a second Ctrl-C between the end and the removal left a stale journal beside a whole
        # file (a new user's trial), which every verb then took for a crash's. A signal before the step leaves the
        # file without its end and the journal beside it (`pairplay recover`); one in it is delivered after it.
        with signals.held():
            if self.failure is None:
                try:
                    self._guarded(self.writer.close)
                    self._guarded(_fsync, self.path)
                except RecordingFailed:
                    pass
            else:
                self.writer.abandon()
            self.whole = self.failure is None
            testpause.pause("recorder-whole")
            if self.journal is not None:  # kept unless the file is complete and on disk: recover reads it
                self.journal.close(remove=self.whole)
        self.release()  # the journal gone: nothing of ours is live any more
        if self.outbox is not None:
            self.outbox.close(deadline.left(cap=0.5))
        return self.failure
