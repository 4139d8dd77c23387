"""A recorder SIGKILLed before its first flush and restarted within the live session continues it.

Before: its MCAP file held no message yet (only MCAP's magic and header), its journal (replay/wal.py)
what it had received; `pairplay run recorder` again read only the MCAP to decide whether the services
on the bus sent what the earlier recording holds (services/recorder.py `same_live_session`), found
nothing, and refused in one line ("a recording of this session exists"): the rest of the session went
unrecorded. Now every decision about what the earlier recording holds reads its journal where the
MCAP lacks it (`earlier_records`)."""

from __future__ import annotations

import signal
import subprocess
import time

from pairplay.replay.reader import read_any_log, read_log
from pairplay.replay.wal import MAGIC, read_journal, wal_path
from pairplay.schemas import events as ev

from busutil import wait_until
from cli_zygote import shared
from test_faults import endpoint_of, first_line, session_proc


def recorder(tmp_path, session: str, endpoint: str):
    """`pairplay run recorder` forked from this test process's zygote (tests/cli_zygote.py): SIGKILLed, or ended
    by its session's end; its start-up is not what is tested (each `python -m pairplay` paid ~0.9 s of CPU)."""
    return shared().start(["run", "recorder", "--session", session, "--out", str(tmp_path), "--connect", endpoint],
                          stdout=subprocess.DEVNULL)


def kill_before_first_flush(tmp_path, session: str, endpoint: str) -> None:
    """Start a recorder and SIGKILL it once its journal holds its first frame of records; its MCAP then as
    a kill before its first flush leaves it: no message (empty, or MCAP's magic and header; a file flushed
    since is cut back to its header). Before, the kill had to fall in the window between the journal's first write (every 5 ms)
    and the file's first flush (25 ms after its oldest message), four tries: at load 40-66 the test's own
    reaction missed it in all four ("the first flush came before the kill in every attempt")."""
    path = tmp_path / f"{session}.mcap"
    journal = wal_path(path)
    first = recorder(tmp_path, session, endpoint)
    try:
        assert wait_until(lambda: journal.exists() and journal.stat().st_size > 0, 60), "no journal"
        header = 0

        def records() -> bool:  # past the header frame: the header's size is read once it is complete
            nonlocal header
            data = journal.read_bytes()
            if not header and len(data) >= len(MAGIC) + 20:
                header = len(MAGIC) + 20 + int.from_bytes(data[len(MAGIC):len(MAGIC) + 4], "little")
            return bool(header) and len(data) > header

        assert wait_until(records, 60), "the journal never held a record"
        first.send_signal(signal.SIGKILL)
        first.wait(10)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    if read_any_log(path).events:  # flushed before the kill (a file killed before holds nothing yet, or less)
        data = path.read_bytes()  # magic (8 bytes), then the Header record: opcode, u64 length, content
        assert data[:8] == b"\x89MCAP0\r\n" and data[8] == 0x01, data[:16]
        with open(path, "r+b") as f:
            f.truncate(8 + 9 + int.from_bytes(data[9:17], "little"))
        assert not read_any_log(path).events


def test_a_recorder_killed_before_its_first_flush_and_restarted_continues_the_session(tmp_path, pairplay_cli):
    session = "rk"
    p = session_proc(tmp_path, "--participant", "sim:ashley", "--rounds", "5000", "--session", session,
                     "--external", "recorder")
    second = None
    try:
        endpoint = endpoint_of(first_line(p))
        kill_before_first_flush(tmp_path, session, endpoint)
        journaled = read_journal(wal_path(tmp_path / f"{session}.mcap")).records
        assert journaled
        second = recorder(tmp_path, session, endpoint)
        # once the restarted recorder has refilled the gap (its RecordingGap is in its file), the
        # session is stopped (as its experimenter would: seconds, not its 5,000 rounds; with 150 a quick
        # machine could play them all first and end it "completed", not "interrupted")
        assert wait_until(lambda: second.poll() is not None or read_any_log(tmp_path / f"{session}.1.mcap").of(
            "RecordingGap") if (tmp_path / f"{session}.1.mcap").exists() else second.poll() is not None,
            120, 0.1)
        assert second.poll() is None, second.stderr.read()
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=60)
        assert second.wait(timeout=30) == 0, second.stderr.read()
    finally:
        for proc in (p, second):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert p.returncode == 143  # (SIGTERM's)
    path = tmp_path / f"{session}.1.mcap"
    ran = pairplay_cli("replay", "--verify", path)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    log = read_log(path)
    assert log.whole and not log.bad
    gaps = [r.event for r in log.events if isinstance(r.event, ev.RecordingGap)]
    assert len(gaps) == 1 and gaps[0].earlier_file == f"{session}.mcap" and gaps[0].copied > 0
    assert log.metadata["pairplay.recorder.journal"]["taken"] == str(gaps[0].copied)
    payloads = {r.payload for r in log.events}
    lost = [k for k, p, _ in journaled if not k.split("/")[2] == "recorder" and p not in payloads]
    assert not lost, lost[:5]  # nothing received before the kill is lost
    for source in ("game", "learner", "participant"):  # ... nor doubled, nor missing since
        seqs = sorted(r.event.seq for r in log.events if r.event.source == source)
        assert seqs == list(range(1, len(seqs) + 1)), source
    assert len(log.of("SessionStarted")) == 1
    assert [e.reason for e in log.of("SessionEnded")] == ["interrupted"], log.of("SessionEnded")
    # (suggestions the bridge had not reported when SIGTERM closed it are counted as not reported; a pick the
    # participant made as the SIGTERM came reaches the game after its end, and is refused and recorded so: a
    # full suite under load)
    refused = [r.event.reason for r in log.events if isinstance(r.event, ev.MessageRejected)
               and "not reported" not in r.event.reason and not r.event.reason.startswith("the session is over; ")]
    assert not refused, refused[:5]


def test_a_recorder_killed_mid_session_gets_the_robots_reports_of_its_outage_refilled(tmp_path):
    """The robot bridge answers a restarted recorder's refill query as the other services do
    (services/robot/bridge.py, runner.py `answer_sent`). Before, nobody answered for the robot: the
    RobotActed the virtual robot reported while the recorder was down were missing from the file, a
    hole in the robot's numbers, each counted at the close as a suggestion not reported, and the
    RecordingGap named the robot unanswered."""
    session = "rkr"
    p = session_proc(tmp_path, "--participant", "sim:ashley", "--rounds", "5000", "--session", session,
                     "--external", "recorder")
    first = second = None
    path, restarted = tmp_path / f"{session}.mcap", tmp_path / f"{session}.1.mcap"
    try:
        endpoint = endpoint_of(first_line(p))
        first = recorder(tmp_path, session, endpoint)
        assert wait_until(lambda: path.exists() and len(read_any_log(path).of("RobotActed")) >= 20, 60), "no robot"
        # the session plays on, the robot reports, nobody records: the recorder frozen, its token still on the bus
        # (a link whose loss is not noticed yet); killed, its token goes and the game is held until a recorder is
        # back (services/recorderwatch.py), and the robot reports what it still performs
        first.send_signal(signal.SIGSTOP)
        time.sleep(1.0)
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        second = recorder(tmp_path, session, endpoint)
        # its refill written (the RecordingGap), and the robot caught up past it: every suggestion made before the
        # gap has its RobotActed, and the robot acted on some made after it. The wait is for exactly that, not
        # for reports after the gap alone: the robot does NOT report in suggestion order (a superseded smile
        # waits up to its gesture's end, 0.8 s, or abort_grace_s, while the quick ones after it report at once;
        # docs/robot.md), so "5 acted after the gap" let a SIGTERM come while one made 42 ms before the gap
        # still waited for its reply; the loaded bridge's close could not report it in the shutdown's deadline
        # and counted it "not reported" (2 of 7 CI runs; traced here, 11 runs at load 20-33: in 3 a suggestion
        # made before the gap, one 40 ms before it, was reported 51-413 ms after the fifth made after it; they
        # passed only because the loaded test's SIGTERM came 0.8-2.8 s later)
        waiting: list = ["no gap refilled"]  # what the wait still waits for (its failure's message)

        def caught_up(log) -> bool:
            gaps = log.of("RecordingGap")
            if not gaps:
                return False
            acted = {e.suggestion_seq for e in log.of("RobotActed")}
            made = log.of("SuggestionMade")
            before = {e.seq for e in made if e.time_ns < gaps[0].time_ns}
            after = {e.seq for e in made if e.time_ns >= gaps[0].time_ns}
            # (one never acted on while the session lives: lost on its way to the robot, the refill's burst or not)
            waiting[:] = [f"suggestions made before the gap without RobotActed: {sorted(before - acted)[:10]}; "
                          f"acted on after it: {len(after & acted)}"]
            return before <= acted and len(after & acted) >= 5
        assert wait_until(lambda: second.poll() is not None or restarted.exists() and caught_up(read_any_log(restarted)),
                          60, 0.1), waiting[0]
        assert second.poll() is None, second.stderr.read()
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=60)
        assert second.wait(timeout=30) == 0, second.stderr.read()
    finally:
        for proc in (p, first, second):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.communicate()
    log = read_log(restarted)
    [gap] = log.of("RecordingGap")
    assert "robot" in gap.refilled_from and "robot" not in gap.unanswered, gap
    acted = {e.suggestion_seq for e in log.of("RobotActed")}
    # every suggestion made before the refill was done (the earlier file's, the outage's) has its report;
    # at the end SIGTERM may leave the newest few unreported (a smile waits ~0.8 s for its gesture's end):
    # counted, and only those
    before = {e.seq for e in log.of("SuggestionMade") if e.time_ns < gap.time_ns}
    assert len(before) > 100 and sorted(before - acted) == [], "RobotActed of the outage not refilled"
    tail = {e.seq for e in log.of("SuggestionMade") if e.time_ns >= gap.time_ns} - acted
    robot = sorted(r.event.seq for r in log.events if r.event.source == "robot")
    assert robot == list(range(1, len(robot) + 1))  # no hole in the robot's numbers, none twice
    counted = sum(int(e.reason.split()[0]) for e in log.of("MessageRejected")
                  if "not reported" in e.reason and e.reason.split()[0].isdigit())
    assert counted == len(tail), (counted, sorted(tail))  # not-reported: the tail only, none of the outage's (how many: load)


def _a_recorded_game_not_yet_running(bus, session: str, path):
    """A game's Node on `bus`, started (its ServiceStarted, SessionStarted, RoundStarted published and recorded
    to `path` by a recorder, closed since) but its thread not run: its queries wait in its inbox until the test
    runs it (`game.run_in_thread`), as behind a busy step."""
    from pairplay.schemas.session import SessionConfig
    from pairplay.services.game import GameLogic
    from pairplay.services.recorder import Recorder
    from pairplay.services.runner import Node

    config = SessionConfig(session=session, participant="human:t", seed=1, rounds=3, observed_source="first-pick",
                           ignore_rule="time")
    first = Recorder(bus, session, path)
    first.start()
    game = Node(bus, GameLogic(config), session, resume=False)
    game.start()
    assert wait_until(lambda: first.step(0.05) and False or
                      sum(k.split("/")[2] == "game" for k, _ in first.kept) >= 3, 60)
    first.close()
    return game


def test_a_restarted_recorders_refill_asks_again_a_live_service_that_has_not_answered_yet(tmp_path):
    """A service on the bus whose answer to the restart's refill comes after the ask's REFILL_TIMEOUT_S (its
    thread busy: at load 40-66 the game's, learner's or participant's) is asked again, and the one RecordingGap
    says what every ask gave. Before, the first ask decided: the service was recorded as unanswered and what it
    would have given back as lost (test_recorder_continues_losses' live restart named the missing events;
    test_faults' restarted recorder lacked a source in `refilled_from`).

    Real parts: the game's Node on a real bus, its queries answered only once the test lets its thread run
    (until then each waits in its inbox, as behind a busy step); a real Recorder, then a second one restarted."""
    import threading

    from pairplay.services.bus import Deadline
    from pairplay.services.recorder import Recorder

    from busutil import listener

    s = "slow"
    path = tmp_path / f"{s}.mcap"
    with listener() as bus:
        game = _a_recorded_game_not_yet_running(bus, s, path)
        second = Recorder(bus, s, path, restart=True)
        second.start()  # its first ask: the game's thread has not run, its answer waits
        gaps = lambda: [k for k, _ in second.kept if k.endswith("/RecordingGap")]  # noqa: E731
        stop = threading.Event()
        game.run_in_thread(stop)  # the game's thread runs now: the next ask is answered
        try:
            assert wait_until(lambda: second.step(0.05) and False or bool(gaps()), 120)
        finally:
            second.close(deadline=Deadline(5.0))
            stop.set()
            game.thread.join(10)
            game.close()
    [gap] = [r.event for r in read_log(second.path).events if isinstance(r.event, ev.RecordingGap)]
    assert gap.refilled_from == ["game"] and gap.unanswered == [], gap


def test_a_restarted_recorder_asks_again_a_live_session_that_has_not_answered_yet(tmp_path):
    """Whether the session on the bus is the recording's (`same_live_session`) was one ask of 3 s: a live service
    busy past it (load 40-66) had the restarted recorder refuse its own session ("no live session on the bus
    sent what it holds"). Now, while a service of the session is on the bus (its token), a silent one is asked
    again; with nobody of the session there, the answer is no at once.

    Real parts: the game's Node on a real bus, its queries answered only once the test lets its thread run (the
    first ask waits in its inbox, as behind a busy step), a real recording of its events."""
    import threading

    from pairplay.services.recorder import same_live_session

    from busutil import connector, listener

    s = "silent"
    path = tmp_path / f"{s}.mcap"
    with listener() as bus:
        game = _a_recorded_game_not_yet_running(bus, s, path)
        said: list[bool] = []
        stop = threading.Event()
        with connector(bus) as client:  # the restarted recorder's own bus
            asking = threading.Thread(target=lambda: said.append(same_live_session(client, s, path)), daemon=True)
            asking.start()
            try:
                # the game runs once it holds a second ask (the first timed out unanswered), or the asking ended
                assert wait_until(lambda: len(game.inbox) >= 2 or not asking.is_alive(), 120)
                game.run_in_thread(stop)
                asking.join(60)
            finally:
                stop.set()
                game.thread.join(10)
                game.close()
        assert said == [True], said
    # nobody of the session on the bus: no, at once (one ask). A bus of its own: the tokens of the game and the first
    # recorder are the bus's until it closes (Bus._keep), and the ask on it went on through all SAME_SESSION_ASKS
    # (3 + 6 + 6 s unanswered: 15 of the test's 18 s) to the same False
    with listener() as empty:
        assert not same_live_session(empty, s, path)



def test_the_earlier_file_of_a_restarted_recorder_names_the_file_that_continues_it(tmp_path, pairplay_cli):
    """trial34 N: after a restart in place, every verb reading the killed recorder's file (`rebuild`, `replay
    --verify`, `view`) said PARTIAL and "`pairplay recover` adds them" (its journal), and nothing of the restarted
    recorder's file beside it that holds the whole session: following the advice made a third, partial copy. Now
    the line every such verb says (replay/recover.py `journal_left`) names that file instead."""
    from loopback_session import loopback_events
    from pairplay.replay.continued import continued_in
    from pairplay.replay.recover import journal_left
    from pairplay.replay.writer import EventLogWriter
    from pairplay.schemas.envelope import stamped
    from pairplay.schemas.events import Nanos, encode_event
    from pairplay.schemas.keys import event_key
    from pairplay.schemas.session import SessionConfig

    config = SessionConfig(session="c2", participant="sim:deaf", persona="deaf", seed=4, rounds=3)
    events = list(loopback_events(config))
    gap = stamped(ev.RecordingGap(earlier_file="c2.mcap", copied=len(events) // 2, last_copied_ns=Nanos(1),
                                  resumed_ns=Nanos(2)), session="c2", source="recorder", seq=1, time_ns=3)

    def write(path, chosen) -> None:
        w = EventLogWriter(path)
        for i, e in enumerate(chosen):
            w.write(event_key(e.session, e.source, type(e).__name__), encode_event(e), log_time_ns=10**18 + i,
                    sequence=e.seq)
        w.close()
    earlier, later = tmp_path / "c2.mcap", tmp_path / "c2.1.mcap"
    write(earlier, events[:len(events) // 2])  # the part the killed recorder wrote
    write(later, events)  # a file named as a continuation that does not say it continues c2.mcap: not taken
    assert continued_in(earlier) is None
    later.unlink()
    write(later, [*events, gap])
    assert continued_in(earlier) == later
    line = journal_left(earlier)
    assert line == "a restarted recorder continued it in c2.1.mcap beside it, which holds the whole session from " \
                   "this file's events on: give that instead", line
    ran = pairplay_cli("rebuild", earlier, "--out", tmp_path / "rb", "--partial")
    assert "a restarted recorder continued it in c2.1.mcap" in ran.stderr, ran.stdout + ran.stderr
    data = earlier.read_bytes()  # cut, as the kill left it: recover writes its copy
    earlier.write_bytes(data[:len(data) * 2 // 3])
    ran = pairplay_cli("recover", earlier)  # (trial35 N1: recover alone said nothing of it)
    assert ran.returncode == 0 and (tmp_path / "c2.recovered.mcap").is_file(), ran.stdout + ran.stderr
    assert "a restarted recorder continued it in c2.1.mcap beside it" in ran.stderr, ran.stdout + ran.stderr
    ran = pairplay_cli("recover", earlier)  # over its own output: the refusal alone (trial36 R1: the warning first)
    assert ran.returncode == 2 and len(ran.stderr.strip().splitlines()) == 1, ran.stderr
