"""A service SIGKILLed mid-session and restarted (issue 12 item 5): behind a `pairplay router`
with `--recover` (every process a client; Zenoh's advanced publishers replay their caches to the
restarted service, which joins late) and behind the session's own process as the router (no
`--recover`: what a lab does with `pairplay session --external <service>`; the one-process
`pairplay session` has no service of its own to lose).

The learner, the participant and the robot bridge (`pairplay run learner|participant`, `pairplay
robot`) are killed once the game is under way and started again with the same command: the
restarted service takes its state from the recorder's log, skips the caches' history of what the
log held (its cut point, services/guard.py), and the session completes and verifies; every
source's sequence numbers are in the file once each without a gap (the robot's too: a restarted
bridge numbered from 1 again), every suggestion is rewarded once, every suggestion has one
RobotActed or is counted as not reported, nothing is refused as a repeat, and the restart is
recorded (a second ServiceStarted with `resumed_events`, and the service's absence,
`pairplay.recorder.absence`)."""

from __future__ import annotations

import signal
import threading
from collections import Counter

import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.events import decode_event
from pairplay.schemas.keys import alive_key
from pairplay.schemas.robot import RobotActed
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.participant import ParticipantLogic
from pairplay.services.recorder import ABSENCE_METADATA
from pairplay.services.runner import Node
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

from busutil import wait_until
from cli_zygote import shared
from test_router import free_port, start_router


class HeldParticipant(ParticipantLogic):
    """The simulated participant, held while `gate` is clear (a person thinking): the session then
    cannot end while the robot bridge is down, whatever the machine's speed."""

    def __init__(self, gate: threading.Event):
        super().__init__()
        self.gate = gate

    def handle(self, event):
        self.gate.wait(60)
        return super().handle(event)


def metadata_all(path, name: str) -> list[dict]:
    """Every metadata record of that name, in file order (read_log keeps the last of each)."""
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        return [dict(m.metadata) for m in make_reader(f).iter_metadata() if m.name == name]


def held_participant(session: str, endpoint: str, recover: bool, gate: threading.Event,
                     stop: threading.Event) -> None:
    """The participant as a client of the session's router, as its own process would be: it
    leaves the bus when the session has ended for it."""
    bus = Bus(BusOptions(mode="client", connect=[endpoint], recovery=recover))
    try:
        node = Node(bus, HeldParticipant(gate), session, stop=stop)
        node.start()
        node.run(stop)
        node.close(1.0)
    finally:
        bus.close()


def spawn(victim: str, session: str, endpoint: str, recover: bool):
    """The victim's own process, forked from this test process's zygote (tests/cli_zygote.py): SIGKILL and a
    restart, not its start-up, are what is tested (each `python -m pairplay` paid ~0.9 s of CPU importing)."""
    verb = ["robot", "--robot", "virtual"] if victim == "robot" else ["run", victim]
    return shared().start([*verb, "--session", session, "--connect", endpoint, *(["--recover"] if recover else [])])


def restart_mid_session(tmp_path, victim: str, recover: bool, rounds: int = 10):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = start_router(port) if recover else None
    session = f"rs-{victim}-{int(recover)}"
    config = SessionConfig(session=session, participant="sim:ashley", persona="ashley", seed=3, rounds=rounds)
    options = (BusOptions(mode="client", connect=[endpoint], recovery=True) if recover
               else BusOptions(mode="router", listen=[endpoint]))
    gate, stop = threading.Event(), threading.Event()
    gate.set()
    nodes, box, started = {}, {}, []
    external = (victim,) + (("participant",) if victim == "robot" else ())

    def on_bus(bus):
        box["bus"] = bus
        bus.subscribe(f"pairplay/{session}/*/ServiceStarted",
                      lambda _k, p: started.append(decode_event(p)))

    runner = threading.Thread(target=lambda: box.setdefault("path", run_session(
        config, tmp_path / f"{session}.mcap", bus_options=options, external=external, on_bus=on_bus, stop=stop,
        nodes_out=nodes, settle_timeout_s=30)), daemon=True)
    first = second = None
    try:
        runner.start()
        if victim == "robot":  # the participant on a bus of its own, held while the bridge is down
            assert wait_until(lambda: "bus" in box, 30)
            threading.Thread(target=held_participant, args=(session, endpoint, recover, gate, stop), daemon=True).start()
        first = spawn(victim, session, endpoint, recover)
        assert wait_until(lambda: "game" in nodes and nodes["game"].driver.seq >= 150, 60), "the game did not start"
        gate.clear()
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        bus = box["bus"]
        gone = alive_key(session, victim)
        assert wait_until(lambda: gone not in bus.alive_now(alive_key(session, "*")), 15)
        second = spawn(victim, session, endpoint, recover)
        assert wait_until(lambda: any(e.resumed_events > 0 for e in started if e.source == victim), 30), \
            second.stderr.read() if second.poll() is not None else "no resumed ServiceStarted"
        gate.set()
        runner.join(60)
        assert not runner.is_alive(), "the session did not finish after the restart"
        assert second.wait(30) == 0, second.stderr.read()[-2000:]
    finally:
        gate.set()
        stop.set()
        runner.join(10)
        for p in (first, second, router):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    return box["path"]


@pytest.mark.parametrize("victim,recover", [("learner", True), ("participant", True), ("robot", True),
                                            ("robot", False)])
def test_a_service_killed_and_restarted_mid_session_resumes_from_the_log(tmp_path, victim, recover):
    path = restart_mid_session(tmp_path, victim, recover)
    log = read_log(path)
    assert not log.truncated and not log.bad
    events = [r.event for r in log.events]
    for source in ("game", "learner", "participant", "robot"):  # nothing lost, nothing doubled
        seqs = [e.seq for e in events if e.source == source]
        assert sorted(seqs) == list(range(1, len(seqs) + 1)), source
    ended = [e for e in events if isinstance(e, ev.SessionEnded)]
    assert len(ended) == 1 and ended[0].reason == "completed"
    made = Counter((e.round, e.turn, e.attempt) for e in events if isinstance(e, ev.SuggestionMade))
    rewarded = Counter((e.round, e.turn, e.attempt) for e in events if isinstance(e, ev.RewardGiven))
    assert rewarded == made and max(rewarded.values()) == 1
    starts = [e for e in events if isinstance(e, ev.ServiceStarted) and e.source == victim]
    assert len(starts) == 2 and starts[0].resumed_events == 0 and starts[1].resumed_events > 0
    refused = [e.reason for e in events if isinstance(e, ev.MessageRejected)
               and "not reported" not in e.reason]
    assert not refused, refused[:5]  # the caches' history of what the log held is not a repeat
    if victim == "robot":  # every suggestion has its one RobotActed, or is counted as not reported
        suggestions = {e.seq for e in events if isinstance(e, ev.SuggestionMade)}
        acted = Counter(e.suggestion_seq for e in events if isinstance(e, RobotActed))
        counted = sum(int(e.reason.split()[0]) for e in events if isinstance(e, ev.MessageRejected)
                      and e.offending_source == "robot" and "not reported" in e.reason)
        assert max(acted.values()) == 1 and len(suggestions - set(acted)) == counted
        assert counted > 0 and len(acted) > counted  # the crashed bridge's are counted, the rest performed
    absences = metadata_all(path, ABSENCE_METADATA)
    assert [a["service"] for a in absences] == [victim]
    assert int(absences[0]["back_ns"]) > int(absences[0]["left_ns"]) > 0
    assert verify_recording(path).ok


def test_a_robot_bridge_still_reading_the_log_is_not_on_the_bus_so_its_first_start_resumes_nothing(tmp_path):
    """trial29 F1: the bridge declared its token (what the waiting game starts the session on) before it read the
    log, so a game could start in between and the bridge's FIRST start said `resumed_events=4`, the session's first
    events taken for its own earlier life. Held just before its log query (pairplay/testpause.py `log-query`), the
    bridge is not on the bus yet, and its one start resumes nothing (services/runner.py `join_log`)."""
    import os
    import subprocess
    import sys

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    session = "rs-robot-first"
    config = SessionConfig(session=session, participant="sim:ashley", persona="ashley", seed=3, rounds=2)
    stop, box = threading.Event(), {}
    runner = threading.Thread(target=lambda: box.setdefault("path", run_session(
        config, tmp_path / f"{session}.mcap", bus_options=BusOptions(mode="router", listen=[endpoint]),
        external=("robot",), on_bus=lambda bus: box.setdefault("bus", bus), stop=stop)), daemon=True)
    go = tmp_path / "go"
    # its own process, not the zygote's fork: the pause is named in its environment
    bridge = subprocess.Popen([sys.executable, "-m", "pairplay", "robot", "--robot", "virtual", "--session", session,
                               "--connect", endpoint], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, "PAIRPLAY_TEST_PAUSE": f"log-query:{go}"})
    try:
        runner.start()
        assert next(line for line in bridge.stderr if line.startswith("pairplay-test:")) == \
            "pairplay-test: paused at log-query\n"
        assert wait_until(lambda: "bus" in box, 30)
        assert alive_key(session, "robot") not in box["bus"].alive_now(alive_key(session, "*"))
        go.touch()
        runner.join(60)
        assert not runner.is_alive(), "the session did not finish"
        assert bridge.wait(30) == 0, bridge.stderr.read()[-2000:]
    finally:
        go.touch()
        stop.set()
        runner.join(10)
        if bridge.poll() is None:
            bridge.kill()
            bridge.wait()
    events = [r.event for r in read_log(box["path"]).events]
    starts = [e for e in events if isinstance(e, ev.ServiceStarted) and e.source == "robot"]
    assert [e.resumed_events for e in starts] == [0]
    assert [e.reason for e in events if isinstance(e, ev.SessionEnded)] == ["completed"]
