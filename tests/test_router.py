"""A router of its own (`pairplay router`) restarted mid-session on loopback: the session's
services, the participant and the recorder are clients in three Zenoh sessions of their own, so
every message between them crosses the router. The router is SIGKILLed while the game waits for
picks and restarted ~1.5 s later: the session finishes, verifies, each source's sequence numbers
are in the file once each without a gap, and the outage is recorded. The same with caches of one
message (Zenoh cannot bring the outage back): the recorder refills it from the services' own
records and records the gap (RecordingGap)."""

from __future__ import annotations

import socket
import threading
import time


from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.participant import ParticipantLogic
from pairplay.services.recorder import LINK_METADATA, Recorder
from pairplay.services.runner import Node
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

from cli_zygote import shared


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_router(port: int):
    """`pairplay router` on that port, listening: forked from this test process's zygote (tests/cli_zygote.py;
    its start-up and its signals are not what the tests that use it test: it is killed, SIGKILL, or ended)."""
    p = shared().start(["router", "--listen", f"tcp/127.0.0.1:{port}"])
    assert p.stdout.readline().startswith(f"listening tcp/127.0.0.1:{port}")
    return p


def test_router_verb_refuses_a_port_in_use_on_one_line(pairplay_cli):
    port = free_port()
    first = start_router(port)
    try:
        second = pairplay_cli("router", "--listen", f"tcp/127.0.0.1:{port}", timeout=30)  # its words and exit
    finally:
        first.terminate()
        first.wait(10)
    assert second.returncode == 2 and second.stderr.count("\n") == 1 and "pairplay router" in second.stderr
    assert first.returncode == 143  # SIGTERM: 128 + 15, as every verb (cli/main.py), after a clean stop
    out, err = first.communicate(timeout=10)
    assert (out, err) == ("", "pairplay router: stopped (SIGTERM)\n")  # the stop's line on stderr, as every verb's (was stdout)


def run_through_router(tmp_path, session: str, rounds: int, cache_samples: int, outage_s: float = 1.5,
                       remote_participant: bool = True, until=None):
    """`until(recorder)`: stop the session (aborted) once it holds, instead of playing every round."""
    port = free_port()
    endpoint = [f"tcp/127.0.0.1:{port}"]
    router = start_router(port)
    opts = lambda: BusOptions(mode="client", connect=endpoint, recovery=True, cache_samples=cache_samples)  # noqa: E731
    config = SessionConfig(session=session, participant="sim:ashley", persona="ashley", seed=3, rounds=rounds)
    rec_bus, board_bus = Bus(opts()), Bus(opts())
    recorder = Recorder(rec_bus, session, tmp_path / f"{session}.mcap")
    recorder.start()
    rec_stop, stop = threading.Event(), threading.Event()
    rec_thread = threading.Thread(target=recorder.run, args=(rec_stop,), daemon=True)
    rec_thread.start()
    board = Node(board_bus, ParticipantLogic(), session, stop=stop)

    def play() -> None:  # and leave the bus once the session has ended for it, as its own process would: the
        board.run(stop)  # session waits for its external services to leave (before, 20 s of settle_timeout_s)
        board.close(1.0)
        board_bus.close()
    if remote_participant:  # else the session's own process plays too, and goes on while the router is down
        board.start()
        board_thread = threading.Thread(target=play, daemon=True)
        board_thread.start()
    nodes: dict = {}
    done: dict = {}
    runner = threading.Thread(target=lambda: done.setdefault("path", run_session(
        config, tmp_path / "unused.mcap", bus_options=opts(), external=("recorder", "participant") if remote_participant else ("recorder",), stop=stop,
        nodes_out=nodes, settle_timeout_s=20)), daemon=True)
    t0 = time.monotonic()
    runner.start()
    try:
        while "game" not in nodes or nodes["game"].driver.seq < 50:  # the game is under way
            assert time.monotonic() - t0 < 60 and runner.is_alive()
            time.sleep(0.01)
        router.kill()  # a crash, not a close
        router.wait()
        killed_at_seq = nodes["game"].driver.seq
        time.sleep(outage_s)
        router = start_router(port)
        restarted = time.monotonic()
        while until is not None and not until(recorder) and time.monotonic() - restarted < 60:
            time.sleep(0.02)
        if until is not None:
            stop.set()
        runner.join(60)
        assert not runner.is_alive(), "the session did not finish after the router came back"
        finished = time.monotonic()
        # the recorder has the session's end, then its refill after the link's return has had its time
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (not recorder.ended or recorder._refill_at is not None
                                               or recorder._link_lost_ns is not None or len(recorder.inbox)):
            time.sleep(0.02)
        if not remote_participant:  # never started: its Outbox's thread only (play closes a started one)
            board.close(1.0)
    finally:
        stop.set()
        rec_stop.set()
        rec_thread.join(5)
        if remote_participant:
            board_thread.join(10)
        recorder.close()
        for bus in (rec_bus, board_bus):
            bus.close()
        router.kill()
        router.wait()
    return {"path": tmp_path / f"{session}.mcap", "killed_at_seq": killed_at_seq, "recorder": recorder,
            "after_restart_s": finished - restarted}


def check_whole(path, reason="completed", verify=True):
    log = read_log(path)
    assert not log.truncated and not log.bad
    events = [r.event for r in log.events]
    for source in ("game", "learner", "participant"):  # nothing lost, nothing doubled
        seqs = [e.seq for e in events if e.source == source]
        assert sorted(seqs) == list(range(1, len(seqs) + 1)), source
    ended = [e for e in events if isinstance(e, ev.SessionEnded)]
    assert len(ended) == 1 and ended[0].reason == reason
    checked = verify_recording(path)
    if verify:
        assert checked.ok
    else:  # a session stopped mid-turn: every derived event agrees up to the stop, whose end verify cannot foresee
        wrong = [m for c in checked.checks for m in c.mismatches]
        assert len(wrong) <= 1 and all("SessionEnded seq" in m for m in wrong), wrong
    return log, events


def test_a_router_restart_mid_session_loses_and_doubles_nothing(tmp_path):
    run = run_through_router(tmp_path, "rt1", rounds=4, cache_samples=10_000)
    log, events = check_whole(run["path"])
    outage = log.metadata[LINK_METADATA]  # the outage is recorded (the last one, if several)
    assert int(outage["back_ns"]) > int(outage["lost_ns"])
    assert not [e for e in events if isinstance(e, ev.MessageRejected)]  # Zenoh brought back everything, once


def refilled_and_no_hole(recorder) -> bool:
    """The recorder has refilled a gap and has nothing more to ask (the session may stop now)."""
    with recorder._lock:
        gap = any(k.endswith("/RecordingGap") for k, _ in recorder.kept)
    return gap and recorder._refill_at is None and not recorder._link_down


def test_what_the_caches_lost_is_refilled_from_the_services_and_the_gap_recorded(tmp_path):
    run = run_through_router(tmp_path, "rt2", rounds=300, cache_samples=1, remote_participant=False,
                             until=refilled_and_no_hole)
    log, events = check_whole(run["path"], reason="aborted", verify=False)
    gaps = [e for e in events if isinstance(e, ev.RecordingGap)]
    assert len(gaps) >= 1 and gaps[0].earlier_file == "" and gaps[0].refilled > 0
    assert {"game", "learner", "participant"} <= set(gaps[0].refilled_from)
