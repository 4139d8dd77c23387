"""A Zenoh router as a process of its own: the hub every service of a session reaches as a client.

Rule: the router holds no pairplay state and publishes nothing; it forwards between
its clients (Zenoh forwards between a router's clients, not between peers that only
share a third peer: measured, LIBRARY-NOTES). Because nothing lives in it, it can be
restarted: its clients reconnect by themselves (~1 s after it is back, measured) and
their buses (client mode, services/bus.py) recover what the outage held up from
the publishers' caches. A restarted router must listen where the clients connect,
so it is given fixed endpoints (`--listen tcp/<address>:<port>`); `listening` with
the real endpoints is its first line. It runs until SIGINT/SIGTERM and closes
within the exit budget.
"""

from __future__ import annotations

import threading
from typing import Callable

from pairplay.services.bus import CLOSE_TIMEOUT_S, Bus, BusOptions


def run_router(options: BusOptions, stop: threading.Event, on_ready: Callable[[Bus], None] | None = None) -> None:
    """Open a Zenoh router with `options` (mode router) and keep it until `stop` is set.
    Raises BusError (one line for the user) if it cannot listen as configured."""
    options.mode = "router"
    options.recovery = False  # it publishes and subscribes to nothing
    bus = Bus(options)
    try:
        if on_ready is not None:
            on_ready(bus)
        while not stop.wait(0.2):
            pass
    finally:
        bus.close(CLOSE_TIMEOUT_S)
