"""The robot bridge as a bus service: SuggestionMade in, the robot acts, RobotActed out.

Rule: the bridge ("robot" on the bus) takes SuggestionMade from the learner
(subscribed to those keys, SessionEnded and RoundStarted only, not the whole
session) and hands each to the robot driver (virtual, IrisTK or Realtime API); the driver
reports each suggestion's fate once, from its own thread, as a RobotActed
event that the bridge stamps and publishes (the recorder keeps it like any
other event). Input goes through the same shell as every service (node.Driver):
a message that does not decode, belongs to another session, repeats a
sequence number or carries an impossible action or card becomes a
MessageRejected, and the bridge goes on; so does a frame from the robot that
cannot be read (key `robot:<backend>`). One lock serialises the two threads
that stamp, so sequence numbers stay strictly increasing.
After SessionEnded the bridge still takes what arrives until the bus has been
quiet for END_QUIET_S (another service's message may overtake a learner's),
waits (up to `settle_s`) for the robot to report every open suggestion, then
leaves the bus. Stopped, it waits what the stop's shutdown deadline leaves, at
most `settle_s`: a signal's 1.1 s leaves ~0.2 s, a session that ended by itself
(its own 30 s) the whole of it, whether the bridge saw that stop or the game's
SessionEnded first. What is still open then is "in-flight", or "failed" only
if the robot could not take it (services/robot/driver.py `_shutdown`).

RobotActed is an observation of the world, not a function of the log: a
replay or verify never recomputes it (the bridge is not a replayable logic).
A bridge that joins a session under way (restarted after a crash: `pairplay
robot ... --session S` again) does not perform old suggestions again. It reads
the recorder's log first, and only then puts its token on the bus (services/runner.py
`join_log`: a game waiting for it cannot start the session while it reads, so a first
start resumes nothing; declared first, trial29 F1 saw "resumed_events=4"): its numbering
continues the log's last RobotActed (a bridge starting again from 1 had every
report refused as a repeat), the log is its cut point (services/guard.py: what
a recovering bus's caches replay to a late joiner is skipped, not performed),
every SuggestionMade of the log without its RobotActed is counted as not
reported ("made before this robot bridge joined"), and a log that holds the
session's end ends the bridge at once (it waited for ever for an end that had
passed). It then takes suggestions from the moment it joins.

A bridge in the learner's process (`pairplay session`: `published_suggestions`
says the seq of the learner's last SuggestionMade) takes every suggestion the
learner published before it closes, for at most LAST_SUGGESTION_WAIT_S and
within a stop's shutdown deadline (a signal's 1.1 s leaves it no time; a
session that ended by itself has 30 s). Its suggestions come on a Zenoh
callback thread of their own, which a starved machine runs late: the session,
ended by itself, stopped the bridge while its last suggestions were still on
that thread, and they were never performed, counted at the recorder's close as
without RobotActed (load 30-47: 14 RobotActed of 15). A bridge in another
process cannot know what is still on its way; what it never got is counted
there the same way.

Like every service (services/runner.py `answer_sent`), the bridge answers a
restarted recorder's refill query (`pairplay/<session>/_query/robot/sent?after=
robot:<seq>`) with what it published after that number, so the RobotActed of
a recorder's outage are refilled into its file. Before, nobody answered for
the robot: those reports were missing from the recording and the gap named the
robot unanswered.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from typing import Callable

from pairplay import __version__
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import Event
from pairplay.schemas.keys import event_key, query_key, session_keys
from pairplay.schemas.robot import BoardCalibration, RobotActed, RobotConfig

from pairplay.services.bus import Bus, Deadline, Inbox, Outbox, deadline_of
from pairplay.services.node import Driver, Rejected
from pairplay.services.recorded import FLUSH_S, until_recorded
from pairplay.services.runner import GAME_GONE_S, SENT_QUERY, GameWatch, answer_sent, join_log, serve_sent
from pairplay.services.robot.backends import open_robot
from pairplay.services.robot.driver import RobotDriver, Suggestion

log = logging.getLogger("pairplay.robot.bridge")
NAME = "robot"
END_QUIET_S = 0.25  # after SessionEnded, stop once no message came for this long
STOPPED_SETTLE_S = 1.0  # orphaned (the game left) or a stopped in-process learner: the wait's scale (run, take_published)
STOPPED_RESERVE_S = 0.6  # stopped: done this long before the shutdown's deadline (the session waits until 0.55)
# stopped: of what the deadline leaves the bridge, this much is the robot's close (the driver sends what is due, reports
# what is open and closes the connection: a Realtime robot's close handshake, up to its close_timeout of 1 s), taken
# from the wait for its replies. Before, that wait took all but ~50 ms of a signal's 1.1 s (0.4 s to 0.05 s), and a
# robot whose close took longer (a loaded Wi-Fi) was left mid-close as the process exited: its last commands cut
ROBOT_CLOSE_SHARE_S = 0.25
LAST_SUGGESTION_WAIT_S = 5.0  # at most this long for an in-process learner's suggestions still on their way (rule)
ROBOT_CLOSE_S = 20.0  # ended by itself: how long the driver may take to report what is still open (a
# starved driver with ~800 open suggestions took over 5 s in the soak; a stopped session has its deadline)


class BridgeLogic:
    """The bridge's input side, in the shape node.Driver feeds (see node.Logic)."""

    name = NAME
    consumes = frozenset({"SuggestionMade", "SessionEnded"})
    sources = {"SuggestionMade": frozenset({"learner"}), "SessionEnded": frozenset({"game"})}
    # What the bridge subscribes to: what it consumes, and the game's RoundStarted, read only so the
    # guard sees the game's sequence numbers rise (it refuses a jump of more than MAX_SEQ_JUMP from a
    # source, schemas/trust.py, and a 300-round session's SessionEnded comes ~40,000 game events in).
    # Not the whole session: decoding its every event (~50,000 in 300 rounds) was most of the bridge's cost.
    listens = (*sorted(consumes), "RoundStarted")

    def __init__(self, perform: Callable[[Suggestion], None]) -> None:
        self.perform = perform
        self.done = False
        self.last_suggestion = 0  # the highest SuggestionMade seq taken (RobotBridge.take_published)

    def start(self) -> list[Event]:
        return []

    def handle(self, event: Event) -> list[Event]:
        if isinstance(event, ev.SessionEnded):
            self.done = True
        elif isinstance(event, ev.SuggestionMade):
            self.last_suggestion = max(self.last_suggestion, event.seq)
            try:
                self.perform(Suggestion(event.session, event.round, event.turn, event.attempt, event.action,
                                        event.observed, event.target, suggestion_seq=event.seq))
            except ValueError as exc:  # an action code or a card the robot cannot show
                raise Rejected(f"cannot perform suggestion: {exc}") from None
        return []


class RobotBridge:
    def __init__(self, bus: Bus, session: str, robot_url: str = "virtual", *,
                 config: RobotConfig | None = None, calibration: BoardCalibration | str | None = None,
                 clock: Callable[[], int] = time.time_ns, settle_s: float = 15.0) -> None:
        self.bus, self.session, self.robot_url, self.settle_s = bus, session, robot_url, settle_s
        self._config, self._calibration = config, calibration
        self._lock = threading.Lock()
        self._inbox = Inbox()  # Zenoh's callback threads only hand over (services/bus.py)
        self._outbox = Outbox(bus, NAME, keep=True)  # the one place the bridge publishes from; kept: a restarted
        # recorder asks what it sent (answer_sent)
        self.robot: RobotDriver | None = None
        # suggestions handed to the robot and RobotActed published (under _lock): what `cut` counts
        self._handed = self._reported = 0
        self._cut = False
        self.backend = ""  # the robot's URL without its query (a Realtime key must not be recorded)
        self.logic = BridgeLogic(self._perform)
        self.shell = Driver(self.logic, session, clock)
        self.shell.guard.by_tag = True  # it subscribes to the tags it listens to only (`start`; services/guard.py)
        self.thread: threading.Thread | None = None
        self.game_gone_s = GAME_GONE_S  # see runner.GameWatch
        self.game_watch: GameWatch | None = None
        # an in-process learner: the seq of its last SuggestionMade published (0: none yet); see rule
        self.published_suggestions: Callable[[], int] | None = None
        # its recorder is another process: ended by itself, it leaves once the recorder holds every RobotActed it
        # published, answering the refill meanwhile (services/recorded.py; services/runner.py Node's too)
        self.confirm_recorded = False

    def _perform(self, suggestion: Suggestion) -> None:
        if self.robot is None:
            raise ValueError("the robot bridge is not running (not started, or closed)")
        self.robot.perform(suggestion)
        self._handed += 1  # the bridge's thread, under _lock (step)

    # -- publishing (two threads stamp, the bridge's and the robot driver's; the outbox publishes)
    def _publish(self, events: list[Event]) -> None:
        for e in events:
            self._outbox.send(event_key(self.session, e.source, type(e).__name__), ev.encode_event(e))

    def _on_acted(self, acted: RobotActed) -> None:
        with self._lock:
            if self._cut:  # too late: counted as not reported (see `cut`), never recorded as well
                return
            self._publish(self.shell._stamp([acted]))
            self._reported += 1

    @property
    def outbox(self) -> Outbox:
        """What the bridge publishes through: its session's recorder writes what it holds at the close
        (services/session.py `own_tail`)."""
        return self._outbox

    def cut(self, why: str) -> int:
        """Take no more reports from the robot; count the suggestions it has not reported yet.

        A driver still closing (a loaded machine: 584 open suggestions of a soak's
        300-round session took longer than `ROBOT_CLOSE_S`) would report them after the
        outbox and the recording had closed: lost, uncounted. Now they are a
        MessageRejected count ("not reported: <why>"), published with what the inbox shed;
        a report that comes later is dropped, so nothing is counted and recorded both.
        Returns the count (0 after the first call)."""
        with self._lock:
            if self._cut:
                return 0
            self._cut = True
            left = self._handed - self._reported
            shed = Counter(self._inbox.take_shed())  # added to below: a copy (take_shed may give its shared empty one)
            if left:
                log.warning("robot %s: %d suggestion(s) not reported: %s", self.backend, left, why)
                shed[(NAME, f"suggestion not reported, {why}")] += left
            self._publish(self.shell.tick(shed, force=True))
            return left

    def _on_robot_rejected(self, reason: str, excerpt: str) -> None:
        with self._lock:
            self._publish(self.shell.reject(f"robot sent an unreadable frame: {reason}",
                                            f"robot:{self.backend}", payload=excerpt.encode()))

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self, stop: threading.Event | None = None) -> "RobotBridge":
        """Open the robot, subscribe, catch up with a session under way (see rule), announce:
        the game may start once our token is seen. `stop` ends the wait for the log."""
        self.robot = open_robot(self.robot_url, self._on_acted, config=self._config,
                                calibration=self._calibration, on_rejected=self._on_robot_rejected)
        for tag in self.logic.listens:  # Zenoh then does not even send the others here
            self.bus.subscribe(f"{session_keys(self.session)[:-2]}*/{tag}", self._inbox.put)
        self.bus.queryable(query_key(self.session, NAME, SENT_QUERY), self._inbox.control)  # a recorder's refill
        self.game_watch = GameWatch(self.bus, self.session, self.game_gone_s)
        self.backend = self.robot.transport.url
        # the token (what a waiting game starts on) only once the log is read (runner.join_log): declared first, a
        # game could start the session in between and this first start resume its first events (trial29 F1)
        recorded = join_log(self.bus, self.session, NAME, stop)
        if recorded:
            self.game_watch.existed()  # a game gone before we watched never shows its token (runner.GameWatch)
        announce = ev.ServiceStarted(service=f"{NAME} {self.backend}", version=__version__,
                                     resumed_events=len(recorded))
        with self._lock:
            unreported = self._resume(recorded)
            self._publish(self.shell._stamp([announce]))
            if unreported:
                why = "made before this robot bridge joined (the one before it crashed, or none was on the bus)"
                log.warning("robot: %d suggestion(s) of the log were never reported: %s", unreported, why)
                shed = Counter({(NAME, f"suggestion not reported, {why}"): unreported})
                self._publish(self.shell.tick(shed, force=True))
        return self

    def _resume(self, recorded: list[Event]) -> int:
        """Take a session under way from its log (see rule): continue the numbering, note the
        log's inputs as the cut point, end if the session has; how many suggestions of the log
        no RobotActed reported."""
        own = [e for e in recorded if e.source == NAME]
        self.shell.seq = max([self.shell.seq] + [e.seq for e in own])
        acted = {e.suggestion_seq for e in own if isinstance(e, RobotActed)}
        unreported = 0
        for e in recorded:
            tag = type(e).__name__
            if e.source == NAME or tag not in self.logic.listens or e.session != self.session:
                continue
            self.shell.guard.note(event_key(e.session, e.source, tag), e)
            if isinstance(e, ev.SuggestionMade) and e.seq not in acted:
                unreported += 1
            elif isinstance(e, ev.SessionEnded):
                self.logic.done = True
        self.shell.guard.cut = dict(self.shell.guard.last_seq)
        return unreported

    def step(self, timeout_s: float = 0.1) -> bool:
        item = self._inbox.get(timeout_s)
        shed = self._inbox.take_shed()
        if shed or self.shell.refusals.pending():
            with self._lock:
                self._publish(self.shell.tick(shed))
        if item is None:
            return False
        key, payload, _ = item
        if key is None:  # a restarted recorder asks what we sent (its refill)
            answer_sent(self._outbox, NAME, payload)
            return True
        with self._lock:
            self._publish(self.shell.receive(key, payload))
        return True

    def run(self, stop: threading.Event) -> None:
        orphaned = False
        while not stop.is_set() and not self.logic.done:
            self.step()
            if self.game_watch is not None and self.game_watch.gone():
                log.warning("robot: the session's game left the bus %.0f s ago without the bridge seeing the "
                            "session's end (a cut link?); stopping", self.game_watch.gone_s)
                orphaned = True
                break
        # Messages from different services may overtake each other on their way here (a
        # SessionEnded before the last SuggestionMade): go on until the bus is quiet.
        while self.step(timeout_s=0.0 if stop.is_set() else END_QUIET_S):
            pass
        self.take_published(stop)
        # stopped: the robot reports what is open for what the shutdown's deadline leaves, at most settle_s, and
        # what it has not reported then is recorded as in flight; the deadline, not who won the race, decides.
        # A signal's 1.1 s leaves it ~0.2 s and the process exits promptly; a session that ended by itself stops
        # its services with its own 30 s (services/session.py SETTLE_S), and a bridge that saw that stop before
        # the SessionEnded waits as long as one that saw the end first (it waited 1 s, STOPPED_SETTLE_S, and a
        # head turn's return still due was cut: "1 failed" once in 4 runs of a 1-round session, now in-flight)
        if stop.is_set():
            deadline = deadline_of(stop)
            self.close(deadline.left(STOPPED_RESERVE_S + 0.05 + ROBOT_CLOSE_SHARE_S, self.settle_s), deadline)
        elif orphaned:  # nobody records what the robot still reports: do not wait for it
            self.close(min(self.settle_s, STOPPED_SETTLE_S))
        else:
            self.close(self.settle_s, stop=stop)

    def take_published(self, stop: threading.Event) -> bool:
        """Take what an in-process learner published and our inbox has not brought yet (see rule), for
        at most LAST_SUGGESTION_WAIT_S, and, once stopped, within the shutdown's deadline; whether every
        one was taken."""
        if self.published_suggestions is None:
            return True
        # stopped: within the shutdown's deadline, leaving the robot's last reports and its close their share (a
        # signal's 1.1 s leaves nothing to wait with; a session that ended by itself has SETTLE_S)
        wait_s = (deadline_of(stop).left(STOPPED_RESERVE_S + 0.05 + ROBOT_CLOSE_SHARE_S + STOPPED_SETTLE_S / 2,
                                         LAST_SUGGESTION_WAIT_S)
                  if stop.is_set() else LAST_SUGGESTION_WAIT_S)
        until = time.monotonic() + wait_s
        while self.logic.last_suggestion < (self.published_suggestions() or 0):
            left = until - time.monotonic()
            if left <= 0:
                return False
            self.step(min(0.05, left))
        return True

    def run_in_thread(self, stop: threading.Event) -> threading.Thread:
        thread = threading.Thread(target=self.run, args=(stop,), name="pairplay-robot", daemon=True)
        thread.start()  # kept only once started: a thread that could not start is never joined (it raised)
        self.thread = thread
        return thread

    def close(self, settle_s: float | None = None, deadline: Deadline | None = None,
              stop: threading.Event | None = None) -> None:
        """Let the robot report what is open (for at most `settle_s`), then close its connection;
        all of it `STOPPED_RESERVE_S` before `deadline`, if given (a stopped session's shutdown). Given
        the session's `stop` and `confirm_recorded`, stay until the recorder holds what we published."""
        robot, self.robot = self.robot, None
        if robot is None:
            return
        settle_s = self.settle_s if settle_s is None else settle_s
        # (an unreachable robot's reports cannot come: each game of a pilot with one waited its whole settle time,
        # 15 s, once a stopped bridge was given it)
        if not robot.wait_idle(settle_s, until_unreachable=True):  # INFO: nothing is lost, the file records them
            log.info("robot %s: suggestions still open %s; reporting them as they are", robot.transport.url,
                     "(it is unreachable)" if robot.unreachable else f"after {settle_s:.1f} s")
        if deadline is None:
            robot.close(ROBOT_CLOSE_S)
        else:
            robot.close(deadline.left(STOPPED_RESERVE_S + 0.05, ROBOT_CLOSE_S))
        self.cut("the robot driver had not reported it when the bridge closed")
        if self.confirm_recorded and stop is not None and deadline is None:
            self._outbox.flush(FLUSH_S)  # (what it published last: the recorder is asked about it next)
            with self._lock:
                upto = {NAME: self.shell.seq}
            lacking = until_recorded(self.bus, self.session, upto,
                                     lambda s: serve_sent(self._inbox, self._outbox, NAME, s), stop)
            if lacking:  # (the session's process says every hole of the recording: services/session.py)
                log.warning("robot: %s", lacking)
        self._outbox.close(1.0 if deadline is None else deadline.left(STOPPED_RESERVE_S, 1.0))
