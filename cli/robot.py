"""`pairplay robot`: the robot bridge as its own process, or a quick try of a robot.

Rule: `pairplay robot --session ID --robot URL --connect ENDPOINT` joins a
running session's bus (e.g. on the PC next to the robot) and performs its
suggestions until the session ends. `pairplay robot --robot URL --try 35,46`
performs those action codes once each (observed and target cards from
--observed/--target) and prints what happened: a check of the connection,
the gesture names and the calibration before a study. The same three robot
options (--robot, --robot-config, --calibration) are what `pairplay session`
takes (add_robot_arguments, check_robot_args, bridge_from_args).
"""

from __future__ import annotations

import argparse
import sys
import threading

from pairplay import signals
from pairplay.cli.args import session_id
from pairplay.core.geometry import N_CARDS
from pairplay.errors import OptionError, UserError
from pairplay.lists import comma_items
from pairplay.schemas.policy import N_ACTIONS

from pairplay.services.bus import Bus, add_bus_arguments, options_from_args, stop_on_signals
from pairplay.services.robot.backends import FORMS, load_robot_config, open_robot
from pairplay.services.robot.bridge import RobotBridge
from pairplay.services.robot.choice import CONNECT_PROBE_S, RobotChoice, check_choice, robot_unreachable, start_bridge
from pairplay.services.robot.calibration import CalibrationError, load_calibration
from pairplay.services.robot.driver import Suggestion

from pairplay.services.robot.choice import NO_ROBOT



def add_robot_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("robot")
    g.add_argument("--robot", default="virtual", metavar="URL",
                   help=f"robot backend: {FORMS}, or none (default: virtual, no hardware)")
    g.add_argument("--robot-config", metavar="FILE", help="RobotConfig JSON: gesture names, texts, timings")
    g.add_argument("--calibration", metavar="FILE", help="board calibration JSON (default: the packaged one)")
    g.add_argument("--robot-unreachable-ok", action="store_true",
                   help="start even if the robot does not accept a connection now (the bridge keeps trying; "
                        "what it cannot deliver is recorded failed). Default: refuse the session")


def robot_choice(args: argparse.Namespace) -> RobotChoice | None:
    """The --robot options as a RobotChoice (None for --robot none)."""
    if args.robot == NO_ROBOT:
        return None
    return RobotChoice(args.robot, args.robot_config, args.calibration)


def check_robot_args(args: argparse.Namespace) -> None:
    """Refuse a bad --robot URL, robot config or calibration before a session starts (ValueError)."""
    choice = robot_choice(args)
    if choice is not None:
        check_choice(choice)


def probe_robot_args(args: argparse.Namespace) -> None:
    """OptionError if the networked robot of --robot does not accept a connection now: a session started
    with an unreachable robot recorded every suggestion failed and said so only under -v (a new user's
    trial). --robot-unreachable-ok goes on without it; the virtual robot and --robot none need no probe."""
    if robot_choice(args) is None or getattr(args, "robot_unreachable_ok", False):
        return
    probe_robot(args.robot, fix="--robot-unreachable-ok starts the session anyway (the bridge keeps trying), "
                                "--robot none without a robot", option="--robot-unreachable-ok")


def bridge_from_args(bus: Bus, session: str, args: argparse.Namespace, stop=None) -> RobotBridge | None:
    """A started RobotBridge for a session (None for --robot none); ValueError on a bad option or file.
    `stop` ends its wait for the log of a session under way."""
    choice = robot_choice(args)
    return None if choice is None else start_bridge(bus, session, choice, stop)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--session", type=session_id, help="the session whose suggestions to perform")
    p.add_argument("--try", dest="try_codes", metavar="CODES", type=action_codes,
                   help="comma-separated action codes (0..87) to perform once")
    p.add_argument("--observed", type=card, default=7, help="observed card for --try (default 7: row 2, column 2)")
    p.add_argument("--target", type=card, default=10, help="matching card for --try (default 10: row 2, column 5)")
    add_robot_arguments(p)
    add_bus_arguments(p)


def run(args: argparse.Namespace) -> int:
    if bool(args.session) == bool(args.try_codes):
        raise OptionError("give either --session ID (serve a session) or --try CODES (try the robot)", "pairplay robot")
    if args.robot == NO_ROBOT:
        raise OptionError("--robot none leaves nothing to do", "--robot none")
    try:
        return _try(args) if args.try_codes else _serve(args)
    except (ValueError, CalibrationError) as exc:
        if isinstance(exc, UserError):
            raise
        raise OptionError(str(exc), "robot options") from None


def action_codes(text: str) -> list[int]:
    """--try's comma-separated action codes, each 0..87 (argparse type)."""
    try:
        items = comma_items(text)
    except ValueError as exc:  # `35,,46` tried two actions without a word
        raise argparse.ArgumentTypeError(str(exc)) from None
    try:
        codes = [int(c) for c in items]
    except ValueError:
        raise argparse.ArgumentTypeError(f"action codes are integers 0..{N_ACTIONS - 1}, got {text!r}") from None
    if not codes or any(not 0 <= c < N_ACTIONS for c in codes):
        raise argparse.ArgumentTypeError(f"action codes are integers 0..{N_ACTIONS - 1}, got {text!r}")
    return codes


def card(text: str) -> int:
    """A card index 0..17 (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value < N_CARDS:
        raise argparse.ArgumentTypeError(f"a card is 0..{N_CARDS - 1}, got {text!r}")
    return value


def probe_robot(url: str, timeout_s: float = CONNECT_PROBE_S, fix: str = "", option: str = "") -> None:
    """OptionError at once if a networked robot does not accept a TCP connection: `--try` is a
    check before a study, so say so in about a second instead of retrying with backoff."""
    reason = robot_unreachable(url, timeout_s)
    if reason:  # the URL without its query: a Realtime key is never echoed
        raise OptionError(f"the robot does not accept a connection: {reason}", f"--robot {url.split('?')[0]}",
                          fix=fix, option=option)


def _try(args: argparse.Namespace) -> int:
    codes = args.try_codes
    probe_robot(args.robot)
    acted = []
    robots = []

    def on_acted(event) -> None:
        acted.append(event)
        if robots and robots[0].refused:
            return  # said once, on stderr, by the OptionError below
        print(f"action {event.action}: {event.outcome}{' (' + event.error + ')' if event.error else ''}")
        for label, lines in (("sent   ", event.commands), ("replied", event.replies), ("unsent ", event.unsent),
                             ("unconfirmed", event.unconfirmed)):
            for line in lines:
                print(f"  {label} {line.strip()}")

    robot = open_robot(args.robot, on_acted, config=load_robot_config(args.robot_config),
                       calibration=load_calibration(args.calibration),
                       on_rejected=lambda reason, excerpt: print(f"  unreadable frame from the robot: {reason}"))
    robots.append(robot)
    try:
        for code in codes:
            robot.perform(Suggestion("try", 0, 0, 0, code, args.observed, args.target))
            robot.wait_idle(robot.config.ack_timeout_s + robot.config.give_up_s)
            if robot.refused:  # asking again cannot help: say it once and stop
                raise OptionError(robot.refused, f"--robot {args.robot.split('?')[0]}")  # never echo a key
    finally:
        robot.close()
    return 0 if all(a.outcome in ("done", "sent", "nothing") for a in acted) and len(acted) == len(codes) else 1


def _serve(args: argparse.Namespace) -> int:
    stop = threading.Event()
    stop_on_signals(stop)
    with Bus(options_from_args(args), stop=stop) as bus:
        bridge = bridge_from_args(bus, args.session, args, stop)
        bridge.confirm_recorded = True  # the recorder is another process (services/recorded.py)
        print(f"robot bridge for session {args.session} on {bridge.backend}; bus listening on {bus.listening()}",
              flush=True)
        bridge.run(stop)
    if getattr(stop, "why", ""):  # the status is the signal's (cli/main.py); it said nothing
        print(f"pairplay robot: stopped ({signals.said(stop.why)})", file=sys.stderr)  # every verb's line: stderr
    return 0
