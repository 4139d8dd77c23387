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
`settle_timeout_s`, or refused the game's start: services/refusal.py), with how far it got. An external
recorder off the bus holds the game until one is back (services/recorderwatch.py); none back, the rounds it
missed are said (`summary["not_recorded"]`). With an external recorder every service leaves only once it holds
the service's events, and the holes it has once all have left are said the same way (services/recorded.py).
The robot's suggestions still awaiting
an acknowledgement are recorded as "in-flight" (schemas/robot.py).
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path

import logging

import msgspec

from pairplay import signals, testpause
from pairplay.core.personas import persona
from pairplay.errors import InputError, UserError
from pairplay.nearest import nearest
from pairplay.schemas.events import encode_event, own_seq
from pairplay.schemas.keys import alive_key, check_chunk, event_key
from pairplay.schemas.robot_url import robot_kind
from pairplay.arguments import at, path_argument
from pairplay.schemas.session import SessionConfig, config_argument
from pairplay.services.bus import CLOSE_TIMEOUT_S, Bus, BusOptions, Deadline, deadline_of
from pairplay.services.forgery import ForgeryWatch
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.participant import ParticipantLogic
from pairplay.services.recorder import Recorder, RecordingFailed, check_new_recording
from pairplay.services.recorded import recording_lacks
from pairplay.services.recorderwatch import RecorderWatch
from pairplay.services.refusal import EndRefused, RefusalWatch, StartRefused  # noqa: F401  (StartRefused: re-exported)
from pairplay.services.refusal import published_seq
from pairplay.services.robot.bridge import ROBOT_CLOSE_S
from pairplay.services.robot.choice import RobotChoice, start_bridge
from pairplay.services.runner import GAME_GONE_S, Node, Stopped, start_unless_stopped
from pairplay.services.unanswered import RequestWatch

log = logging.getLogger("pairplay.session")


class ForgedEvent(UserError):
    """Another process on the bus published a SessionStarted or SessionEnded claiming to be this session's
    game (schemas/trust.py: Zenoh gives no authenticated publisher per message; docs/bus.md "Security").
    The game saw it on its own key without having published it, and a service took it (or one in another
    process may have: services/forgery.py): a forged end ends a service, a forged start configures it. The
    session is stopped, its recording finished, and this one line names the event. `where`: the recording."""


def forgery_watch(game: Node | None, nodes: list[Node], recorder: Recorder | None, bridge,
                  external: list[str]) -> ForgeryWatch:
    """The session's watch on forged starts and ends its game sees (services/forgery.py)."""
    listeners = [(n.logic.name, n.driver.guard) for n in nodes if n is not game]
    listeners += [("recorder", recorder.guard)] if recorder is not None else []
    listeners += [(bridge.logic.name, bridge.shell.guard)] if bridge is not None else []
    return ForgeryWatch(game, listeners, external)


def run_session(config: SessionConfig, path: str | Path, *, bus: Bus | None = None,
                bus_options: BusOptions | None = None, external: tuple[str, ...] = (),
                stop: threading.Event | None = None, settle_timeout_s: float = GAME_GONE_S,
                on_bus=None, nodes_out: dict | None = None, wait_also: tuple[str, ...] = (),
                robot: RobotChoice | None = None, extra_nodes=None, hold=None, summary: dict | None = None) -> Path:
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
    the questionnaire that follows it (services/protocol.py).
    `summary`, if given, receives what the caller may print without reading the
    file back (an interrupted process has no time for that): `events` written,
    `unrecorded` messages the recorder shed (floods, and what was still queued
    at the exit), `started` whether the game started the session, `rounds_played`, `ended` the game's
    SessionEnded reason ("" if it published none: "completed" under a signal that came after the last round).

    Stopped (SIGINT/SIGTERM, the caller's `stop`, a recording failure), every step
    of the shutdown shares one deadline (`stop.deadline`, services/bus.py), so
    the process is done within `SHUTDOWN_S` of the signal, its recording finished.
    A caller's `config` or `path` that cannot run is refused first (schemas/session.py config_argument)."""
    config = config_argument(config, "run_session")
    # the robot it is started with, recorded in its SessionStarted by kind (a robot that then sends nothing is said
    # by every reader of the file); a game elsewhere records its own
    kind = robot_kind(robot.url) if robot is not None else "external" if "robot" in external else ""
    if kind and not config.robot and "game" not in external:
        config = msgspec.structs.replace(config, robot=kind)
    try:
        startable(config)
    except ValueError as exc:
        raise InputError(f"config: {exc}", at("run_session", "config")) from None
    path = path_argument(path, "run_session")
    if "recorder" not in external:  # refused before the bus opens (the Recorder checks again, claiming the file)
        check_new_recording(path, set_aside_too=False)
    # the session's process is the router its external services connect to as clients
    given = bus
    if given is None:
        bus = Bus(bus_options or BusOptions(mode="router"))
    else:
        # the caller's bus outlives the session (a study's games, one after another): the session declares
        # on a scope of it, released at its end with every subscriber's thread (services/bus.py Bus)
        bus = given.scope()
    stop = stop or threading.Event()
    recorder = recorder_thread = None
    recorder_stop = threading.Event()
    if "recorder" not in external:
        # the file is claimed before the caller's first line: of two sessions of one id started at the same
        # moment, the one refused (RecordingExists) has printed nothing (pairplay/livelock.py)
        try:
            recorder = Recorder(bus, config.session, path, on_failure=lambda _why: stop.set())
        except BaseException:
            bus.close(CLOSE_TIMEOUT_S)
            raise
    needed = ["recorder", "learner"] + (["participant"] if config.participant.startswith("sim:") else [])
    if config.observed_source == "gaze":
        needed.append("tracker")  # the eye tracker: without it no turn gets a suggestion
    nodes = []
    bridge = game = recorder_watch = None
    not_recorded = ""  # an external recorder left the bus and none came back: the rounds it missed (RecorderWatch)
    own_end: list = []  # the game's SessionEnded if the session's stop ended it (end_game)
    # Everything from here on is undone by the `finally` whatever fails, a thread that could not start included
    # (`ulimit -v`): a bus left open kept zenoh-python's threads, which are not daemons, and the process hung
    # in its exit (a new user's `bench`: 11 min) after a traceback.
    try:
        if on_bus is not None:
            on_bus(given or bus)  # what the caller attaches is the caller's: it may outlive the session
        if recorder is not None:
            recorder.start()
            thread = threading.Thread(target=recorder.run, args=(recorder_stop,), name="pairplay-recorder",
                                      daemon=True)
            thread.start()
            recorder_thread = thread  # only once started (close_all joins it)
        # a service that refuses the game's own start or end: the session stops at once (services/refusal.py);
        # subscribed before the game starts, told which game is this session's once there is one
        refusals = RefusalWatch(bus, config.session, None)
        requests = RequestWatch(bus, config.session)  # before the game starts: its first request is seen
        if robot is not None:
            bridge = start_unless_stopped(lambda: start_bridge(bus, config.session, robot), stop, "robot")
        if bridge is not None:
            bridge.confirm_recorded = "recorder" in external  # (services/recorded.py, as its nodes below)
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
            # its recorder elsewhere: it leaves the bus once the recorder holds its events (services/recorded.py)
            node.confirm_recorded = "recorder" in external
            start_unless_stopped(node.start, stop, node.logic.name)
            node.run_in_thread(stop)
            if nodes_out is not None:
                nodes_out[node.logic.name] = node
            if bridge is not None and node.logic.name == "learner":  # the bridge takes all it published before
                # it closes (its suggestions' callback thread may lag behind the session's end: bridge.py's rule)
                bridge.published_suggestions = lambda learner=node: published_seq(learner, "SuggestionMade", True) or 0
        if "game" not in external:
            game = Node(bus, GameLogic(config), config.session, resume=False, stop=stop)
            game.confirm_recorded = "recorder" in external
            nodes.append(game)
            if "recorder" in external:  # held while its recorder is off the bus (services/recorderwatch.py)
                recorder_watch = RecorderWatch(bus, config.session, lambda: game.logic.round,
                                               over=lambda: game.logic.done,
                                               connect=" ".join(bus.options.connect) or " ".join(bus.locators()),
                                               settle_s=settle_timeout_s)
                game.hold = recorder_watch.held
            if nodes_out is not None:
                nodes_out["game"] = game
            start_unless_stopped(lambda: game.start(wait_for=tuple(needed) + tuple(wait_also)), stop, "game")
            game.run_in_thread(stop)
            refusals.game = game
        else:
            needed.append("game")
        watch = forgery_watch(game, nodes, recorder, bridge, [s for s in needed if s in external])
        failure = watch_services(bus, config.session, nodes, [s for s in needed if s in external or s == "robot"],
                                 stop, settle_timeout_s, broken=lambda: watch.verdict() or refusals.verdict(),
                                 waiting=lambda: "; ".join(filter(None, (requests.line(),
                                                                        recorder_watch and recorder_watch.line()))))
        said = recorder_watch.line() if recorder_watch is not None else ""
        if said:  # what came after the last check, said too
            log.warning(said)
        # taken before anything else ends: an external recorder leaves the bus once the session has ended
        not_recorded = recorder_watch.lost(config.rounds if game.logic.done else game.logic.round + 1,
                                           getattr(stop, "why", "") if stop.is_set() else "") \
            if recorder_watch is not None else ""
        own_end = end_game(game, stop, failure, recorder)
        if not failure and not stop.is_set():
            # an external recorder stays until everyone else left: do not wait for it
            wait_external_exit(bus, config.session, [s for s in external if s in needed and s != "recorder"], stop,
                               settle_timeout_s, broken=refusals.verdict)
            if "recorder" in external and not not_recorded:  # every service has left but ours, each once the
                # recorder held its events, or not in time: what the recording lacks now is said (services/recorded.py)
                upto = {n.logic.name: n.driver.seq for n in nodes}
                if bridge is not None:  # the robot's last reports come after the game's end (trial34 A)
                    upto["robot"] = bridge.shell.seq
                not_recorded = recording_lacks(bus, config.session, upto, stop) or next(
                    (n.lacking for n in nodes if n.lacking.startswith("the recorder left the bus")), "")
                # (a recorder gone before a service had its answer, after the game's end: trial34 A; one gone after
                # every service had it is no loss, and not asked of it)
        if hold is not None and not failure and recorder is not None:
            hold(recorder)
        if recorder is not None:
            # stopped: the end event gets what the shutdown's deadline leaves (see `close_all`)
            wait_recorded(recorder, published(nodes, bridge), quiet_s=0.2 if external and not stop.is_set() else 0.0,
                          timeout_s=deadline_of(stop).left(RESERVE["recorded"], 1.0) if stop.is_set() else 5.0)
    except Stopped:  # SIGINT/SIGTERM (or a recording failure) while the game waited for its services
        own_end = end_game(game, stop, "", recorder)
        if recorder is not None:
            wait_recorded(recorder, published(nodes, bridge), quiet_s=0.0, timeout_s=deadline_of(stop).left(RESERVE["recorded"], 1.0))
    finally:
        interrupted = stop.is_set()
        deadline = deadline_of(stop) if interrupted else Deadline(SETTLE_S)
        if not interrupted:  # the services' own shutdown steps (deadline_of) share this one, not a signal's
            stop.deadline = deadline
        stop.set()
        try:
            failure = close_all(nodes, bridge, recorder, recorder_thread, recorder_stop, deadline, interrupted,
                                stopped_by(stop) if interrupted else "", own_end)
        finally:
            bus.close(deadline.left(cap=CLOSE_TIMEOUT_S))
        if interrupted:
            log.info("stopped: services and recording closed %.2f s before the shutdown's deadline", deadline.left())
        if summary is not None and recorder is not None:
            summary.update(events=recorder.writer.count, unrecorded=recorder.inbox.shed_total,
                           started=game is not None and game.driver.seq > 0,
                           rounds_played=game.logic.round if game is not None else 0,
                           ended=game.logic.ended if game is not None else "")
            testpause.pause("session-summed")  # (tests/test_cut_signals.py: a second signal once it is known)
        if not_recorded and summary is not None:  # the caller says it (cli/session.py), once
            summary["not_recorded"] = not_recorded
        elif not_recorded:
            log.error(not_recorded)
    if failure is not None:
        raise RecordingFailed(failure, recorder.path)
    where = recorder.path if recorder is not None else f"session {config.session}"
    forged = forgery_watch(game, nodes, recorder, bridge, [s for s in external if s in needed]).verdict()
    if forged:
        raise ForgedEvent(f"{forged}: the session was stopped", where)
    refused = refusals.error(where)
    if refused is not None:
        raise refused
    return recorder.path if recorder is not None else Path(path)


def startable(config: SessionConfig) -> None:
    """ValueError unless the services can start `config`, a valid one: what `pairplay session` checks of its
    options before anything starts (cli/session.py), made of every config handed to run_session, whoever built
    it. Before, `persona="wasm"` opened the bus, the participant refused the game's start (StartRefused) and the
    recording stayed behind; `participant="sim:ashley", persona="wasim"` ran as wasim; policy_actions under
    q-learning were ignored without a word."""
    kind, _, who = config.participant.partition(":")
    if kind not in ("sim", "human"):
        near = nearest(kind, ("sim", "human")) if _ else ""
        raise ValueError(f"participant {config.participant!r}: use sim:<persona> or human:<id>"
                         + (f" (did you mean '{near}:{who}'?)" if near else ""))
    check_chunk("participant id", who)
    if kind == "sim":
        try:  # the participant plays `persona` (services/participant.py): a persona it knows
            played = persona(config.persona)
        except KeyError as err:
            raise ValueError(err.args[0]) from None
        try:
            named = persona(who)
        except KeyError as err:
            raise ValueError(f"participant {config.participant!r}: {err.args[0]}") from None
        if named.key != played.key:  # the session would record one persona and play another
            raise ValueError(f"participant {config.participant!r} and persona {config.persona!r} disagree: give "
                             f"persona={named.key!r} (or participant='sim:{played.key}')")
    if config.policy_actions and config.algorithm not in ("pi-reuse", "fixed"):
        raise ValueError(f"policy_actions are used only by algorithm 'pi-reuse' or 'fixed'; {config.algorithm!r} "
                         "would ignore them")
    never = config.learner_config().never_reuses() if config.algorithm == "pi-reuse" else ""
    if never:
        raise ValueError(f"algorithm 'pi-reuse' with rounds {config.rounds} would never reuse the bias policy: {never}")


# Seconds of the shutdown's deadline each step leaves to the steps after it (services/bus.py
# Deadline): the waits add up to at most the deadline, whatever each one meets.
RESERVE = {"recorded": 0.8, "nodes": 0.6, "bridge": 0.55, "recorder_thread": 0.5, "recorder": 0.1}
SETTLE_S = 30.0  # a session that ended by itself: the same steps, with their usual caps
LAST_EVENTS_WAIT_S = 10.0  # at most this long for the services' last events to reach the recorder


def close_all(nodes: list[Node], bridge, recorder: Recorder | None, recorder_thread, recorder_stop: threading.Event,
              deadline: Deadline, interrupted: bool, stopped: str, own: list = ()) -> str | None:
    """Stop the services, then finish the recording, all by `deadline`; the recording's failure, if any.

    The deadline bounds the waits on others: the services' threads, the robot, the bus bringing their
    last events. What is this process's own work is done whatever it left (on a starved machine the
    signal's deadline has passed before the shutdown runs at all: load 20-29): the recorder's thread
    finishes the batch it writes before the file is closed (closed under it, the file was cut, or the
    thread's next write failed: "write to closed file"), and the session's own end (`own`: the
    SessionEnded the stop made the game publish) is written even if the bus has not brought it yet."""
    for node in nodes:
        node.finish(deadline.left(RESERVE["nodes"], 1.0), deadline.left(RESERVE["nodes"], 0.3))
    if bridge is not None and bridge.thread is not None:
        # the bridge reports the robot's last acknowledgements before the recorder closes
        bridge.thread.join(deadline.left(RESERVE["bridge"], 1.5 if interrupted else bridge.settle_s + ROBOT_CLOSE_S + 2))
        if bridge.thread.is_alive():  # what it reports from now on would come after the recording: count it
            bridge.cut("the session's shutdown could not wait for the robot any longer")
    if recorder is None:
        recorder_stop.set()
        return None
    wait_all_recorded(recorder, nodes, bridge, deadline.left(RESERVE["recorder_thread"] + 0.05, LAST_EVENTS_WAIT_S),
                      own)
    recorder_stop.set()
    if recorder_thread is not None:  # None: it could not start
        # its own work (a step: what its inbox held, BATCH_S at most, and a due flush), never a wait on
        # another: not cut by the deadline, or the file would be finished under the batch it writes; a second
        # signal cuts it, SIGTERM as SIGINT (a second SIGTERM was not heard: pairplay/signals.py `wait_cut`)
        signals.wait_cut(recorder_thread)
    # the recorder's own deadline: the shutdown's, less what closing the bus keeps; what the services hold is
    # taken again when the recorder closes: a service's thread the deadline did not wait for may have
    # published more meanwhile (a learner working through its inbox after a SIGINT)
    return recorder.close(stopped_by=stopped, deadline=Deadline(deadline.left(RESERVE["recorder"])),
                          own=lambda: own_tail(recorder, nodes, bridge, own))


def end_game(game: Node | None, stop: threading.Event, failure: str, recorder: Recorder | None) -> list:
    """A game that has not ended the session ends it now, saying why (SessionEnded); one whose start has
    not published its SessionStarted is not ended (its start, under the same lock, then sees the stop).
    Returns what it published, (key, payload) each: the session's own end, which its recorder writes
    however long the bus takes to bring it (`close_all`)."""
    if game is None:
        return []
    if recorder is not None and recorder.failure and not failure:
        failure = f"recording failed: {recorder.failure}"
    reason, detail = end_reason(stop, failure)
    with game._lock:
        if game.logic.done or game.driver.seq == 0:
            return []  # not started: nothing to end
        events = game.driver._stamp(game.logic.end(reason, detail))
        game.publish(events)
    return [(event_key(game.session, e.source, type(e).__name__), encode_event(e)) for e in events]


def stopped_by(stop: threading.Event) -> str:
    """Who stopped a session: the signal's name (`stop.why`), else the caller (the experimenter)."""
    return getattr(stop, "why", "") or "stopped by the experimenter"


def end_reason(stop: threading.Event, failure: str) -> tuple[str, str]:
    """(reason, detail) of a session that did not complete (SessionEnded.reason: END_REASONS)."""
    if failure:
        return "failed", failure
    why = stopped_by(stop)
    if why != "stopped by the experimenter":
        return "interrupted", why
    # an abort the game did not take in time (services/protocol.py StudyRunner.abort: its grace, which a loaded
    # machine can outlast) keeps the experimenter's reason; before, the end said "stopped by the experimenter"
    return "aborted", getattr(stop, "aborted", "") or why


def watch_services(bus: Bus, session: str, nodes: list[Node], external: list[str], stop: threading.Event,
                   grace_s: float, broken=lambda: "", waiting=lambda: "") -> str:
    """Wait until the in-process nodes are done or `stop`; return why a needed service failed ("" if none):
    an in-process node's thread died, or an external service's token was gone for `grace_s` (a crashed
    service restarted within that time resumes from the log, services/runner.py), or `broken()` names
    why the session cannot go on: a forged start or end the game saw (ForgedEvent), a service that
    refused the game's own start or end (services/refusal.py); checked every 0.1 s, so it stops within that.
    `waiting()` names a wait worth a word (services/unanswered.py): said as a warning, the session goes on."""
    missing_since: dict[str, float] = {}
    checked = 0.0
    while not stop.is_set():
        why = broken()
        if why:
            return why
        said = waiting()
        if said:
            log.warning(said)
        running = [n for n in nodes if n.thread is not None and n.thread.is_alive()]
        dead = [n.logic.name for n in nodes if n.thread is not None and not n.thread.is_alive() and not n.logic.done]
        if dead:
            return f"{', '.join(dead)} stopped before the session ended"
        if not running:
            return ""
        now = time.monotonic()
        if external and now - checked > 0.5:
            checked = now
            alive = bus.alive_now(alive_key(session, "*"), timeout_s=0.5, stop=stop)
            if stop.is_set():
                break
            for name in external:
                if alive_key(session, name) in alive:
                    missing_since.pop(name, None)
                elif now - missing_since.setdefault(name, now) > grace_s:
                    return f"{name} left the bus and did not come back within {grace_s:g} s"
        running[0].thread.join(0.1)
    return ""


def published(nodes: list[Node], bridge) -> list[tuple[str, object]]:
    """(source, stamping shell) of every in-process service: the nodes and the robot bridge, if any."""
    shells = [(n.logic.name, n.driver) for n in nodes]
    return shells + ([(bridge.logic.name, bridge.shell)] if bridge is not None else [])


def wait_recorded(recorder: Recorder, shells: list[tuple[str, object]], quiet_s: float,
                  timeout_s: float = 5.0) -> None:
    """Wait until the recorder holds every event our services published (`published`: Zenoh
    delivers to local subscribers on its own threads, so the last ones may still be on their
    way), and, with external services, until it has been quiet for `quiet_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if all(recorder.top_seq.get(name, 0) >= shell.seq for name, shell in shells) and not len(recorder.inbox):
            break
        time.sleep(0.005)
    count = -1
    while quiet_s and time.monotonic() < deadline and count != recorder.writer.count:
        count = recorder.writer.count
        time.sleep(quiet_s)


def wait_all_recorded(recorder: Recorder, nodes: list[Node], bridge, timeout_s: float, own=()) -> list:
    """Wait (at most `timeout_s`) until the recorder holds the last event of every service
    in this process, those they published while closing included; return what it still lacks
    of them (`own_tail`: the recorder writes it at its close) and count what even that lacks.

    `wait_recorded` ran before the services closed: a Node then publishes its last refusal
    counts, and the robot bridge reports its robot's still open suggestions (RobotActed),
    each through its outbox on its own thread. On a loaded machine the recorder stopped
    before they came (a soak's 80-round session lost 735 of 1,213 RobotActed, uncounted).
    What is neither recorded nor in hand when the wait is over (an outbox that keeps no
    `sent`) is counted in the file (a MessageRejected count per source), never lost silently."""
    last = {name: shell.seq for name, shell in published(nodes, bridge)}
    deadline = time.monotonic() + timeout_s
    while any(recorder.top_seq.get(name, 0) < seq for name, seq in last.items()) and time.monotonic() < deadline:
        time.sleep(0.005)
    tail = own_tail(recorder, nodes, bridge, own)
    covered = dict(recorder.top_seq)
    for key, payload in tail:  # written by the recorder itself (Recorder.close): not missing
        source, seq = key.split("/")[-2], own_seq(payload)
        covered[source] = max(covered.get(source, 0), seq)
    missing = Counter({(name, "published, not received when the recording stopped"): seq - covered.get(name, 0)
                       for name, seq in last.items() if covered.get(name, 0) < seq})
    if missing:
        log.warning("%d event(s) published but not received when the recording stopped: %s", sum(missing.values()),
                    ", ".join(f"{n} {c}" for (n, _), c in missing.items()))
        recorder.refusals.shed(missing)
    return tail


def own_tail(recorder: Recorder, nodes: list[Node], bridge, own=()) -> list[tuple[str, bytes]]:
    """(key, payload) of what this process's services were given to publish that the recorder does not
    hold yet, each service's in its order (`Outbox.in_hand`), then the session's own end (`own`, end_game)
    if it is not among them. The recorder writes them at its close whatever the bus brought (Recorder.close):
    this process's own work, not a wait on another. Before, only the end was: an event the bus had not
    brought when a starved process's deadline passed (a SIGSTOP right after a SIGINT: test_session_end)
    left a hole below the end, recorded as lost on the bus, and `rebuild` refused the session.

    Each service's events are stamped in the order it hands them to its Outbox, so the scan stops at the
    first one the recorder holds (a session's `sent` may hold 10^5 events)."""
    outboxes = [(node.logic.name, node.outbox) for node in nodes]
    if bridge is not None:
        outboxes.append((bridge.logic.name, bridge.outbox))
    tail: list[tuple[str, bytes]] = []
    seen: set[tuple[str, int]] = set()
    for name, outbox in outboxes:
        top = recorder.top_seq.get(name, 0)
        mine = []
        for key, payload in reversed(outbox.in_hand()):
            seq = own_seq(payload)
            if 0 <= seq <= top:
                break  # (-1: a payload of ours its peers refuse; the recorder refuses and records it)
            if (key, seq) not in seen:  # (in_hand may give one twice)
                seen.add((key, seq))
                mine.append((key, payload))
        tail.extend(reversed(mine))
    tail.extend((key, payload) for key, payload in own if (key, own_seq(payload)) not in seen)
    return tail


def wait_external_exit(bus: Bus, session: str, services: list[str], stop: threading.Event, timeout_s: float,
                       broken=lambda: "") -> None:
    """Wait until the external services settled and left the bus (they exit when done), or `broken()`
    names why one will not (it refused the game's end: services/refusal.py)."""
    deadline = time.monotonic() + timeout_s
    while services and not stop.is_set() and time.monotonic() < deadline and not broken():
        alive = bus.alive_now(alive_key(session, "*"), timeout_s=0.5)
        if not any(alive_key(session, s) in alive for s in services):
            return
        time.sleep(0.05)
