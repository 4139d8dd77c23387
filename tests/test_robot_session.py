"""A whole simulated session on the bus with the robot bridge: every suggestion performed once, recorded."""

from __future__ import annotations

import threading

from busutil import listener, wait_until
from robot_doubles.harness import FAST

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.robot import RobotActed
from pairplay.schemas.session import SessionConfig
from pairplay.services.recorder import Recorder
from pairplay.services.robot.bridge import RobotBridge
from pairplay.services.session import run_session

SESSION = "robot-session"


def test_every_suggestion_of_a_session_gets_one_robot_act(tmp_path):
    bus = listener()
    ours = tmp_path / "with-robot.mcap"  # our own recorder: it stays until the bridge has settled
    recorder = Recorder(bus, SESSION, ours)
    recorder.start()
    recorder_stop = threading.Event()
    recorder_thread = threading.Thread(target=recorder.run, args=(recorder_stop,), daemon=True)
    recorder_thread.start()
    bridges: list[RobotBridge] = []

    def with_robot(session_bus) -> None:  # what `pairplay session --robot virtual` does
        bridge = RobotBridge(session_bus, SESSION, "virtual?time_scale=0", config=FAST).start()
        bridge.run_in_thread(threading.Event())
        bridges.append(bridge)

    config = SessionConfig(session=SESSION, participant="sim:wasim", persona="wasim", seed=4, rounds=2)
    try:
        run_session(config, tmp_path / "session.mcap", bus=bus, on_bus=with_robot)
        bridges[0].thread.join(10)  # it leaves after SessionEnded, once every suggestion is reported
        assert not bridges[0].thread.is_alive()
        # Zenoh hands the last RobotActed to our recorder on its own thread: wait for it there
        kept = lambda tag: sum(k.endswith("/" + tag) for k, _ in recorder.kept)  # noqa: E731
        assert wait_until(lambda: kept("RobotActed") == kept("SuggestionMade") > 0, 10)
    finally:
        recorder_stop.set()
        recorder_thread.join(5)
        recorder.close()
        bus.close()
    events = [r.event for r in read_log(ours).events]
    made = {e.seq: e for e in events if isinstance(e, ev.SuggestionMade)}
    acted = [e for e in events if isinstance(e, RobotActed)]
    assert made and sorted(a.suggestion_seq for a in acted) == sorted(made)
    for a in acted:
        m = made[a.suggestion_seq]
        assert (a.round, a.turn, a.attempt, a.action) == (m.round, m.turn, m.attempt, m.action)
        assert a.outcome in ("done", "sent", "nothing", "aborted") and a.source == "robot"
    assert not [e for e in events if isinstance(e, ev.MessageRejected) and e.source == "robot"]
