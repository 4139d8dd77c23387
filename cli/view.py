"""`pairplay view`: watch a session live on the bus, or a recording, in rerun.

Rule: the view only subscribes and draws; it never publishes, so it cannot
change a session. It saves an .rrd by default (headless, nothing listens on the
network); `--serve` adds rerun's web viewer, `--spawn` the native viewer.
Rerun's usage analytics stay off for anything the view starts (view_output).

  pairplay view --recording recordings/s1.mcap              # -> recordings/s1.rrd
  pairplay view --recording REC --speed 1 --serve           # paced, in the browser
  pairplay view --session s1 --connect tcp/127.0.0.1:7447   # live
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path

from pairplay.services.bus import add_bus_arguments, open_bus, options_from_args, stop_on_signals
from pairplay.services.view.output import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT, ViewOutput, finish, open_stream
from pairplay.services.view.rerun_logger import RerunView
from pairplay.services.view.sources import LiveSource, recording_items
from pairplay.services.view.drive import drive


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_argument_group("what to view")
    src.add_argument("--session", help="session id: view it live on the bus (or pick it from a recording)")
    src.add_argument("--recording", type=Path, metavar="REC", help="an MCAP recording to view instead of the bus")
    src.add_argument("--speed", type=float, default=0.0,
                     help="recording pace: 1 = as recorded, 10 = ten times faster, 0 = as fast as possible (default)")
    out = parser.add_argument_group("where the view goes")
    out.add_argument("--out", type=Path, metavar="RRD",
                     help="the .rrd to save (default: next to the recording, or recordings/<session>.rrd)")
    out.add_argument("--no-save", action="store_true", help="do not save an .rrd (needs --serve or --spawn)")
    out.add_argument("--serve", action="store_true",
                     help="serve rerun's web viewer (data on 127.0.0.1 only; see docs/view.md)")
    out.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, help="rerun data port for --serve/--spawn")
    out.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, help="web viewer page port for --serve")
    out.add_argument("--spawn", action="store_true", help="open rerun's native viewer (needs a display)")
    out.add_argument("--exit-when-done", action="store_true",
                     help="with --serve: exit when the source ends instead of serving until Ctrl-C")
    out.add_argument("--q-interval", type=float, default=0.25, metavar="S",
                     help="log the Q-table at most every S seconds of session time (default 0.25)")
    out.add_argument("--rerun-analytics", action="store_true",
                     help="leave rerun's usage analytics to your rerun settings (default: off for viewers started here)")
    add_bus_arguments(parser)


def _default_rrd(args: argparse.Namespace) -> Path:
    if args.recording:
        return args.recording.with_suffix(".rrd")
    return Path("recordings") / f"{args.session}.rrd"


def run(args: argparse.Namespace) -> int:
    if not args.recording and not args.session:
        print("pairplay view: give --session ID (live) or --recording REC", file=sys.stderr)
        return 2
    if args.recording and not args.recording.is_file():
        print(f"pairplay view: no recording at {args.recording}", file=sys.stderr)
        return 2
    if args.no_save and not (args.serve or args.spawn):
        print("pairplay view: --no-save leaves no output; add --serve or --spawn", file=sys.stderr)
        return 2
    out = ViewOutput(rrd=None if args.no_save else (args.out or _default_rrd(args)), serve=args.serve,
                     spawn=args.spawn, grpc_port=args.grpc_port, web_port=args.web_port,
                     rerun_analytics=args.rerun_analytics)
    try:
        rec, where = open_stream(out, recording_name=args.session or args.recording.stem)
    except (RuntimeError, ValueError, OSError) as err:  # a viewer that cannot start, a port in use
        print(f"pairplay view: {err}", file=sys.stderr)
        return 1
    for line in where:
        print(f"pairplay view: {line}", file=sys.stderr)
    stop = threading.Event()
    saved_handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    stop_on_signals(stop)
    view = RerunView(rec, q_interval_s=args.q_interval)
    echo = lambda line: print(line, file=sys.stderr)  # noqa: E731
    try:
        if args.recording:
            summary = drive(view, recording_items(args.recording, speed=args.speed, session=args.session),
                            stop=stop, echo=echo)
        else:
            with open_bus(options_from_args(args)) as bus:
                source = LiveSource(bus, args.session)
                print(f"pairplay view: listening to session {args.session}; Ctrl-C to stop", file=sys.stderr)
                summary = drive(view, source.items(stop), stop=stop, echo=echo)
        print(f"pairplay view: {summary.events} events, {summary.notes} notes, "
              f"Q-table logged {summary.q_logged} times", file=sys.stderr)
        if args.serve and not args.exit_when_done and not stop.is_set():
            print("pairplay view: still serving; Ctrl-C to stop", file=sys.stderr)
            while not stop.wait(0.5):
                pass
    finally:
        finish(rec)
        for sig, handler in saved_handlers.items():  # run() may be called in-process (tests, tools)
            signal.signal(sig, handler)
    return 0
