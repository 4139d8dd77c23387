"""Bench: suggestion -> robot command on the wire, through the bridge, beside the raw path.

Rule: both paths start at a Zenoh put of a SuggestionMade on one bus session
and end when a stand-in IrisTK broker (loopback TCP, same process, same clock)
has read the whole `EVENT action.speech` frame. The bridge path goes through
the bridge's subscriber, its input checks, the renderer, the driver's worker
thread and the IrisTK encoder; the raw reference is a subscriber callback that
writes a pre-built frame to the socket. One suggestion at a time (the next is
sent when the previous arrived), so the figures are latencies, not throughput.
"""

from __future__ import annotations

import itertools
import socket
import threading
import time

import numpy as np

from pairplay.core.actions import code_of_parts
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import event_key
from pairplay.schemas.robot import RobotConfig

from pairplay.services.bus import Bus, BusOptions
from pairplay.services.robot.bridge import RobotBridge
from pairplay.services.robot.iristk_protocol import event_frame, make_event

SESSION = "bench-robot"
SPEECH = code_of_parts(2, 0, 0, 0)


class StandInBroker:
    """Accepts one client, answers the handshake, timestamps every action.speech frame it reads."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.arrivals: list[int] = []
        self.arrived = threading.Semaphore(0)
        threading.Thread(target=self._serve, daemon=True, name="bench broker").start()

    def _serve(self) -> None:
        while True:
            try:
                sock, _ = self.server.accept()
            except OSError:
                return
            threading.Thread(target=self._client, args=(sock,), daemon=True).start()

    def _client(self, sock: socket.socket) -> None:
        """Reads as IrisTK's broker does (lines; `EVENT <name> <n>` then exactly n bytes)."""
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buffer, pending = bytearray(), None
        with sock:
            while data := sock.recv(65536):
                buffer += data
                while True:
                    if pending is not None:
                        name, n = pending
                        if len(buffer) < n:
                            break
                        del buffer[:n]
                        pending = None
                        if name == "action.speech":
                            self.arrivals.append(time.time_ns())
                            self.arrived.release()
                        continue
                    end = buffer.find(b"\n")
                    if end < 0:
                        break
                    line = bytes(buffer[:end]).decode("utf-8", "replace")
                    del buffer[:end + 1]
                    if line.startswith("CONNECT "):
                        sock.sendall(b"SUBSCRIBE action.**\nCONNECTED\n")
                    elif line.startswith("EVENT "):
                        _, name, n = line.split(" ")
                        pending = (name, int(n))

    def close(self) -> None:
        self.server.close()


def _suggestion(seq: int) -> tuple[str, bytes]:
    event = ev.SuggestionMade(round=0, turn=seq, attempt=0, state=0, action=SPEECH, chosen_by="greedy",
                              epsilon=0.0, alpha=0.5, psi=0.0, observed=0, target=seq % 17 + 1)
    event = stamped(event, session=SESSION, source="learner", seq=seq, time_ns=time.time_ns())
    return event_key(SESSION, "learner", "SuggestionMade"), ev.encode_event(event)


_SEQ = itertools.count(1)  # the learner's sequence numbers only ever grow


def _measure(bus: Bus, broker: StandInBroker, n: int) -> np.ndarray:
    latencies = []
    for seq in itertools.islice(_SEQ, n):
        key, payload = _suggestion(seq)
        before = len(broker.arrivals)
        start = time.time_ns()
        bus.put(key, payload)
        if not broker.arrived.acquire(timeout=5.0):
            raise RuntimeError("robot bench: a suggestion never reached the stand-in broker")
        latencies.append((broker.arrivals[before] - start) / 1e3)
    return np.array(latencies)


def _raw_reference(publisher: Bus, subscriber: Bus, broker: StandInBroker, n: int) -> np.ndarray:
    sock = socket.create_connection(("127.0.0.1", broker.port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.sendall(b"CONNECT furhat raw\n")
    sock.recv(64)
    frame = event_frame(make_event("action.speech", "raw", "raw", time.time_ns(), text="Try at row 1 and column 2"))
    sub = subscriber.subscribe(f"pairplay/{SESSION}/learner/SuggestionMade", lambda key, payload: sock.sendall(frame))
    try:
        time.sleep(0.2)  # let the subscription reach the publisher's session
        return _measure(publisher, broker, n)
    finally:
        sub.undeclare()
        sock.close()


# back-to-back suggestions are far above a participant's pace: the robot-side rate limit lifted (it would add its
# 1/max_commands_per_s wait, which is what it is for, not the path)
BENCH_CONFIG = RobotConfig(ack_timeout_s=0.5, abort_grace_s=0.05, max_commands_per_s=1e6, command_burst=500)


def bench_rows(quick: bool = False) -> list[dict]:
    n = 100 if quick else 400
    publisher = Bus(BusOptions())
    subscriber = Bus(BusOptions(listen=[], connect=publisher.locators()))
    broker, raw_broker = StandInBroker(), StandInBroker()
    bridge = RobotBridge(subscriber, SESSION, f"iristk://127.0.0.1:{broker.port}", config=BENCH_CONFIG, settle_s=1.0)
    stop = threading.Event()
    try:
        bridge.start()
        bridge.run_in_thread(stop)
        time.sleep(0.2)  # the subscription and the robot connection settle
        _measure(publisher, broker, 20)  # warm-up
        through_bridge = _measure(publisher, broker, n)
        raw = _raw_reference(publisher, subscriber, raw_broker, n)
    finally:
        stop.set()
        if bridge.thread is not None:
            bridge.thread.join(5.0)
        broker.close()
        raw_broker.close()
        subscriber.close()
        publisher.close()
    rows = []
    for q, goal in ((50, "robot_p50"), (99, "robot_p99")):
        value, reference = float(np.percentile(through_bridge, q)), float(np.percentile(raw, q))
        rows.append({"row": f"robot: suggestion -> IrisTK command on the wire, p{q}", "value": value,
                     "unit": "us", "reference": f"zenoh put -> raw socket write, p{q}",
                     "reference_value": reference, "ratio": value / reference, "goal": goal})
    return rows


if __name__ == "__main__":
    for row in bench_rows(quick=True):
        print(row)
