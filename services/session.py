"""One whole session over the bus, recorded: the work behind `pairplay session`.

Rule: the recorder starts first, then the learner and the participant (each a
Node with its liveliness token), and the game last: it waits until every
service the session needs is on the bus, then announces the session. All run
in this process on one Zenoh session unless `external` leaves a service to
another process, which the game then waits for. The session is over when the
game has ended it and every service has settled (in-process threads finished,
external services' tokens gone); then the recorder finishes its file.
Every session ends with a SessionEnded that says why: "completed" (the game
played every round), "interrupted" (SIGINT/SIGTERM: `stop.why` names the
signal), "aborted" (the caller's `stop` without a signal: the experimenter) or
"failed" (a service the session needs left the bus and did not come back within
`settle_timeout_s`), with how far it got; the robot's suggestions still awaiting
an acknowledgement are recorded as "in-flight" (schemas/robot.py).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from pairplay.schemas.keys import alive_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.participant import ParticipantLogic
from pairplay.services.recorder import Recorder, RecordingFailed
from pairplay.services.robot.choice import RobotChoice, start_bridge
from pairplay.services.runner import Node, Stopped


def run_session(config: SessionConfig, path: str | Path, *, bus: Bus | None = None,
                bus_options: BusOptions | None = None, external: tuple[str, ...] = (),
                stop: threading.Event | None = None, settle_timeout_s: float = 30.0,
                on_bus=None, nodes_out: dict | None = None, wait_also: tuple[str, ...] = (),
                robot: RobotChoice | None = None, extra_nodes=None, hold=None) -> Path:
    """Run one session to its end (or `stop`); return the recording's path.

    `nodes_out`, if given, receives the in-process Nodes by service name (tests
    read the live learner's final Q-table from it). `wait_also`: more services
    (liveliness names) the game waits for before it starts the session.
    `robot` (the --robot options) adds the robot bridge (services/robot).
    `extra_nodes(bus) -> [Node]`: more in-process services (the lab's board),
    started after the recorder and before the game, which waits for them.
    Raises RecordingFailed (after closing everything) if the recording could
    not be written: the session stops at the first write error.
    `hold(recorder)`, if given, is called once the game has ended, before the
    recording is finished: the human study keeps a game's recording open for
    the questionnaire that follows it (services/protocol.py)."""
    own_bus = bus is None
    # the session's process is the router its external services connect to as clients
    bus = bus if bus is not None else Bus(bus_options or BusOptions(mode="router"))
    stop = stop or threading.Event()
    if on_bus is not None:
        on_bus(bus)
    recorder = recorder_thread = None
    recorder_stop = threading.Event()
    if "recorder" not in external:
        recorder = Recorder(bus, config.session, path, on_failure=lambda _why: stop.set())
        recorder.start()
        recorder_thread = threading.Thread(target=recorder.run, args=(recorder_stop,), name="pairplay-recorder",
                                           daemon=True)
        recorder_thread.start()
    needed = ["recorder", "learner"] + (["participant"] if config.participant.startswith("sim:") else [])
    if config.observed_source == "gaze":
        needed.append("tracker")  # the eye tracker: without it no turn gets a suggestion
    nodes = []
    bridge = game = None
    try:
        if robot is not None:
            bridge = start_bridge(bus, config.session, robot)
        if bridge is not None:
            bridge.run_in_thread(stop)
        if bridge is not None or "robot" in external:  # a bridge on the robot's own host: `pairplay robot`
            needed.append("robot")
        if extra_nodes is not None:
            for node in extra_nodes(bus):
                nodes.append(node)
                needed.append(node.logic.name)
        if "learner" not in external:
            nodes.append(Node(bus, LearnerLogic(), config.session, stop=stop))
        if "participant" not in external and config.participant.startswith("sim:"):
            nodes.append(Node(bus, ParticipantLogic(), config.session, stop=stop))
        for node in nodes:
            node.start()
            node.run_in_thread(stop)
            if nodes_out is not None:
                nodes_out[node.logic.name] = node
        if "game" not in external:
            game = Node(bus, GameLogic(config), config.session, resume=False, stop=stop)
            nodes.append(game)
            if nodes_out is not None:
                nodes_out["game"] = game
            game.start(wait_for=tuple(needed) + tuple(wait_also))
            game.run_in_thread(stop)
        else:
            needed.append("game")
        failure = watch_services(bus, config.session, nodes, [s for s in needed if s in external or s == "robot"],
                                 stop, settle_timeout_s)
        end_game(game, stop, failure, recorder)
        if not failure and not stop.is_set():
            # an external recorder stays until everyone else left: do not wait for it
            wait_external_exit(bus, config.session, [s for s in external if s in needed and s != "recorder"], stop,
                               settle_timeout_s)
        if hold is not None and not failure and recorder is not None:
            hold(recorder)
        if recorder is not None:
            # stopped: the end event gets 1 s to reach the file (the process is gone within 2 s)
            wait_recorded(recorder, nodes, quiet_s=0.2 if external and not stop.is_set() else 0.0,
                          timeout_s=1.0 if stop.is_set() else 5.0)
    except Stopped:  # SIGINT/SIGTERM (or a recording failure) while the game waited for its services
        end_game(game, stop, "", recorder)
        if recorder is not None:
            wait_recorded(recorder, nodes, quiet_s=0.0, timeout_s=1.0)
    finally:
        interrupted = stop.is_set()
        stop.set()
        for node in nodes:
            if node.thread is not None:
                node.thread.join(1.0)
            node.close(0.3)
        if bridge is not None and bridge.thread is not None:
            # the bridge reports the robot's last acknowledgements before the recorder closes
            bridge.thread.join(bridge.settle_s + 5 if not interrupted else 1.5)
        recorder_stop.set()
        failure = None
        if recorder is not None:
            recorder_thread.join(1.0)
            failure = recorder.close(stopped_by=stopped_by(stop) if interrupted else "")
        if own_bus:
            bus.close()
    if failure is not None:
        raise RecordingFailed(failure, recorder.path)
    return recorder.path if recorder is not None else Path(path)


def end_game(game: Node | None, stop: threading.Event, failure: str, recorder: Recorder | None) -> None:
    """A game that has not ended the session ends it now, saying why (SessionEnded)."""
    if game is None or game.logic.done or game.driver.seq == 0:
        return  # not started: nothing to end
    if recorder is not None and recorder.failure and not failure:
        failure = f"recording failed: {recorder.failure}"
    reason, detail = end_reason(stop, failure)
    with game._lock:
        game.publish(game.driver._stamp(game.logic.end(reason, detail)))


def stopped_by(stop: threading.Event) -> str:
    """Who stopped a session: the signal's name (`stop.why`), else the caller (the experimenter)."""
    return getattr(stop, "why", "") or "stopped by the experimenter"


def end_reason(stop: threading.Event, failure: str) -> tuple[str, str]:
    """(reason, detail) of a session that did not complete (SessionEnded.reason: END_REASONS)."""
    if failure:
        return "failed", failure
    why = stopped_by(stop)
    return ("aborted", why) if why == "stopped by the experimenter" else ("interrupted", why)


def watch_services(bus: Bus, session: str, nodes: list[Node], external: list[str], stop: threading.Event,
                   grace_s: float) -> str:
    """Wait until the in-process nodes are done or `stop`; return why a needed service failed ("" if none):
    an in-process node's thread died, or an external service's token was gone for `grace_s` (a crashed
    service restarted within that time resumes from the log, services/runner.py)."""
    missing_since: dict[str, float] = {}
    checked = 0.0
    while not stop.is_set():
        running = [n for n in nodes if n.thread is not None and n.thread.is_alive()]
        dead = [n.logic.name for n in nodes if n.thread is not None and not n.thread.is_alive() and not n.logic.done]
        if dead:
            return f"{', '.join(dead)} stopped before the session ended"
        if not running:
            return ""
        now = time.monotonic()
        if external and now - checked > 0.5:
            checked = now
            alive = bus.alive_now(alive_key(session, "*"), timeout_s=0.5)
            for name in external:
                if alive_key(session, name) in alive:
                    missing_since.pop(name, None)
                elif now - missing_since.setdefault(name, now) > grace_s:
                    return f"{name} left the bus and did not come back within {grace_s:g} s"
        running[0].thread.join(0.1)
    return ""


def wait_recorded(recorder: Recorder, nodes: list[Node], quiet_s: float, timeout_s: float = 5.0) -> None:
    """Wait until the recorder holds every event our nodes published (Zenoh delivers
    to local subscribers on its own threads, so the last ones may still be on their
    way), and, with external services, until it has been quiet for `quiet_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if all(recorder.top_seq.get(n.logic.name, 0) >= n.driver.seq for n in nodes) and not len(recorder.inbox):
            break
        time.sleep(0.005)
    count = -1
    while quiet_s and time.monotonic() < deadline and count != recorder.writer.count:
        count = recorder.writer.count
        time.sleep(quiet_s)


def wait_external_exit(bus: Bus, session: str, services: list[str], stop: threading.Event, timeout_s: float) -> None:
    """Wait until the external services settled and left the bus (they exit when done)."""
    deadline = time.monotonic() + timeout_s
    while services and not stop.is_set() and time.monotonic() < deadline:
        alive = bus.alive_now(alive_key(session, "*"), timeout_s=0.5)
        if not any(alive_key(session, s) in alive for s in services):
            return
        time.sleep(0.05)
