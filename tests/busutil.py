"""Helpers for tests on a real Zenoh bus: loopback peers on free ports, closed after."""

from __future__ import annotations

import queue
import signal
import subprocess
import threading
import time
from contextlib import contextmanager

from pairplay.services.bus import Bus, BusOptions


def listener() -> Bus:
    """A peer listening on a free loopback port (multicast and gossip off)."""
    return Bus(BusOptions())


def connector(to: Bus) -> Bus:
    return Bus(BusOptions(listen=[], connect=to.locators()))


def collect(bus: Bus, key_expr: str) -> queue.Queue:
    q: queue.Queue = queue.Queue()
    bus.subscribe(key_expr, lambda k, p: q.put((k, p)))
    return q


def session_in_thread(config, path, **options) -> tuple[threading.Thread, dict]:
    """`run_session(config, path, **options)` in a thread, once its bus is up: (the thread, a dict with the
    session's "bus" and its in-process nodes by name)."""
    from pairplay.services.session import run_session
    box: dict = {}
    ready = threading.Event()

    def on_bus(bus):
        box["bus"] = bus
        ready.set()

    runner = threading.Thread(target=lambda: run_session(config, path, on_bus=on_bus, nodes_out=box, **options))
    runner.start()
    assert ready.wait(30)
    return runner, box


def wait_until(predicate, timeout_s: float = 20.0, every_s: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(every_s)
    return predicate()


@contextmanager
def recorder_process(bus: Bus, session: str, out):
    """`pairplay run recorder` for `session` into folder `out`, connected to `bus`, once its token is
    up; killed and reaped at the end if it is still running (a test that failed half-way). Forked from this
    test process's zygote (tests/cli_zygote.py): its tests SIGKILL it; its start-up is not what they test."""
    from cli_zygote import shared
    from pairplay.schemas.keys import alive_key
    proc = shared().start(["run", "recorder", "--session", session, "--out", str(out), "--connect",
                           bus.locators()[0]], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        assert wait_until(lambda: alive_key(session, "recorder") in bus.alive_now(alive_key(session, "*")), 30)
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def sigkill(proc) -> None:
    """SIGKILL a process and reap it."""
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
