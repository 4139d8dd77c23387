"""`pairplay router`: a Zenoh router alone in this process (services/router.py).

Rule: the server host runs it; the session, the recorder and the other hosts' services
connect to it (`--connect`, client mode) and survive its restart. The first line is
`listening <endpoints>`. Exit 130 on SIGINT, 143 on SIGTERM (cli/main.py); a bus that cannot open (a port
in use, a bad --zenoh-config) is one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import sys
import threading

from pairplay import signals
from pairplay.services.bus import BusError, add_bus_arguments, options_from_args, stop_on_signals


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_bus_arguments(p)


def run(args: argparse.Namespace) -> int:
    from pairplay.services.router import run_router
    if args.mode not in (None, "router"):
        print(f"pairplay router: --mode {args.mode}: a router's mode is router", file=sys.stderr)
        return 2
    stop = threading.Event()
    stop_on_signals(stop)
    options = options_from_args(args, default_mode="router")
    try:
        run_router(options, stop, on_ready=lambda bus: print(f"listening {' '.join(bus.locators())}", flush=True))
    except BusError as err:
        print(f"pairplay router: {err}", file=sys.stderr)
        return 2
    if getattr(stop, "why", ""):  # the status is the signal's (cli/main.py: 130, 143)
        print(f"pairplay router: stopped ({signals.said(stop.why)})", file=sys.stderr, flush=True)  # every verb's interrupted line: stderr
    return 0
