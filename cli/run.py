"""`pairplay run SERVICE`: one service alone in this process, on the bus.

Rule: the service joins the session given by --session, catches up from the
recorder's log if the session is under way (a restarted learner resumes where
the crashed one stopped), runs until the session ends for it, and exits 0; on
SIGINT/SIGTERM it closes its Zenoh session cleanly. A game started with
--participant (and the options of `pairplay session`) starts the session; a game
given only --session restarts a crashed one from the recorder's log. The other
services read the config from the bus. The first line printed is `listening <endpoints>` so an orchestrator can
connect further processes to this one. A recorder whose session has a
recording in --out continues it only if the services of the session on the bus
sent the very events it holds (a recorder restarted within the live session,
services/recorder.py `same_live_session`); otherwise it refuses in one line,
before its `listening` line (a live recording's before the bus opens: the
listening line came first, then the refusal).
An option a service does not use is refused in one line, never ignored: the
session's options (--algorithm, --policy, --rounds, ...) belong to the game that
starts the session; a learner, a participant, a recorder, a combiner and a game
restarted by --session alone follow the config the session was started with.
A game that waits for a recorder (--wait-for recorder) is held while none is on the bus, and the session fails
once it has been gone `--settle` seconds (30 by default, as a session's settle time for any service it needs).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time
from pathlib import Path

from pairplay import signals, testpause
from pairplay.cli import interrupts
from pairplay.cli.args import duration, note_given, output_folder, session_id
from pairplay.errors import OptionError, command_word, escaped
from pairplay.lists import comma_items, repeated
from pairplay.nearest import hinted
from pairplay.numbers import counted, shown
from pairplay.outputs import check_folder
from pairplay.schemas.trust import SERVICES as BUS_SERVICES
from pairplay.services.bus import Bus, Deadline, add_bus_arguments, deadline_of, options_from_args, signal_taken, stop_on_signals
from pairplay.services.forgery import EVERY_LISTENER, ForgeryWatch
from pairplay.services.refusal import RefusalWatch
from pairplay.services.runner import GAME_GONE_S, GameWatch, Node, Stopped, start_unless_stopped, waiting_for

SERVICES = ("game", "learner", "participant", "recorder", "combiner")  # what `run` runs
WAITABLE = BUS_SERVICES - {"game"}  # what a game can wait for: every other service on the bus

log = logging.getLogger("pairplay.run")


def services_to_wait_for(text: str) -> list[str]:
    """`learner,recorder` -> ["learner", "recorder"]; argparse's one line for an unknown name or an empty item.
    A new user's trial gave `--wait-for learner,participant,recorder`: taken as one service of that name, the game
    waited 30 s and said none of them was on the bus, though all three were (and `--wait-for foo` waited too)."""
    try:
        names = comma_items(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    unknown = [n for n in names if n not in WAITABLE]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{', '.join(hinted(n, WAITABLE) for n in unknown) or repr(text)}: "
                                         f"not a service to wait for "
                                         f"(one of {', '.join(sorted(WAITABLE))})")
    if twice := repeated(names):
        raise argparse.ArgumentTypeError(f"{text!r} names {twice} twice: each service is waited for once")
    return names


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("service", choices=SERVICES)
    p.add_argument("--session", type=session_id, help="session id (required except for the game, which can make one)")
    p.add_argument("--out", type=output_folder, default="recordings",
                   help="recorder: directory of the recording; combiner: the directory its requests' paths lie in")
    p.add_argument("--participant", help="game: sim:<persona> or human:<id>")
    p.add_argument("--wait-for", action="extend", type=services_to_wait_for, default=[], metavar="SERVICES",
                   help=f"game: services to wait for before starting, comma-separated or the option repeated "
                        f"(of {', '.join(sorted(WAITABLE))})")
    p.add_argument("--settle", type=duration, default=GAME_GONE_S, metavar="SECONDS",
                   help=f"game with --wait-for recorder: how long the recorder may be off the bus, the game held, "
                        f"before the session fails (default {GAME_GONE_S:g}, 0..3600)")
    add_bus_arguments(p)
    known = {a.dest for a in p._actions}
    from pairplay.cli.session import add_config_arguments
    extra = argparse.ArgumentParser(add_help=False)
    add_config_arguments(extra)
    for action in extra._actions:
        if action.dest not in known and action.option_strings:
            p._add_action(action)
            note_given(action)
    for action in p._actions:
        if action.dest in ("participant", "wait_for", "out", "settle"):
            note_given(action)


# options besides the bus's and --session that a service uses; the session's options (the game's, with
# --participant) are in CONFIG: any other a service is given is refused (module rule)
USES = {"game": {"participant", "wait_for", "settle"}, "recorder": {"out"}, "combiner": {"out"},
        "learner": set(), "participant": set()}


def refuse_unused(args: argparse.Namespace) -> None:
    """OptionError naming the first option given that `args.service` would not use (module rule)."""
    starts = args.service == "game" and bool(args.participant)
    given = dict((dest, option) for dest, option in getattr(args, "_given", ()))
    if args.service == "game" and "settle" in given and "recorder" not in args.wait_for:  # it would change nothing
        raise OptionError(f"{given['settle']} {shown(args.settle)} is the time a recorder the game waits for may be off "
                          "the bus: give --wait-for recorder too", given["settle"])
    for dest, option in getattr(args, "_given", ()):
        if dest in USES[args.service] or (starts and dest not in ("out",)):
            continue
        value = getattr(args, dest)
        # (as typed: `--turn-back-ms 5` was echoed "5.0")
        said = " ".join(map(str, value)) if isinstance(value, list) else shown(value)
        if dest in ("participant", "wait_for", "settle"):
            why = "used by the game only"
        elif dest == "out":
            why = "used by the recorder and the combiner only"
        elif args.service == "game":
            why = ("a session's option, taken by a game that starts it (with --participant); a game restarted "
                   "by --session alone plays the config in the session's log")
        else:
            why = (f"a session's option: the {args.service} follows the config the game started the session with "
                   f"(pairplay run game --participant ... {option} ...)")
        raise OptionError(f"{option} {said} is not taken by pairplay run {args.service}: {why}", option)


def run(args: argparse.Namespace) -> int:
    stop = threading.Event()
    stop_on_signals(stop)
    recording: dict = {}  # the recorder's file, once it has one (_run)
    try:
        code = _run(args, stop, recording)
    except KeyboardInterrupt:  # a second signal cut the shutdown: what the recording is, as the disk holds it
        if not signal_taken(stop) or "path" not in recording:  # (the handler's note: services/bus.py signal_taken)
            raise
        from pairplay.cli.session import cut_line
        again = signals.again or signal.SIGINT
        print(cut_line("run recorder", recording["path"], again), file=sys.stderr)
        return 128 + again
    if code == 0 and getattr(stop, "why", ""):  # the status is the signal's (cli/main.py); it said nothing
        # a file that holds no session still takes its id, as `pairplay session` interrupted before its start says
        empty = f" before session {args.session} started: {holds_none(recording['path'])}" if recording.get("empty") else ""
        print(f"pairplay run {args.service}: stopped ({signals.said(stop.why)}){empty}", file=sys.stderr)
    elif code == 0 and recording.get("empty"):  # its game left the bus without starting the session (it gave up)
        print(f"pairplay run recorder: session {args.session}'s game left the bus without starting it: "
              f"{holds_none(recording['path'])}", file=sys.stderr)
        return 1
    return code


def holds_none(path) -> str:
    """What a recorder's line says of a file that holds no session: kept, and the id it takes."""
    return (f"{escaped(str(path))} holds no session (the id stays taken: remove the file, or "
            "`pairplay session --force`, to reuse it)")


def _none_held(earlier: Path) -> str:
    """The way out for an id taken by a recording that holds no session (a recorder stopped before its session
    began: the stop line said to remove it), "" for one that holds a session: "has a recording already" alone
    gave no way out, and not the one the stop line had given (trial34 E)."""
    from pairplay.replay.check import journal_holds_no_session
    from pairplay.replay.reader import read_any_log
    from pairplay.replay.wal import wal_path
    journal = wal_path(earlier)
    if not read_any_log(earlier).no_session or (journal.exists() and not journal_holds_no_session(journal)):
        return ""
    both = f"{escaped(earlier.name)} and its journal" if journal.exists() else escaped(earlier.name)
    return f"it holds no session (its recorder stopped before the session began): remove {both} to reuse the id, " \
           "or choose another --session"


def _run(args: argparse.Namespace, stop: threading.Event, recording: dict) -> int:
    refuse_unused(args)
    config = None
    if args.service == "game" and args.participant:
        from pairplay.cli.session import config_from_args
        config = config_from_args(args)
        if "robot" in args.wait_for:  # a bridge elsewhere (`pairplay robot`): its SessionStarted says one is expected
            import msgspec
            config = msgspec.structs.replace(config, robot="external")
        args.session = config.session
    elif not args.session:
        raise OptionError(f"--session is required for the {args.service}", "--session")
    earlier = None
    if args.service == "recorder":
        from pairplay.livelock import is_live
        from pairplay.services.recorder import RecordingExists, latest_file, same_live_session
        check_folder(args.out)
        path = Path(args.out) / f"{args.session}.mcap"
        earlier = latest_file(path)
        # before the bus opens: its listening line came first, then this refusal (a new user's trial)
        if earlier is not None and is_live(earlier):  # its recorder is running: not ours to continue
            raise RecordingExists(earlier, args.session, live=True)
    bus = Bus(options_from_args(args))  # a BusError (one line, exit 2) if it cannot open
    node = None
    try:
        if args.service == "recorder":
            # a recorder restarted within the live session continues its file; a new session's is refused,
            # before the listening line (asking the bus takes up to 3 s, more while a service of the session is on the bus
            # and silent; a refusal is the one line said)
            restart = earlier is not None and same_live_session(bus, args.session, path, stop=stop)
            if stop.is_set():  # a signal while it asked: nothing recorded, the signal's line (run)
                return 0
            if earlier is not None and not restart:
                raise RecordingExists(earlier, args.session, _none_held(earlier) or
                                      "no live session on the bus sent what it holds; choose another --session (a "
                                      "recording is never replaced)")
        # the first line: where we listen (an orchestrator connects there), and what a game waits for
        waits = waiting_for(args.wait_for) if args.service == "game" else ""
        print(f"listening {bus.listening()}{' - ' + waits if waits else ''}", flush=True)
        if args.service == "recorder":
            from pairplay.services.recorder import RECORDER_SWITCH_S, Recorder
            recorder = Recorder(bus, args.session, path, on_failure=lambda _why: stop.set(), restart=restart)
            recording["path"] = recorder.path
            sys.setswitchinterval(RECORDER_SWITCH_S)  # this process is the recorder alone (see its rule)
            recorder.start()
            game = GameWatch(bus, args.session)  # a session whose end never reached us: its game is gone
            if restart:  # its game was live when we asked (same_live_session), and may have ended since
                game.existed()
            checked = 0.0
            try:
                # after SessionEnded the learner still settles the last reward: stay while others are on the bus
                while not stop.is_set() and not game.gone():
                    recorder.step()
                    if recorder.ended and time.monotonic() - checked > 0.3:
                        checked = time.monotonic()
                        if not _others_alive(bus, args.session):
                            break
            finally:
                # stopped: done by the shutdown's deadline (started by the signal), less the bus's close
                failure = recorder.close(stopped_by=getattr(stop, "why", "") if stop.is_set() else "",
                                         deadline=Deadline(deadline_of(stop).left(0.1)) if stop.is_set() else None)
            interrupts.work_done()  # the file is finished: a signal from now on cuts nothing (cli/session.py cut_line)
            if not restart and not recorder.holds_session:  # kept (check_new_recording's rule), and said so
                recording["empty"] = True
            testpause.pause("recording-finished")
            if failure is not None:
                print(escaped(f"pairplay run recorder: writing {recorder.path} failed ({failure}); the file is "
                              "readable up to the failure: ") + f"pairplay recover {command_word(recorder.path)}",
                      file=sys.stderr)
                return 1
            if not recording.get("empty"):  # the one line a person looks for on its host, as `pairplay session` says it
                # (it said nothing at its end: trial34 J); a file that holds no session is said by run()
                print(f"recorded {counted(recorder.writer.count, 'event')} to {escaped(str(recorder.path))}", flush=True)
            return 0
        if args.service == "combiner":
            from pairplay.services.combiner import CombinerLogic
            logic = CombinerLogic(args.out)
        elif args.service == "game":
            from pairplay.services.game import GameLogic
            if config is None:  # a restart: the session's config is in its log
                config = _recorded_config(bus, args.session, stop)
                if config is None:
                    raise OptionError("the session has no SessionStarted on the bus; give --participant (and "
                                      "the session options) to start it", f"--session {args.session}")
            logic = GameLogic(config)
        elif args.service == "learner":
            from pairplay.services.learner import LearnerLogic
            logic = LearnerLogic()
        else:
            from pairplay.services.participant import ParticipantLogic
            logic = ParticipantLogic()
        # a game given its config starts the session; every other service, and a game
        # restarted by session id alone, catches up from the recorder's log
        node = Node(bus, logic, args.session, resume=not (args.service == "game" and args.participant), stop=stop)
        node.confirm_recorded = True  # the recorder is another process: leave once it holds ours (services/recorded.py)
        # a game alone in its process: a service elsewhere that refuses its start can take no part, and the
        # game would wait for it for ever: it ends the session, one line (services/refusal.py); subscribed
        # before the start. Its end refused: the refusing service's own process ends (runner.GameWatch)
        refusals = RefusalWatch(bus, args.session, node, tags=("SessionStarted",)) if args.service == "game" else None
        # a game that waits for a recorder is held while it is off the bus, and fails if none is back in time
        recorder_watch = None
        if args.service == "game" and "recorder" in args.wait_for:
            from pairplay.services.recorderwatch import RecorderWatch
            recorder_watch = RecorderWatch(bus, args.session, lambda: logic.round, over=lambda: logic.done,
                                           connect=" ".join(args.connect) or " ".join(bus.locators()),
                                           settle_s=args.settle)
            node.hold = recorder_watch.held
        try:
            start_unless_stopped(lambda: node.start(wait_for=tuple(args.wait_for)), stop, args.service)
        except Stopped:
            return 0
        if not getattr(args, "quiet", False):  # chatter: its listening line said where it is (cli/main.py -q rule)
            print(f"{args.service} running in session {args.session}", flush=True)
        # the service's own thread publishes what it decides (Node.step) and may wait in a put on a
        # congested peer; this (main) thread stays free for the signals and the bounded shutdown
        thread = node.run_in_thread(stop)
        # a game alone in its process: every listener is elsewhere, so a forged start or end that fits the
        # game's sequence may have been taken (services/forgery.py): the game ends the session, one line
        watch = ForgeryWatch(node, [], external=EVERY_LISTENER) if args.service == "game" else None
        forged = refused = gone = ""
        while thread.is_alive() and not stop.wait(0.05):
            forged = watch.verdict() if watch is not None else ""
            refused = refusals.verdict() if refusals is not None and not forged else ""
            if recorder_watch is not None:
                said = recorder_watch.line()
                if said:
                    log.warning(said)
                if recorder_watch.gone_for() > args.settle:  # the session's settle time (--settle)
                    gone = f"recorder left the bus and did not come back within {args.settle:g} s"
            if forged or refused or gone:
                stop.set()
        said = recorder_watch.line() if recorder_watch is not None else ""
        if said:  # what came after the last check, said too
            log.warning(said)
        # taken before the end: a recorder leaves the bus once the session has ended
        not_recorded = recorder_watch.lost(logic.config.rounds if logic.done else logic.round + 1,
                                           getattr(stop, "why", "") if stop.is_set() else "") \
            if recorder_watch is not None else ""
        if stop.is_set():
            thread.join(deadline_of(stop).left(0.5, 0.2))
        elif args.service == "game" and not not_recorded and node.lacking:  # said as a session's failure, below
            not_recorded = f"{node.lacking} (session {args.session})"
        if args.service == "game" and not logic.done:  # stopped: the session's end says why and how far
            from pairplay.services.session import end_reason
            reason, detail = end_reason(stop, forged or refused or gone)
            with node._lock:
                node.publish(node.driver._stamp(logic.end(reason, detail)))
            node.close(deadline_of(stop).left(0.3, 0.5))  # let the recorder take it before the bus closes
            time.sleep(deadline_of(stop).left(0.3, 0.2))
        if forged:
            from pairplay.services.session import ForgedEvent
            raise ForgedEvent(f"{forged}: the game ended the session", f"session {args.session}")
        if refused:
            raise refusals.error(f"session {args.session}")
        if not_recorded:  # one line, exit 1: a session that failed (README's exit table)
            print(f"pairplay run game: {escaped(not_recorded)}", file=sys.stderr)
            return 1
        return 0
    finally:
        deadline = deadline_of(stop) if stop.is_set() else Deadline(1.0)
        if node is not None:
            node.close(deadline.left(0.1, 0.5))
        bus.close(deadline.left(cap=0.5))


def _recorded_config(bus: Bus, session: str, stop: threading.Event):
    from pairplay.services.runner import fetch_log
    for e in fetch_log(bus, session, stop=stop):
        if type(e).__name__ == "SessionStarted":
            return e.config
    return None


def _others_alive(bus: Bus, session: str) -> bool:
    from pairplay.schemas.keys import alive_key
    alive = bus.alive_now(alive_key(session, "*"), timeout_s=0.3)
    return any(not k.endswith("/recorder") for k in alive)
