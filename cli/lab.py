"""`pairplay lab`: a live, recorded session for one person on the touch-screen board.

Rule: one command starts everything a human session needs on its embedded
defaults: the bus, recorder, game, learner, robot bridge (virtual unless
`--robot`) and the lab's web server (services/lab), which serves the board
and the mirror page and publishes the person's touches as events. It prints
the board's and the mirror's URLs, each with the session's token, and writes
recordings/<session>.mcap. The web server listens on 127.0.0.1 (a free port)
unless `--listen HOST:PORT` says otherwise; `--certfile/--keyfile` serve it
over TLS (README, "Serving the board beyond loopback"). No consent is checked: a
study's people play from `protocol serve`, which checks it; the lab says so at its
start (NO_CONSENT_CHECKED). The session options
are `pairplay session`'s; a person's session refuses what a person cannot do
and defaults to the human-phase schedules of thesis 7.2 (cli/session.py).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from pairplay import signals, testpause
from pairplay.cli import interrupts
from pairplay.errors import escaped
from pairplay.schemas.policy import PolicyFileError
from pairplay.inputs import check_option_file
from pairplay.outputs import check_folder
from pairplay.services.recorder import check_new_recording
from pairplay.services.bus import LOOPBACK_ANY_PORT, MODES, BusOptions, stop_on_signals
from pairplay.services.lab.reach import plain_beyond_loopback

from pairplay.cli.args import duration, output_folder
from pairplay.cli.robot import add_robot_arguments, check_robot_args, probe_robot_args, robot_choice
from pairplay.cli.session import (add_config_arguments, config_from_args, cut_line, print_interrupted, read_back,
                                  sum_up)
from pairplay.numbers import counted

LOOPBACK = "127.0.0.1"
# The lab is one session outside any study folder: no consent is held here to check, so none is (a person's
# game in a study is played from `protocol serve`, which refuses it without their consent). Said at the start,
# beside the URLs: `--participant human:p01` looks like a study's id, and a researcher expected the check.
NO_CONSENT_CHECKED = ("consent: not checked here (one session outside any study folder; a study's games, each "
                      "person's consent checked first, run from `pairplay protocol serve FOLDER`)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--out", type=output_folder, default="recordings", help="directory of the recording (default recordings/); a session whose recording "
                   "(<session>.mcap or <session>.<k>.mcap) exists there is refused")
    w = p.add_argument_group("web server")
    w.add_argument("--listen", default=f"{LOOPBACK}:0", metavar="HOST:PORT",
                   help="where the pages are served (default 127.0.0.1:0: loopback, a free port)")
    w.add_argument("--certfile", help="TLS certificate (PEM): serve https/wss")
    w.add_argument("--keyfile", help="TLS private key (PEM) of --certfile")
    w.add_argument("--linger", type=duration, default=3.0, help="seconds the pages show the end before the server stops")
    add_robot_arguments(p)
    g = p.add_argument_group("bus (Zenoh)")
    g.add_argument("--bus-listen", action="append", metavar="ENDPOINT",
                   help=f"Zenoh endpoint to listen on, repeatable (default {LOOPBACK_ANY_PORT})")
    g.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="Zenoh endpoint to connect to")
    g.add_argument("--mode", choices=MODES, default=None, help="Zenoh mode (default: router)")
    g.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config (TLS, access control), passed through")


def parse_listen(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isascii() or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"--listen {text!r}: use HOST:PORT, e.g. 127.0.0.1:8080 (port 0: a free one)")
    return host.strip("[]"), int(port)


def run(args: argparse.Namespace) -> int:
    try:
        if not args.participant.startswith("human:"):
            raise ValueError(f"--participant {args.participant!r}: the lab is for a person (human:<id>); "
                             "simulated participants play with `pairplay session`")
        config = config_from_args(args)
        check_robot_args(args)
        host, port = parse_listen(args.listen)
        if bool(args.certfile) != bool(args.keyfile):
            raise ValueError("--certfile and --keyfile go together")
        for option, f in (("--certfile", args.certfile), ("--keyfile", args.keyfile)):
            if f:  # before the bus and the pages start: uvicorn opens them only then (a pipe blocked it)
                check_option_file(f, option)
        out = check_folder(args.out) / f"{config.session}.mcap"  # before the bus and the pages start
        # a person's recording is never replaced: no --force here
        check_new_recording(out, hint="choose another --session (a person's recording is never replaced)")
    except (ValueError, KeyError, PolicyFileError) as err:
        print(f"pairplay lab: {err}", file=sys.stderr)
        return 2
    probe_robot_args(args)  # an OptionError: one line with its way out (cli/main.py)
    from pairplay.services.lab.server import run_lab

    stop = threading.Event()
    stop_on_signals(stop)
    bus_options = BusOptions(mode=args.mode or ("client" if args.connect else "router"), listen=args.bus_listen,
                             connect=list(args.connect or []), zenoh_config=args.zenoh_config)

    def ready(urls, bus) -> None:
        warning = plain_beyond_loopback(host, tls=bool(args.certfile))  # the same line as `protocol serve`'s
        if warning:
            print(f"pairplay lab: {warning}", file=sys.stderr)
        print(escaped(f"session {config.session}: {config.participant}, {counted(config.rounds, 'round')}, "
                      f"{config.algorithm}, observed card: {config.observed_source}"), flush=True)
        print(f"board:  {urls.board}", flush=True)
        print(f"mirror: {urls.mirror}", flush=True)
        print(f"bus listening on {bus.listening()}", flush=True)
        print(NO_CONSENT_CHECKED, flush=True)

    summary: dict = {}
    try:
        path = run_lab(config, out, host=host, port=port, bus_options=bus_options, robot=robot_choice(args),
                       stop=stop, on_ready=ready, linger_s=args.linger, ssl_certfile=args.certfile,
                       ssl_keyfile=args.keyfile, summary=summary)
        interrupts.work_done()  # the recording is finished: a signal from now on cuts nothing (cli/session.py cut_line)
    except KeyboardInterrupt:  # a second signal: the shutdown of the first was cut short
        if not stop.is_set():
            raise
        again = signals.again or signal.SIGINT  # (a second SIGTERM cuts it too: pairplay/signals.py `wait_cut`)
        print(cut_line("lab", out, again), file=sys.stderr)
        return 128 + again
    except TimeoutError as err:  # a service the game waits for never came (the eye tracker, say)
        print(f"pairplay lab: the session did not start: {err}", file=sys.stderr)
        return 1
    except OSError as err:  # the system refused the address (a port in use): the user's setup, exit 2
        if err.filename is not None:  # a file, not the address: said by cli/main.py, naming it
            raise
        print(f"pairplay lab: cannot serve the pages: {err.strerror or err} (--listen {args.listen})",
              file=sys.stderr)
        return 2
    testpause.pause("recording-finished")
    if getattr(stop, "why", "") and summary:
        return print_interrupted(summary, path, signals.said(stop.why), config.rounds,  # no reading the file back: 2 s
                                 "the id stays taken: choose another --session", "lab")  # (lab has no --force)
    recorded, summed = sum_up(path) if getattr(stop, "why", "") else read_back(path, "lab")  # (a signal: one line)
    fold = summed.fold
    e = fold.ended
    if getattr(stop, "why", ""):  # a signal: ONE line, as `pairplay session`
        when = "before the session started" if fold.config is None else \
            f"after the session had completed all {counted(config.rounds, 'round')}" if e is not None and e.reason == "completed" \
            else f"after {len(fold.rounds)} of {counted(config.rounds, 'round')}"
        print(f"pairplay lab: interrupted ({signals.said(stop.why)}) {when}; recorded {counted(summed.events, 'event')} to {escaped(path)}"
              + (f" (read back, it is not whole: {recorded.note})" if recorded.note else ""), file=sys.stderr)
        return 0  # the status is the signal's (cli/main.py)
    ended = "no SessionEnded recorded" if e is None else e.reason + (f" ({e.detail})" if e.detail else "")
    if not getattr(args, "quiet", False):  # a summary of the file it wrote: -q leaves it out (cli/main.py QUIET_SUMMARIES)
        print(f"recorded {counted(summed.events, 'event')} to {escaped(path)}")
        print(f"rounds played: {len(fold.turns_per_round())} of {config.rounds}; rejections: {len(fold.rejections)}; "
              f"ended: {ended}")
        from pairplay.replay.delivery import delivery_line
        robot = delivery_line(summed.kept)
        if robot:
            print(robot)
    elif e is None or e.reason != "completed":  # how a session that did not complete ended is still said
        print(f"ended: {escaped(ended)}")
    if recorded.note:  # said by read_back; as `pairplay session`
        return 1
    return 0 if e is not None and e.reason in ("completed", "interrupted", "aborted") else 1  # as `pairplay session`
