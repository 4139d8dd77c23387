"""Helpers for tests on a real Zenoh bus: loopback peers on free ports, closed after."""

from __future__ import annotations

import queue
import time

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


def wait_until(predicate, timeout_s: float = 20.0, every_s: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(every_s)
    return predicate()
