"""The robot driver: performs suggestions through one transport, reconnecting, and reports each.

Rule: one worker thread owns the connection and writes every command exactly
once, in arrival order, at its due time; a command counts as sent when the write
returned, and is never written again (each carries a unique id). When the robot
is unreachable, due commands wait and the worker reconnects with exponential
backoff (reconnect_min_s doubling up to reconnect_max_s; it starts again from
the minimum only after a connection that lasted longer than the maximum, so a
robot that accepts and drops at once is not hammered); once connected the
backlog goes out in order. A new suggestion supersedes the previous ones: their
later steps (the rest of a head turn) are cancelled, their first steps are still
delivered (nothing the learner decided is lost), and if the new one says nothing
while earlier speech may still play, a StopSpeech goes first.

Writes are rate-limited robot-side (a token bucket: max_commands_per_s, bursts
of command_burst), so a backlog never floods the robot: an IrisTK module whose
1000-event queue overflows turns itself off for good (IrisModule.java 24,
135-142). A robot that refuses us (access denied) is not retried: every open
and later suggestion fails at once with that reason. Commands written within
inflight_window_s before the connection died, and not confirmed by a reply,
are recorded as unconfirmed (a TCP write that returned proves nothing once the
peer is gone); commands never written are recorded as unsent.

Every suggestion ends in exactly one RobotActed (schemas/robot.py lists the
outcomes). Replies are matched by the id the protocol echoes; a protocol reply
without an id goes to the oldest suggestion still waiting for that kind of reply.
A superseded suggestion still waiting for replies is reported once the robot
replies about a later one (replies arrive in order, so its own are all in) or
after abort_grace_s, so replies in flight when it was cut are still recorded.
"""

from __future__ import annotations

import itertools
import logging
import queue
import threading
import time
import uuid
from dataclasses import dataclass, field
from typing import Callable

from pairplay.schemas.robot import RobotActed, RobotConfig

from pairplay.services.robot.render import Renderer, Say, Step, StopSpeech
from pairplay.services.robot.transport import (
    SPEECH_END, SPEECH_START, AccessRefused, Changed, Disconnected, Rejected, Reply, Transport, Wire,
)

log = logging.getLogger("pairplay.robot")
HELD_POLL_S = 0.05  # how often a command the transport holds back is offered again


@dataclass(frozen=True)
class Suggestion:
    """What the bridge asks the robot to perform (from a SuggestionMade)."""

    session: str
    round: int
    turn: int
    attempt: int
    action: int
    observed: int
    target: int
    suggestion_seq: int = 0


@dataclass
class _Step:
    at_s: float
    step: Step
    command_id: str
    wire: Wire | None = None
    sent: bool = False
    cancelled: bool = False
    sent_at: float = 0.0  # monotonic time of the write
    confirmed: bool = False  # a reply about it came
    inflight: bool = False  # written just before the connection died, never confirmed


@dataclass
class _Performance:
    suggestion: Suggestion
    steps: list[_Step]
    received_ns: int
    start: float  # monotonic seconds: the steps' time zero
    superseded: bool = False
    superseded_at: float = 0.0
    overtaken: bool = False  # the robot already replied about a later suggestion
    cut_by_robot: bool = False  # the robot reported one of its commands aborted
    stopped_by_robot: str = ""  # the robot reported its speech stopped early (what it said)
    failed_by_robot: str = ""  # the robot reported a command failed (what it said)
    outstanding: list[tuple[str, str]] = field(default_factory=list)  # (command id, reply kind)
    promised: bool = False
    sent_ns: int = 0
    acked_ns: int = 0
    done_ns: int = 0
    last_send: float = 0.0
    replies: list[str] = field(default_factory=list)
    reconnects: int = 0

    def unsent(self) -> list[_Step]:
        return [s for s in self.steps if not s.sent and not s.cancelled]

    def speech_may_play(self) -> bool:
        says = [s for s in self.steps if isinstance(s.step.command, Say) and not s.cancelled]
        return any(not s.sent or (s.command_id, SPEECH_END) in self.outstanding for s in says)


class RobotDriver:
    def __init__(self, transport: Transport, renderer: Renderer, config: RobotConfig,
                 on_acted: Callable[[RobotActed], None],
                 on_rejected: Callable[[str, str], None] | None = None,
                 clock_ns: Callable[[], int] = time.time_ns) -> None:
        self.transport = transport
        self.renderer = renderer
        self.config = config
        self._on_acted = on_acted
        self._on_rejected = on_rejected or (lambda reason, excerpt: None)
        self._clock_ns = clock_ns
        self._inbox: queue.Queue = queue.Queue()
        self._active: list[_Performance] = []
        prefix = uuid.uuid4().hex[:8]  # unique per driver: ids never repeat across restarts
        self._ids = (f"pairplay.{prefix}.{n}" for n in itertools.count(1))
        self._generation = 0
        self._connected = False
        self._ever_connected = False
        self._backoff = config.reconnect_min_s
        self._next_attempt = 0.0
        self._connected_at = 0.0
        self._dropped_at = 0.0
        self._last_error = "not connected yet"
        self._held = ""  # why the next due command waits although connected ("" = it does not)
        self._closing = False  # the worker saw the close request
        self._close_requested = False
        self._pending = 0
        self._idle = threading.Condition()
        self._tokens = float(config.command_burst)  # the rate limit's bucket
        self._tokens_at = time.monotonic()
        self._rate_next = 0.0  # when the next token is due, while writes wait for one (0: they do not)
        self.refused = ""  # the robot refused us: not retried, every suggestion fails at once
        self.inflight_marked = 0  # commands recorded unconfirmed because the connection died just after
        self.reconnects = 0
        self.rejected = 0
        self._thread = threading.Thread(target=self._run, name=f"robot {transport.url}", daemon=True)

    # -- called from other threads ------------------------------------------------------
    def start(self) -> "RobotDriver":
        self._thread.start()
        return self

    def perform(self, suggestion: Suggestion) -> None:
        """Queue a suggestion; ValueError (bad action code or card, or closed) before anything is queued."""
        if self._close_requested:
            raise ValueError("the robot driver is closed")
        steps = self.renderer.render(suggestion.action, suggestion.observed, suggestion.target)
        with self._idle:
            self._pending += 1
        self._inbox.put(("suggest", suggestion, steps, self._clock_ns(), time.monotonic()))

    def wait_idle(self, timeout: float) -> bool:
        """Block until every queued suggestion has its RobotActed; False on timeout."""
        with self._idle:
            return self._idle.wait_for(lambda: self._pending == 0, timeout)

    @property
    def connected(self) -> bool:
        return self._connected

    def close(self, timeout: float = 5.0) -> None:
        """Send what is due, report every open suggestion, close the connection."""
        self._close_requested = True
        self._inbox.put(("close",))
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _deliver(self, report) -> None:
        self._inbox.put(("report", report, self._clock_ns(), time.monotonic()))

    # -- the worker thread --------------------------------------------------------------
    def _run(self) -> None:
        while True:
            wake = self._next_wakeup()
            try:
                item = self._inbox.get(timeout=None if wake is None else max(0.0, wake - time.monotonic()))
            except queue.Empty:
                item = None
            try:
                while item is not None:
                    try:
                        self._handle(item)
                    except Exception:  # a bug must cost one message, not the robot: log it and go on
                        log.exception("robot %s: driver failed on %s", self.transport.url, item[0])
                    item = self._inbox.get_nowait()
            except queue.Empty:
                pass
            try:
                self._tick()
            except Exception:  # a bug must cost one tick, not the robot: log it and go on
                log.exception("robot %s: driver tick failed", self.transport.url)
            if self._closing:
                self._shutdown()
                return

    def _handle(self, item: tuple) -> None:
        if item[0] == "suggest":
            _, suggestion, steps, received_ns, start = item
            self._add(suggestion, steps, received_ns, start)
        elif item[0] == "report":
            self._report(item[1], item[2], item[3])
        elif item[0] == "close":
            self._closing = True

    def _add(self, suggestion: Suggestion, steps: list[Step], received_ns: int, start: float) -> None:
        speech_playing = self._speech_may_play()
        for earlier in self._active:
            if not earlier.superseded:
                earlier.superseded, earlier.superseded_at = True, start
            for s in earlier.steps:
                if not s.sent and s.at_s > 0:
                    s.cancelled = True
        if speech_playing and not any(isinstance(s.command, Say) for s in steps):
            steps = [Step(0.0, StopSpeech()), *steps]
        ordered = sorted(steps, key=lambda s: s.at_s)  # stable: same-time steps keep their order
        perf = _Performance(suggestion, [_Step(s.at_s, s, next(self._ids)) for s in ordered], received_ns, start)
        self._active.append(perf)
        if self.refused:
            self._finish(perf, "failed", self.refused)

    def _speech_may_play(self) -> bool:
        """Whether the robot may still be speaking: the newest speech command decides."""
        for perf in reversed(self._active):
            if any(isinstance(s.step.command, (Say, StopSpeech)) and not s.cancelled for s in perf.steps):
                return perf.speech_may_play()
        return False

    def _report(self, report, time_ns: int, seen: float) -> None:
        if report.generation != self._generation:
            return  # from a connection already replaced
        if isinstance(report, Disconnected):
            if report.permanent:
                self._refuse(report.reason)
            elif self._connected:
                log.warning("robot %s disconnected: %s", self.transport.url, report.reason)
                self._drop(report.reason, seen)
        elif isinstance(report, Rejected):
            self.rejected += 1
            log.warning("robot %s sent an unreadable frame: %s", self.transport.url, report.reason)
            self._on_rejected(report.reason, report.excerpt)
        elif isinstance(report, Reply):
            self._match(report, time_ns)
        elif isinstance(report, Changed):
            pass  # the tick after this report asks ready() again

    def _match(self, reply: Reply, time_ns: int) -> None:
        for index, perf in enumerate(self._active):
            candidates = [o for o in perf.outstanding
                          if o[1] == reply.kind and (reply.ref is None or o[0] == reply.ref)]
            if not candidates:
                continue
            command_id = candidates[0][0]
            cleared = {(command_id, reply.kind)}
            if reply.kind == SPEECH_END:  # an end implies the start, even if that reply was lost
                cleared.add((command_id, SPEECH_START))
            perf.outstanding = [o for o in perf.outstanding if o not in cleared]
            for step in perf.steps:
                if step.command_id == command_id:
                    step.confirmed, step.inflight = True, False
            said = reply.detail or ("aborted" if reply.aborted else "failed" if reply.failed else "")
            perf.replies.append(reply.wire_name + (f" ({said})" if said else ""))
            perf.cut_by_robot = perf.cut_by_robot or reply.aborted
            if reply.stopped and not perf.stopped_by_robot:
                perf.stopped_by_robot = f"{reply.wire_name}: {reply.detail or 'stopped'}"
            if reply.failed and not perf.failed_by_robot:
                perf.failed_by_robot = f"the robot reported {reply.wire_name} failed"
            perf.acked_ns = perf.acked_ns or time_ns
            if not perf.outstanding:
                perf.done_ns = time_ns
            for earlier in self._active[:index]:  # replies come in order: theirs are all in
                earlier.overtaken = True
            return
        log.debug("robot reply %s (%s) matches no open suggestion", reply.wire_name, reply.ref)

    def _refuse(self, reason: str) -> None:
        """The robot refused us: no retries; every open suggestion fails now with the reason."""
        self.refused = reason
        self._connected = False
        self._last_error = reason
        self.transport.close()
        for perf in list(self._active):
            if perf.unsent():
                self._finish(perf, "failed", reason)

    def _drop(self, reason: str, seen: float | None = None) -> None:
        now = time.monotonic()
        self._mark_inflight(now if seen is None else seen)
        self._connected = False
        self._dropped_at = now
        self._held = ""
        self._last_error = reason
        self.transport.close()
        if now - self._connected_at > self.config.reconnect_max_s:
            self._backoff = self.config.reconnect_min_s  # it was a good connection: start again
        self._next_attempt = now + self._backoff
        self._backoff = min(self._backoff * 2, self.config.reconnect_max_s)

    def _mark_inflight(self, dropped_at: float) -> None:
        """Commands written within inflight_window_s before the drop, unconfirmed: maybe lost."""
        since = dropped_at - self.config.inflight_window_s
        for perf in self._active:
            for step in perf.steps:
                if step.sent and not step.confirmed and not step.inflight and step.sent_at >= since:
                    step.inflight = True
                    self.inflight_marked += 1

    def _connect(self) -> None:
        self._generation += 1
        try:
            self.transport.connect(self._deliver, self._generation)
        except AccessRefused as exc:  # the robot refused access: asking again cannot help
            self._refuse(str(exc))
            return
        except (OSError, ValueError) as exc:  # ConnectionError, timeouts
            self._last_error = f"{type(exc).__name__}: {exc}"
            log.info("robot %s: cannot connect (%s); retry in %.2f s", self.transport.url, self._last_error, self._backoff)
            self._next_attempt = time.monotonic() + self._backoff
            self._backoff = min(self._backoff * 2, self.config.reconnect_max_s)
            return
        self._connected = True
        self._connected_at = time.monotonic()  # the backoff restarts only if this connection lasts
        if self._ever_connected:
            self.reconnects += 1
            for perf in self._active:
                perf.reconnects += 1
        self._ever_connected = True

    def _tick(self) -> None:
        now = time.monotonic()
        if not self._connected and not self.refused and now >= self._next_attempt:
            self._connect()
        if self._connected:
            self._send_due(now)
        self._finalize_ready(time.monotonic())

    def _take_token(self, now: float) -> bool:
        """The rate limit: True if a command may be written now (and count it)."""
        rate, burst = self.config.max_commands_per_s, float(self.config.command_burst)
        self._tokens = min(burst, self._tokens + (now - self._tokens_at) * rate)
        self._tokens_at = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            self._rate_next = 0.0
            return True
        self._rate_next = now + (1.0 - self._tokens) / rate
        return False

    def _send_due(self, now: float) -> None:
        self._held = ""
        self._rate_next = 0.0
        for perf in list(self._active):
            for step in perf.unsent():
                if perf.start + step.at_s > now:
                    break  # steps are in time order; the rest wait for their time
                time_ns = self._clock_ns()
                if step.wire is None:
                    try:
                        step.wire = self.transport.encode(step.step.command, step.command_id, time_ns)
                    except (TypeError, ValueError) as exc:
                        self._finish(perf, "failed", f"cannot encode {step.step.command!r}: {exc}")
                        break
                self._held = self.transport.ready(step.wire)
                if self._held:
                    return  # hold this and everything after it: order is kept
                if not self._take_token(time.monotonic()):
                    return  # the rate limit: this and everything after it wait for a token
                sent_ns = self._clock_ns()  # the write starts now; a fast robot may answer inside it
                try:
                    self.transport.send(step.wire)
                except OSError as exc:
                    log.warning("robot %s: write failed (%s); reconnecting", self.transport.url, exc)
                    self._drop(f"write failed: {exc}")
                    return
                step.sent = True
                step.sent_at = perf.last_send = time.monotonic()
                perf.sent_ns = perf.sent_ns or sent_ns
                perf.outstanding.extend((step.command_id, kind) for kind in step.wire.replies)
                perf.promised = perf.promised or bool(step.wire.replies)

    def _finalize_ready(self, now: float) -> None:
        for perf in list(self._active):
            if perf.unsent():
                stuck = self._held or (not self._connected and f"robot unreachable: {self._last_error}")
                if stuck and now - perf.start > self.config.give_up_s:
                    self._finish(perf, "failed", f"not delivered within {self.config.give_up_s:g} s: {stuck}")
                continue
            cut = any(s.cancelled for s in perf.steps)
            inflight = [s for s in perf.steps if s.inflight]
            if perf.failed_by_robot:
                self._finish(perf, "failed", perf.failed_by_robot)
            elif perf.superseded and perf.outstanding:
                # replies still in flight are recorded until the robot has moved on
                if perf.overtaken or now - perf.superseded_at > self.config.abort_grace_s:
                    self._finish(perf, "aborted")
            elif (perf.superseded and cut) or perf.cut_by_robot:
                self._finish(perf, "aborted")
            elif perf.stopped_by_robot and not perf.outstanding:
                self._finish(perf, "aborted" if perf.superseded else "stopped", perf.stopped_by_robot)
            elif inflight and not perf.outstanding:
                self._finish(perf, "unacknowledged",
                             f"{len(inflight)} command(s) written within {self.config.inflight_window_s:g} s before"
                             f" the connection died ({self._last_error}): they may not have reached the robot")
            elif not perf.outstanding and perf.steps and not perf.promised and self._connected \
                    and now - perf.last_send < self.config.inflight_window_s:
                continue  # nothing will confirm these: wait out the in-flight window before saying "sent"
            elif not perf.outstanding:
                self._finish(perf, "done" if perf.promised else "sent" if perf.steps else "nothing")
            elif now - perf.last_send > self.config.ack_timeout_s:
                lost = f" (connection lost since: {self._last_error})" if self._dropped_at > perf.last_send else ""
                self._finish(perf, "unacknowledged",
                             f"no {perf.outstanding[0][1]} within {self.config.ack_timeout_s:g} s{lost}")

    def _finish(self, perf: _Performance, outcome: str, error: str = "") -> None:
        self._active.remove(perf)
        s = perf.suggestion
        waiting = {command_id for command_id, _ in perf.outstanding}
        unconfirmed = [st.wire.text for st in perf.steps if st.sent and st.wire is not None and not st.confirmed
                       and (st.inflight or (outcome in ("unacknowledged", "in-flight") and st.command_id in waiting))]
        acted = RobotActed(
            session=s.session, round=s.round, turn=s.turn, attempt=s.attempt, action=s.action,
            backend=self.transport.url, outcome=outcome,
            commands=[st.wire.text for st in perf.steps if st.sent and st.wire is not None],
            replies=perf.replies, suggestion_seq=s.suggestion_seq, received_ns=perf.received_ns,
            sent_ns=perf.sent_ns, acked_ns=perf.acked_ns, done_ns=perf.done_ns, error=error,
            reconnects=perf.reconnects, unsent=[self._text(st) for st in perf.unsent()],
            unconfirmed=unconfirmed)
        try:
            self._on_acted(acted)
        except Exception:  # a failing consumer must not stop the robot
            log.exception("robot %s: RobotActed consumer failed", self.transport.url)
        with self._idle:
            self._pending -= 1
            self._idle.notify_all()

    def _text(self, step: _Step) -> str:
        """A never-written command as it would have gone on the wire (or as the renderer gave it)."""
        if step.wire is None:
            try:
                step.wire = self.transport.encode(step.step.command, step.command_id, self._clock_ns())
            except (TypeError, ValueError):
                return repr(step.step.command)
        return step.wire.text

    def _next_wakeup(self) -> float | None:
        times = []
        if self._rate_next:
            times.append(self._rate_next)
        if not self._connected and not self.refused:
            times.append(self._next_attempt)
        for perf in self._active:
            unsent = perf.unsent()
            if unsent and self._connected and not self._held:
                times.append(max(perf.start + unsent[0].at_s, self._rate_next))
            elif unsent and self._held:  # held by the transport: ask it again soon
                times.append(min(time.monotonic() + HELD_POLL_S, perf.start + self.config.give_up_s))
            elif unsent:
                times.append(perf.start + self.config.give_up_s)
            elif perf.outstanding:
                times.append(perf.last_send + self.config.ack_timeout_s)
                if perf.superseded:
                    times.append(perf.superseded_at + self.config.abort_grace_s)
            else:
                times.append(perf.last_send + self.config.inflight_window_s)
        return min(times) if times else None

    def _shutdown(self) -> None:
        for perf in list(self._active):
            if perf.unsent():
                self._finish(perf, "failed", "bridge closed before delivery")
            elif perf.outstanding:
                self._finish(perf, "in-flight", "the session ended while the robot's acknowledgement was awaited")
            elif any(s.inflight for s in perf.steps):
                self._finish(perf, "unacknowledged", "written just before the connection died")
            else:
                self._finish(perf, "done" if perf.promised else "sent" if perf.steps else "nothing")
        if self._connected:
            self._connected = False
            self.transport.close()
