"""The recorder's write-ahead journal (issue 12 item 6): every message durable when received.

A recorder SIGKILLed with a backlog loses nothing the journal held (before the journal the
inbox's backlog died with it); a torn journal is read up to its tear; forged and refused
messages in a journal stay refused and are recorded as such; recover without a journal is
unchanged; a restarted recorder takes what the earlier journal holds; a stray journal is one
line wherever a recording is expected, and a session id whose journal is left is taken."""

from __future__ import annotations

import os
import shutil

import pytest

from pairplay.numbers import counted

from pairplay.replay.reader import read_log
from pairplay.replay.recover import recover
from pairplay.replay.check import MCAP_MAGIC
from pairplay.replay.wal import MAGIC, JournalWriter, NotAJournal, read_journal, wal_path
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.recorder import Recorder, RecordingExists, check_new_recording, set_aside, settle_aside
from pairplay.services.walmerge import admit

from busutil import listener, recorder_process, sigkill, wait_until


def message(event, source="game", seq=1, session="j1"):
    e = stamped(event, session=session, source=source, seq=seq, time_ns=seq)
    return event_key(session, source, type(event).__name__), encode_event(e)


def start(session="j1"):
    cfg = SessionConfig(session=session, participant="sim:ashley", persona="ashley", seed=1, rounds=3)
    return message(ev.SessionStarted(config=cfg), session=session)


def pick(seq, session="j1"):
    return message(ev.CardPicked(round=0, turn=seq, card=seq % 18), source="participant", seq=seq, session=session)


def journal_of(recording, items, session="j1"):
    """A journal beside `recording` holding `items` ((key, payload)), written in two frames."""
    j = JournalWriter(recording, session, clock=iter(range(10**9, 10**10, 1000)).__next__)
    half = len(items) // 2
    for k, p in items[:half]:
        j.add((k, p))
    j.write_pending()
    for k, p in items[half:]:
        j.add((k, p))
    j.close()
    return j.path


def cut_recording(tmp_path, events, name="j1.mcap", session="j1"):
    """A recording of `events` cut as a SIGKILL cuts it: flushed, never finished."""
    live = Recorder(None, session, tmp_path / "live" / name, clock=iter(range(10**9, 10**10, 1000)).__next__)
    for i, (k, p) in enumerate(events):
        assert live.record(k, p, 10**9 + i)
    live.writer.flush(live.clock())
    live.writer._stream.flush()
    shutil.copy(live.path, tmp_path / name)
    live.close()
    return tmp_path / name


# -- the journal file -------------------------------------------------------------
def test_a_journal_reads_back_every_record_in_order_with_its_header(tmp_path):
    items = [pick(s) for s in range(1, 101)]
    path = journal_of(tmp_path / "j1.mcap", items)
    assert path.name == "j1.mcap.journal" and path.read_bytes().startswith(MAGIC)
    j = read_journal(path)
    assert j.session == "j1" and j.header["recording"] == "j1.mcap" and not j.torn
    assert [(k, p) for k, p, _ in j.records] == items and j.frames == 3


@pytest.mark.parametrize("tear", ["mid-head", "mid-body", "flipped", "zeros"])
def test_a_torn_journal_is_read_up_to_its_tear(tmp_path, tear):
    items = [pick(s) for s in range(1, 101)]
    path = journal_of(tmp_path / "j1.mcap", items)
    data = path.read_bytes()
    whole = read_journal(path)
    first_frame_end = len(data) - (len(data) - len(MAGIC)) // 2  # somewhere in the last frame
    if tear == "mid-head":  # the last frame's head cut: find it by re-reading the first two frames
        data = data + b"\x01\x02\x03"
    elif tear == "mid-body":
        data = data[:-7]
    elif tear == "flipped":
        data = data[:-3] + bytes([data[-3] ^ 0xFF]) + data[-2:]
    else:  # a power cut's zero-filled tail
        data = data + b"\0" * 64
    path.write_bytes(data)
    j = read_journal(path)
    assert j.torn, tear
    expected = whole.records if tear in ("mid-head", "zeros") else whole.records[:50]
    assert j.records == expected, (tear, first_frame_end)


def test_what_is_not_a_journal_is_refused_in_one_sentence(tmp_path):
    (tmp_path / "x.journal").write_bytes(b"hello")
    with pytest.raises(NotAJournal):
        read_journal(tmp_path / "x.journal")
    (tmp_path / "y.journal").write_bytes(MAGIC + b"\xff" * 30)
    with pytest.raises(NotAJournal):
        read_journal(tmp_path / "y.journal")


def test_a_journal_is_never_replaced(tmp_path):
    journal_of(tmp_path / "j1.mcap", [pick(1)])
    with pytest.raises(FileExistsError):
        JournalWriter(tmp_path / "j1.mcap", "j1")


# -- recover with a journal ---------------------------------------------------------
def test_recover_adds_what_the_cut_file_lacks_from_its_journal_and_nothing_twice(tmp_path):
    events = [start()] + [pick(s) for s in range(1, 41)]
    path = cut_recording(tmp_path, events[:21])  # the file holds the start and picks 1-20
    journal_of(path, events)  # the journal holds everything received: start and picks 1-40
    done = recover(path, admit=admit)
    assert done.from_journal == 20 and done.journal_refused == 0 and done.journal == wal_path(path)
    log = read_log(done.output)
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 41))
    assert not [r for r in log.events if r.event.source == "recorder"]
    meta = log.metadata["pairplay.recovered"]
    assert meta["from_journal"] == "20" and meta["journal"] == "j1.mcap.journal" and meta["journal_torn"] == ""
    assert wal_path(path).exists()  # recover never changes its inputs


def test_forged_and_refused_messages_in_a_journal_stay_refused_and_are_recorded(tmp_path):
    events = [start()] + [pick(s) for s in range(1, 11)]
    path = cut_recording(tmp_path, events[:6])
    forged = [
        message(ev.SessionEnded(), source="participant", seq=11),  # a source that may not publish it
        pick(10**9),  # a sequence number jump
        (event_key("j1", "participant", "CardPicked"), b"{not json"),  # malformed
        message(ev.CardPicked(round=0, turn=3, card=0), source="participant", seq=3),  # a repeat, other bytes
        message(ev.SessionStarted(config=SessionConfig(session="j1", participant="sim:x", persona="ashley", seed=2, rounds=1)),
                seq=99),  # a second start
        message(ev.MessageRejected(reason="x", key="k"), source="recorder", seq=1),  # our own echo: skipped
        pick(1, session="other"),  # another session's
    ]
    journal_of(path, events + forged)
    done = recover(path, admit=admit)
    assert done.from_journal == 5 and done.journal_refused == 6
    log = read_log(done.output)
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 11))
    assert sum(isinstance(r.event, ev.SessionEnded) for r in log.events) == 0
    refusals = [r.event for r in log.events if r.event.source == "recorder"]
    assert len(refusals) == 6 and all(isinstance(e, ev.MessageRejected) and e.reason for e in refusals)
    assert [e.seq for e in refusals] == list(range(1, 7))
    reasons = " | ".join(e.reason for e in refusals)
    for words in ("jumps", "malformed", "not above", "second SessionStarted", "wrong session"):
        assert words in reasons, words


def test_a_refusal_the_file_holds_already_is_not_recorded_twice(tmp_path):
    events = [start(), pick(1), pick(2)]
    bad = pick(10**9)
    live = Recorder(None, "j1", tmp_path / "live" / "j1.mcap")
    for i, (k, p) in enumerate(events[:2] + [bad]):
        live.record(k, p, 10**9 + i)
    live.writer.flush(live.clock())
    live.writer._stream.flush()
    shutil.copy(live.path, tmp_path / "j1.mcap")
    live.close()
    journal_of(tmp_path / "j1.mcap", events[:2] + [bad] + events[2:])
    done = recover(tmp_path / "j1.mcap", admit=admit)
    assert done.from_journal == 1 and done.journal_refused == 1
    log = read_log(done.output)
    assert sum(r.event.source == "recorder" for r in log.events) == 1  # the live refusal, once


def test_recover_reads_a_torn_journal_up_to_its_tear_and_says_so(tmp_path, pairplay_cli):
    events = [start()] + [pick(s) for s in range(1, 41)]
    path = cut_recording(tmp_path, events[:11])
    journal = journal_of(path, events)
    journal.write_bytes(journal.read_bytes()[:-5])  # the second frame (picks 20-40) torn
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0, ran.stderr
    assert "9 events taken from its journal j1.mcap.journal" in ran.stdout and "torn" in ran.stdout
    log = read_log(tmp_path / "j1.recovered.mcap")
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 20))


def test_recover_says_that_a_cut_recordings_journal_is_kept_and_why(tmp_path, pairplay_cli):
    """After a recovery the journal beside the cut file stays (recover never changes its input; it is what the cut
    file lacks), and the line says so and what to do (it was left with no word: a new user's trial)."""
    events = [start()] + [pick(s) for s in range(1, 21)]
    path = cut_recording(tmp_path, events[:11])
    journal = journal_of(path, events)
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0, ran.stderr
    assert (f"taken from its journal j1.mcap.journal; {path} and its journal are kept as they were (the journal "
            "recovers it again; remove the two once the output is kept)") in ran.stdout, ran.stdout
    assert journal.exists() and (tmp_path / "j1.recovered.mcap").exists()


@pytest.mark.parametrize("damage", ["header", "garbage"])
def test_recover_says_when_the_journal_beside_it_is_unreadable(tmp_path, pairplay_cli, damage):
    """A journal damaged in its header, or garbage under the journal's name, was dropped without a word and
    recover exited 0 as if there had been none (a new user's trial): what it held is lost, so it is a
    WARNING naming the journal; the output is still written (the recording's own records)."""
    events = [start()] + [pick(s) for s in range(1, 21)]
    path = cut_recording(tmp_path, events[:11])
    journal = journal_of(path, events)
    if damage == "header":
        data = bytearray(journal.read_bytes())
        data[25:45] = b"\xff" * 20  # inside the header frame: its CRC fails
        journal.write_bytes(bytes(data))
    else:
        journal.write_bytes(bytes(range(20)))
    for quiet in ([], ["-q"]):  # a warning about the result: on stderr, -q or not (cli/main.py `warn`: -q hid it)
        ran = pairplay_cli("recover", path, "--force", *quiet)
        assert ran.returncode == 0, ran.stderr
        lines = ran.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pairplay recover: the journal beside ") and \
            "j1.mcap.journal" in lines[0] and "unreadable" in lines[0], lines
        assert "Traceback" not in ran.stderr


def test_recover_without_a_journal_is_unchanged(tmp_path, pairplay_cli):
    events = [start()] + [pick(s) for s in range(1, 11)]
    path = cut_recording(tmp_path, events)
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0 and "from its journal" not in ran.stdout, ran.stdout
    log = read_log(tmp_path / "j1.recovered.mcap")
    assert len(log.events) == 11
    assert not any(k.startswith("journal") or k == "from_journal" for k in log.metadata["pairplay.recovered"])


def test_a_journal_of_another_session_is_refused_in_one_line(tmp_path, pairplay_cli):
    path = cut_recording(tmp_path, [start(), pick(1)])
    journal_of(path, [pick(1, session="other")], session="other")
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 2 and len(ran.stderr.strip().splitlines()) == 1 and "Traceback" not in ran.stderr
    assert "session 'other'" in ran.stderr


def test_a_file_cut_before_its_first_flush_is_recovered_from_its_journal(tmp_path):
    events = [start()] + [pick(s) for s in range(1, 6)]
    path = cut_recording(tmp_path, [])  # only MCAP's magic and header reached the disk
    journal_of(path, events)
    done = recover(path, admit=admit)
    assert done.from_journal == 6
    assert len(read_log(done.output).events) == 6 and not read_log(done.output).no_session


def refusals_in(events) -> int:
    """How many refusals the recorder's MessageRejected events account for: one each, or its count."""
    out = 0
    for e in events:
        if isinstance(e, ev.MessageRejected) and e.source == "recorder":
            words = e.reason.split(" ", 1)
            out += int(words[0]) if e.key == "" and words[0].isdigit() else 1
    return out


@pytest.mark.parametrize("cut_after", ["counts", "one_by_one"])
def test_refusals_the_live_recorder_only_counted_are_not_counted_again_by_recover(tmp_path, cut_after):
    """A flood of 200 malformed messages in one second: the live recorder records 20 refusals one by
    one (its rate) and counts the other 180 in one MessageRejected. Before, recover matched only the
    refusals recorded one by one and refused the 180 counted ones again (20 more one by one, 160 more
    counted): 380 refusals for 200 messages. Cut before the count reached the file, recover counts
    them once (the count is what the SIGKILL lost)."""
    live = Recorder(None, "j1", tmp_path / "live" / "j1.mcap", clock=iter(range(10**9, 10**10, 1000)).__next__)
    events = [start(), pick(1)]
    flood = [(event_key("j1", "participant", "CardPicked"), b"{not json %d" % i) for i in range(200)]
    for i, (k, p) in enumerate(events + flood + [pick(2)]):
        live.record(k, p, 10**9 + i)
    if cut_after == "counts":
        live._publish(live.refusals.tick(live.clock(), force=True))
    live.writer.flush(live.clock())
    live.writer._stream.flush()
    shutil.copy(live.path, tmp_path / "j1.mcap")
    live.close()
    held = read_log(tmp_path / "j1.mcap").events
    assert refusals_in(r.event for r in held) == (200 if cut_after == "counts" else 20)
    journal_of(tmp_path / "j1.mcap", events + flood + [pick(2), pick(3)])
    done = recover(tmp_path / "j1.mcap", admit=admit)
    assert done.from_journal == 1 and done.journal_refused == 200
    log = read_log(done.output)
    assert refusals_in(r.event for r in log.events) == 200
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == [1, 2, 3]


@pytest.mark.parametrize("left", [b"", MCAP_MAGIC[:5]])
def test_a_file_of_nothing_beside_its_journal_is_recovered_from_it_and_named_so_elsewhere(tmp_path, pairplay_cli,
                                                                                         left):
    """A recorder SIGKILLed before its first flush leaves a 0-byte MCAP (its writer buffers even the
    magic; measured: tests/test_recorder_restart.py) and what it received in its journal. Before,
    `pairplay recover` refused it ("empty file (0 bytes), not a recording") and the journal's events
    could not be recovered; every other verb said the same, without a word of the journal."""
    events = [start()] + [pick(s) for s in range(1, 6)]
    path = tmp_path / "j1.mcap"
    path.write_bytes(left)
    journal_of(path, events)
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0, ran.stderr
    assert "6 events taken from its journal" in ran.stdout, ran.stdout
    log = read_log(tmp_path / "j1.recovered.mcap")
    assert log.whole and [r.payload for r in log.events] == [p for _, p in events]
    assert path.read_bytes() == left  # the original is never modified
    ran = pairplay_cli("replay", "--verify", path)
    lines = ran.stderr.strip().splitlines()
    assert ran.returncode == 2 and len(lines) == 1 and f"pairplay recover {path}`" in lines[0], ran.stderr
    wal_path(path).unlink()  # without its journal: not a recording, as before
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 2 and "not a recording" in ran.stderr and "journal" not in ran.stderr, ran.stderr


@pytest.mark.parametrize("verb", [["recover"], ["replay", "--verify"], ["rebuild"]])
def test_a_missing_recording_whose_journal_is_left_names_it_and_how_to_recover(tmp_path, pairplay_cli, verb):
    """A new user's trial: the recording removed, its journal left beside where it was; `recover` said only
    "no such recording", not a word of the journal that holds its events. Its line names the journal and the
    two commands that rebuild the recording from it, which then work as said."""
    events = [start()] + [pick(s) for s in range(1, 4)]
    path = tmp_path / "j1.mcap"
    journal_of(path, events)
    ran = pairplay_cli(*verb, path, cwd=tmp_path)
    lines = ran.stderr.strip().splitlines()
    assert ran.returncode == 2 and len(lines) == 1, ran.stderr
    assert f"({wal_path(path)}:" in lines[0] and f"`touch {path}`" in lines[0] and f"`pairplay recover {path}`" in lines[0]
    path.touch()  # as the line says
    ran = pairplay_cli("recover", path, cwd=tmp_path)
    assert ran.returncode == 0 and "4 events taken from its journal" in ran.stdout, (ran.stdout, ran.stderr)


# -- stray journals ------------------------------------------------------------------
@pytest.mark.parametrize("verb", [["rebuild"], ["recover"], ["replay", "--verify"], ["view", "--no-save", "--recording"],
                                  ["counterfactual", "--fit-only"]])
def test_a_journal_given_as_a_recording_is_one_line_naming_recover(tmp_path, pairplay_cli, verb):
    path = cut_recording(tmp_path, [start(), pick(1)])
    journal = journal_of(path, [start(), pick(1)])
    ran = pairplay_cli(*verb, journal, cwd=tmp_path)
    assert ran.returncode != 0 and "Traceback" not in ran.stderr
    lines = ran.stderr.strip().splitlines()
    # the recording as the user gave its journal (folder included: a pasteable command)
    assert len(lines) == 1 and "journal" in lines[0] and f"pairplay recover {path}`" in lines[0], ran.stderr


def test_a_session_whose_journal_is_left_is_taken_and_force_removes_it(tmp_path):
    journal_of(tmp_path / "j1.mcap", [pick(1)])  # a killed recorder's, its recording moved away
    with pytest.raises(RecordingExists):
        check_new_recording(tmp_path / "j1.mcap")
    aside = set_aside(tmp_path / "j1.mcap")  # session --force: removed once the new session has started
    assert not wal_path(tmp_path / "j1.mcap").exists()
    settle_aside(aside, tmp_path / "j1.mcap", replaced=True)
    assert list(tmp_path.iterdir()) == []


# -- the recorder -----------------------------------------------------------------
def test_a_finished_recording_leaves_no_journal_and_a_failed_one_keeps_it(tmp_path):
    with listener() as bus:
        rec = Recorder(bus, "j1", tmp_path / "j1.mcap")
        rec.start()
        assert wal_path(rec.path).exists()
        assert rec.close() is None
        assert not wal_path(rec.path).exists() and read_log(rec.path).whole
        failing = Recorder(bus, "j2", tmp_path / "j2.mcap")
        failing.start()
        failing._fail("disk full (test)")
        failing.close()
        assert wal_path(failing.path).exists()


def test_a_journal_that_cannot_be_written_fails_the_recording_loudly_and_stays(tmp_path):
    failures = []
    with listener() as bus:
        rec = Recorder(bus, "j1", tmp_path / "j1.mcap", on_failure=failures.append)
        rec.start()
        os.close(rec.journal._fd)  # the journal's file can no longer be written (as a full disk)
        rec.enqueue(*start())
        assert wait_until(lambda: rec.journal.failure is not None, 10)
        assert wait_until(lambda: not rec.step(0.01) and rec.failure is not None, 10)
        rec.journal._fd = -1
        assert rec.close() is not None
    assert failures and "journal" in failures[0] and wal_path(rec.path).exists()


def test_a_restarted_recorder_takes_what_the_earlier_journal_holds(tmp_path):
    events = [start()] + [pick(s) for s in range(1, 31)]
    path = cut_recording(tmp_path, events[:11])
    journal_of(path, events + [pick(10**9)])
    rec = Recorder(None, "j1", path, restart=True)
    rec.close()
    log = read_log(rec.path)
    assert rec.path.name == "j1.1.mcap"
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 31))
    assert log.metadata["pairplay.recorder.journal"]["taken"] == "20"
    assert log.metadata["pairplay.recorder.journal"]["refused"] == "1"
    assert sum(isinstance(r.event, ev.MessageRejected) for r in log.events) == 1


def test_a_recorder_restarted_twice_keeps_what_each_earlier_recording_and_journal_holds(tmp_path):
    """The second restart's predecessor was killed before its first flush: its file is empty, its
    journal holds what it received live, but not what it had copied from the first file (a copy is
    not received). Before, the newest file and its journal alone were read: the first file's events
    and its journal's were not in the new file (what the services still had was refilled on a bus;
    the robot's, the recorder's own and a since-restarted service's were lost)."""
    events = [start()] + [pick(s) for s in range(1, 31)]
    path = cut_recording(tmp_path, events[:6])  # j1.mcap: cut after its 5th pick
    journal_of(path, events[:11])  # what its recorder had received: up to the 10th
    (tmp_path / "j1.1.mcap").write_bytes(b"")  # the restarted recorder, killed before its first flush
    journal_of(tmp_path / "j1.1.mcap", events[21:])  # what it received live: the 21st on
    rec = Recorder(None, "j1", path, restart=True)
    rec.close()
    assert rec.path.name == "j1.2.mcap"
    log = read_log(rec.path)
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == \
        list(range(1, 11)) + list(range(21, 31))  # (11-20: a bus's refill; nobody held them here)
    assert not log.of("MessageRejected")


def test_a_recorder_killed_with_a_backlog_loses_nothing_its_journal_held(tmp_path, pairplay_cli):
    """A burst faster than the recorder's writer, SIGKILL as soon as the journal holds the last
    event: the cut file lacks its unflushed tail and its backlog, if any (measured: 48-649 events
    at load 2; a loaded machine may let it catch up first); recover takes it all from the journal.
    Before the journal, what waited in the inbox died with the process."""
    n = 20_000
    with listener() as bus, recorder_process(bus, "jk", tmp_path) as rec:
        key = event_key("jk", "participant", "CardPicked")
        assert wait_until(lambda: bus.matching(key))
        bus.publisher(start("jk")[0]).put(start("jk")[1])  # its session's start: a recording recover completes
        burst = [encode_event(stamped(ev.CardPicked(round=0, turn=seq, card=seq % 18), session="jk",
                                      source="participant", seq=seq, time_ns=seq)) for seq in range(1, n + 1)]
        put = bus.publisher(key).put
        for payload in burst:  # as fast as this process can: faster than the recorder's writer
            put(payload)
        with open(wal_path(tmp_path / "jk.mcap"), "rb") as journal:
            tail = b""

            def journaled() -> bool:  # the last event is in the journal (read as it grows)
                nonlocal tail
                tail = tail[-len(burst[-1]):] + journal.read()
                return burst[-1] in tail

            assert wait_until(journaled, 30, 0.0005)
        sigkill(rec)
    cut = read_log(tmp_path / "jk.mcap")
    assert cut.truncated  # (what it lacks depends on the load: its unflushed tail, its backlog, or nothing)
    ran = pairplay_cli("recover", tmp_path / "jk.mcap")
    assert ran.returncode == 0, ran.stderr
    taken = n + 1 - len(cut.events)  # (its SessionStarted too, if the cut lost it)
    assert f"{counted(taken, 'event')} taken from its journal" in ran.stdout, ran.stdout  # "1 event" (a flaky run)
    log = read_log(tmp_path / "jk.recovered.mcap")
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, n + 1))


def test_a_flood_refused_live_then_a_sigkill_is_accounted_once_by_recover(tmp_path, pairplay_cli):
    """The same on a real bus: a `pairplay run recorder` refuses a flood of malformed messages (20
    one by one, the rest counted), is SIGKILLed once its file holds the count, and recover accounts
    for each refused message once (before: the counted ones twice)."""
    n = 500
    with listener() as bus, recorder_process(bus, "jf", tmp_path) as rec:
        key = event_key("jf", "participant", "CardPicked")
        assert wait_until(lambda: bus.matching(key))
        bus.publisher(start("jf")[0]).put(start("jf")[1])  # its session's start: a recording recover completes
        put = bus.publisher(key).put
        for i in range(n):
            put(b"{not json %d" % i)

        def accounted() -> bool:  # every refusal is in the file (one by one or counted), flushed
            try:
                return refusals_in(r.event for r in read_log(tmp_path / "jf.mcap").events) >= n
            except Exception:
                return False

        assert wait_until(accounted, 30, 0.05)
        assert wait_until(lambda: len(read_journal(wal_path(tmp_path / "jf.mcap")).records) >= n, 10)
        sigkill(rec)
    ran = pairplay_cli("recover", tmp_path / "jf.mcap")
    # (one holding no SessionStarted is refused, as by every verb: test_no_session.py)
    assert ran.returncode == 0, ran.stderr
    log = read_log(tmp_path / "jf.recovered.mcap")
    assert refusals_in(r.event for r in log.events) == n


# -- a complete recording: nothing to recover ---------------------------------------------
def complete_recording(tmp_path, events, name="j1.mcap", session="j1"):
    """A recording of `events` finished by its recorder (whole: summary, index, footer)."""
    live = Recorder(None, session, tmp_path / "live" / name, clock=iter(range(10**9, 10**10, 1000)).__next__)
    for i, (k, p) in enumerate(events):
        assert live.record(k, p, 10**9 + i)
    live.close()
    shutil.copy(live.path, tmp_path / name)
    return tmp_path / name


def test_recover_of_a_complete_file_writes_nothing_and_names_a_stale_journal(tmp_path, pairplay_cli):
    """A new user's trial, 2026-12-01: recover of a complete recording wrote a copy (<stem>.recovered.mcap)
    and said nothing of the stale journal beside it. Now: complete, nothing written, the journal's
    content said, and removed only when told (--discard-journal)."""
    events = [start()] + [pick(s) for s in range(1, 11)]
    path = complete_recording(tmp_path, events)
    before = path.read_bytes()
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0 and ran.stderr == "", ran.stderr
    # (its picks have no answer of the game: said too, as in any file whose game events went: trial33 E)
    assert ran.stdout.strip() == f"{path}: complete already ({len(read_log(path).events)} messages; 10 CardRevealed " \
        "or PickRejected of 'game' missing (0 for the 10 CardPicked of 'participant'): no recover gives them back; the " \
        "session's end was not recorded: a partial session); nothing to recover, nothing written", ran.stdout
    assert not (tmp_path / "j1.recovered.mcap").exists()
    (tmp_path / "j1.recovered.mcap").write_bytes(b"an older version's copy")  # not refused: nothing is written
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0 and "nothing written" in ran.stdout, ran.stderr
    assert (tmp_path / "j1.recovered.mcap").read_bytes() == b"an older version's copy"
    (tmp_path / "j1.recovered.mcap").unlink()
    journal = journal_of(path, events)  # a stale journal: everything it holds is in the file
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0 and ran.stderr == "", ran.stderr
    assert f"its journal j1.mcap.journal holds nothing more ({len(events)} events, all in the file)" in ran.stdout
    assert f"`pairplay recover {path} --discard-journal` removes it" in ran.stdout, ran.stdout
    assert journal.exists() and not (tmp_path / "j1.recovered.mcap").exists()
    ran = pairplay_cli("recover", path, "--discard-journal")
    assert ran.returncode == 0 and "removed (--discard-journal)" in ran.stdout, (ran.stdout, ran.stderr)
    assert not journal.exists() and path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["j1.mcap", "live"]
    ran = pairplay_cli("recover", path, "--discard-journal")
    assert ran.returncode == 2 and ran.stderr.strip().splitlines() == [
        f"pairplay recover: --discard-journal: there is no journal beside it ({path})"], ran.stderr


def test_a_journal_holding_more_than_a_complete_file_is_recovered_and_never_discarded(tmp_path, pairplay_cli):
    events = [start()] + [pick(s) for s in range(1, 11)]
    path = complete_recording(tmp_path, events[:9])
    journal = journal_of(path, events)  # 2 events more than the file
    ran = pairplay_cli("recover", path, "--discard-journal")
    lines = ran.stderr.strip().splitlines()
    assert ran.returncode == 2 and len(lines) == 1 and "its journal holds 2 records it lacks" in lines[0], ran.stderr
    assert journal.exists() and not (tmp_path / "j1.recovered.mcap").exists()
    ran = pairplay_cli("recover", path)
    assert ran.returncode == 0 and "2 events taken from its journal j1.mcap.journal" in ran.stdout, ran.stdout
    log = read_log(tmp_path / "j1.recovered.mcap")
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 11))
    assert journal.exists()  # recover never changes its inputs
    cut = cut_recording(tmp_path, events[:5], name="j2.mcap")
    ran = pairplay_cli("recover", cut, "--discard-journal")
    assert ran.returncode == 2 and "is not complete (cut short)" in ran.stderr, ran.stderr
    assert not (tmp_path / "j2.recovered.mcap").exists()


def test_what_the_journal_adds_goes_on_the_output_channel_of_its_topic_whatever_the_numbering(tmp_path, monkeypatch):
    """recover put a journal's events on the channel with the source file's id, which is the output's
    only while both writers number channels alike (a file another tool wrote, ids not 1, 2, ...)."""
    from mcap.writer import Writer

    import pairplay.replay.recover as recover_module

    class Shifted(Writer):  # numbers its channels from 2: channel 1 is an unused one it registers first
        def start(self, *args, **kwargs):
            super().start(*args, **kwargs)
            super().register_channel("unused", "json", 0)
    monkeypatch.setattr(recover_module, "Writer", Shifted)
    events = [start()] + [pick(s) for s in range(1, 41)]
    path = cut_recording(tmp_path, events[:21])
    journal_of(path, events)
    done = recover(path, admit=admit)
    assert done.from_journal == 20
    log = read_log(done.output)
    assert [r.event.seq for r in log.events if r.event.source == "participant"] == list(range(1, 41))
    assert all(r.key == event_key("j1", r.event.source, type(r.event).__name__) for r in log.events)


def test_a_recording_an_interrupted_force_left_aside_is_never_overwritten_and_keeps_the_id_taken(tmp_path):
    """A new user's trial: `session --force` killed (SIGKILL) before it settled left <name>.mcap.replaced, the
    real earlier recording. Nothing said it: a session without --force started beside it, and the next --force
    renamed the new fragment onto it (the earlier recording gone, even when that second --force was stopped
    and said "the earlier recordings are kept"). Now the set-aside file keeps the id taken and is named, with or
    without --force, until the user gives it back or removes it; a participant's export carries it."""
    from pairplay.services.recorder import RecordingExists, check_new_recording, set_aside

    path = tmp_path / "s1.mcap"
    earlier = tmp_path / "s1.mcap.replaced"
    earlier.write_bytes(b"the real earlier recording")
    (tmp_path / "s1.mcap").write_bytes(b"a fragment")
    for check in (check_new_recording, set_aside):
        with pytest.raises(RecordingExists, match=r"set aside by a `session --force` that was cut short"):
            check(path)
    (tmp_path / "s1.mcap").unlink()  # the fragment removed: the id is still taken by what was set aside
    with pytest.raises(RecordingExists, match=r"s1\.mcap\.replaced"):
        check_new_recording(path)
    assert earlier.read_bytes() == b"the real earlier recording"


def test_a_participants_export_carries_a_recording_a_cut_short_force_set_aside(tmp_path):
    """The same trial: `participant export` left out <game>.mcap.replaced, the participant's real game, and
    took the fragment beside it; `participant delete` removed it. Both now take it."""
    from pairplay.replay.studydata import StudyData
    from test_protocol import STUDY  # a small study file, as the protocol tests use

    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1")
    recording = data.folder / "recordings" / f"{data.session_id(pid, 'phase1', 0)}.mcap"
    recording.parent.mkdir(parents=True, exist_ok=True)
    aside = recording.with_name(recording.name + ".replaced")
    aside.write_bytes(b"the participant's real game")
    from pairplay.schemas import journal as j
    data.append(j.GameStarted(session=data.session_id(pid, "phase1", 0), participant=pid, phase="phase1", game=0,
                              recording=str(recording.relative_to(data.folder))))
    assert aside in data.files_of(pid)


def test_a_recorder_killed_before_its_session_began_is_said_to_hold_none_not_sent_to_recover(tmp_path, pairplay_cli):
    """A real `pairplay run recorder` SIGKILLed while it waits for its session: a file of 0 bytes and a journal
    of its header alone. Before (trial34 E): every reader said "the journal beside it holds what it received:
    `pairplay recover ...`", and recover then said the recording holds nothing. The journal is read first: it
    holds nothing, so no session was recorded, said in one line (exit 2), both named."""
    with listener() as bus, recorder_process(bus, "m4", tmp_path) as rec:
        assert wait_until(lambda: wal_path(tmp_path / "m4.mcap").exists(), 30)
        sigkill(rec)
    path = tmp_path / "m4.mcap"
    assert path.stat().st_size == 0 and not read_journal(wal_path(path)).records
    for verb in (["rebuild", path, "--out", tmp_path / "rb"], ["replay", path, "--verify"]):
        ran = pairplay_cli(*verb)
        assert ran.returncode == 2 and len(ran.stderr.splitlines()) == 1, ran
        assert "the file is empty (0 bytes): its recorder stopped before it wrote a record, and the journal beside " \
               "it (m4.mcap.journal) holds nothing: no session was recorded (remove both to reuse its session id)" \
               in ran.stderr and "pairplay recover" not in ran.stderr, ran.stderr
    ran = pairplay_cli("recover", path)  # which agrees
    assert ran.returncode == 2 and "holds no session" in ran.stderr, ran
