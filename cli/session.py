"""`pairplay session`: one whole session over the bus, recorded to recordings/<session>.mcap.

Rule: the recorder starts first, then the learner and the participant (each a
Node with its liveliness token), and the game last: it waits until every
service the session needs is on the bus, then announces the session. By
default all run in this process on one Zenoh session (peer, loopback, a free
port); `--external learner` (or participant, or game) leaves that service to another
process (`pairplay run learner --session ID --connect <endpoint printed here>`),
which the game then waits for (an external game is started with the session's
options and `--wait-for` the others). The session is over when the game has ended it
and every service has settled (in-process threads finished, external services'
tokens gone); then the recorder finishes its file.

Choices: a simulated participant's ignore rule is "perceived" (it reports what
it perceived) and a human's is "time" (thesis 7.1.2), timed on the board page's
clock, unless given; the learner schedule presets are the thesis's: "virtual"
(6.2), "human-phase1" and "human-phase2" (7.2). A person gets the human-phase
schedule of their algorithm (phase 1: Q-learning, phase 2: pi-reuse) and games
of 5 rounds by default; settings a person cannot satisfy are refused
(SessionConfig.validate). A person plays on the board of `pairplay lab`.
A session id whose recording exists (<session>.mcap or any <session>.<k>.mcap
in --out) is refused before anything starts, unless --force, which sets those
recordings aside (services/recorder.py set_aside) and removes them once the new
recording holds a session: a session stopped before its game started gives
them back; there is no resume of an ended or interrupted session.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from datetime import datetime, timezone
from pathlib import Path

import msgspec

from pairplay import signals, testpause
from pairplay import __version__
from pairplay.cli import interrupts
from pairplay.core.rng import STREAMS_VERSION
from pairplay.schemas.config import DEFAULT_REWARD_BONUS, REWARD_BONUS_RULES, LearnerConfig, LSPIConfig, lspi_unused
from pairplay.schemas.keys import check_chunk
from pairplay.errors import OptionError, UserError, command_word, escaped
from pairplay.outputs import check_folder
from pairplay.schemas.session import (IGNORE_CLOCKS, MS_RANGE, OBSERVED_SOURCES, SessionConfig, learner_overrides,
                                      lspi_overrides)

from pairplay.cli.args import (add_force, count, float_between, game_index, option_policy, output_folder,
                               positive_number, seed_number, session_id, session_rounds)
from pairplay.core.geometry import PICKS_UNIT
from pairplay.cli.robot import add_robot_arguments, check_robot_args, probe_robot_args, robot_choice
from pairplay.services.bus import BusOpenError, ConfigFileError, add_bus_arguments, options_from_args, stop_on_signals
from pairplay.outputs import set_aside_of
from pairplay.services.recorder import (FORCE_SESSION_HINT, REPLACED, check_new_recording, check_not_folders,
                                        earlier_outputs, finished_count, finished_whole, set_aside, settle_aside)
from pairplay.services.runner import waiting_for
from pairplay.services.session import run_session
from pairplay.numbers import counted

milliseconds = float_between(*MS_RANGE, "the board's times: a minute at most")  # schemas/session.py MS_RANGE
PRESETS = {"virtual": LearnerConfig, "human-phase1": LearnerConfig.human_phase1,
           "human-phase2": LearnerConfig.human_phase2}


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("session")
    g.add_argument("--participant", required=True, help="sim:<persona> (a simulated user) or human:<id>")
    g.add_argument("--session", type=session_id, help="session id (default: <participant>-seed<seed>-game<i>-<UTC time>)")
    g.add_argument("--seed", type=seed_number, default=0, help="the session's seed")
    g.add_argument("--rounds", type=session_rounds, help="rounds to play, 1..5000 (default: 20 for sim:, 5 for "
                   "human:, thesis 7.2)")
    g.add_argument("--game-index", type=game_index, default=0, help="which game of the seed (0, 1, ... 2**63-1)")
    g.add_argument("--algorithm", choices=("q-learning", "pi-reuse", "fixed", "lspi"), default="q-learning",
                   help="the learner: Q-learning from scratch (thesis 5.1), pi-reuse of --policy (algorithm 5), "
                        "--policy played as it is, or online LSPI from scratch (algorithm 2, core/lspi.py)")
    g.add_argument("--lspi-ridge", type=positive_number, help="lspi: delta, the ridge penalty (default 1)")
    g.add_argument("--lspi-every", type=count, help="lspi: K, samples between policy improvements (default 10)")
    g.add_argument("--policy", help="policy file: the bias policy (pi-reuse) or the fixed policy; "
                                    "refused with q-learning, which uses none")
    g.add_argument("--observed-source", choices=OBSERVED_SOURCES,
                   help="default: intended for sim:, first-pick for human: (gaze: an eye tracker's GazeFixated events)")
    g.add_argument("--ignore-rule", choices=("perceived", "time"), help="default: perceived for sim:, time for human:")
    g.add_argument("--ignore-window-ms", type=milliseconds,
                   help="'time' rule: picks closer than this ignored the suggestion (thesis 7.1.2; default 1500)")
    g.add_argument("--ignore-clock", choices=IGNORE_CLOCKS,
                   help="'time' rule: time the picks on the board page's clock (page, default for human:) or the "
                        "server's (server)")
    g.add_argument("--turn-back-ms", type=milliseconds, default=1500.0,
                   help="the board page shows a missed pair this long before turning it back (default 1500)")
    g.add_argument("--preset", choices=sorted(PRESETS),
                   help="learner schedule (thesis 6.2, 7.2); default: virtual for sim:, human-phase1 for a human "
                        "with q-learning, human-phase2 with pi-reuse")
    g.add_argument("--reward-bonus", choices=REWARD_BONUS_RULES, default=DEFAULT_REWARD_BONUS,
                   help="simulated reward: when the 1/|candidate set| bonus is paid: when the candidate set holds "
                        "the match (correct, default), on every consistent suggestion (consistent, SPEC's literal "
                        "reading) or on a match only (core/reward.py)")


def config_from_args(args: argparse.Namespace) -> SessionConfig:
    """The session's config from its options; OptionError (a UserError) naming the option if they cannot run."""
    try:
        return _config_from_args(args)
    except KeyError as err:  # an unknown persona
        raise OptionError(str(err.args[0]), f"--participant {args.participant}") from None
    except ValueError as err:
        if isinstance(err, UserError):
            raise
        raise OptionError(str(err), "session options") from None


def _config_from_args(args: argparse.Namespace) -> SessionConfig:
    sim = args.participant.startswith("sim:")
    if not sim and not args.participant.startswith("human:"):
        raise OptionError("use sim:<persona> or human:<id>", f"--participant {args.participant}")
    if args.policy and args.algorithm in ("q-learning", "lspi"):
        raise OptionError(f"--policy is used only by --algorithm pi-reuse or fixed; {args.algorithm} would ignore it",
                          f"--policy {args.policy}")
    if args.algorithm in ("pi-reuse", "fixed") and not args.policy:
        raise OptionError(f"--algorithm {args.algorithm} needs --policy FILE", f"--algorithm {args.algorithm}")
    who = args.participant.split(":", 1)[1]
    if sim:  # the persona's key names the RNG streams, as in the study (core.study)
        from pairplay.core.personas import persona
        who = persona(who).key
    check_chunk("participant", who)
    # a made-up id obeys the rule of a given one (cli/args.py session_id: no . or \, they name its files):
    # `--participant human:p.1` made session p.1-seed0-..., whose recording read as part of another
    session = args.session or session_id(f"{who.replace('.', '_').replace(chr(92), '_')}-seed{args.seed}-"
                                         f"game{args.game_index}-{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%S')}")
    rounds = args.rounds if args.rounds is not None else (20 if sim else 5)
    preset_name = args.preset or ("virtual" if sim else "human-phase2" if args.algorithm == "pi-reuse"
                                  else "human-phase1")
    preset = PRESETS[preset_name]
    schedule = preset(rounds) if preset_name != "virtual" else preset()
    lspi = msgspec.UNSET
    options = {"ridge": "--lspi-ridge", "improve_every": "--lspi-every"}
    given = {k: v for k, v in (("ridge", getattr(args, "lspi_ridge", None)),
                               ("improve_every", getattr(args, "lspi_every", None))) if v is not None}
    unused = lspi_unused(args.algorithm, [options[k] for k in given])
    if unused:
        raise OptionError(unused, "--algorithm")
    if args.algorithm == "lspi":
        try:
            lspi = lspi_overrides(LSPIConfig(**given))
        except ValueError as err:
            raise OptionError(str(err), "--lspi-ridge/--lspi-every") from None
    ignore_rule = args.ignore_rule or ("perceived" if sim else "time")
    timed = [o for o, v in (("--ignore-window-ms", args.ignore_window_ms), ("--ignore-clock", args.ignore_clock))
             if v is not None]
    if timed and ignore_rule != "time":  # ignored without a word (a trial), as LSPI's settings were (lspi_unused)
        raise OptionError(f"{'/'.join(timed)} appl{'ies' if len(timed) == 1 else 'y'} to --ignore-rule time only, "
                          f"not {ignore_rule}" + ("" if args.ignore_rule else " (sim:'s default)"), "--ignore-rule")
    never = schedule.never_reuses() if args.algorithm == "pi-reuse" else ""
    if never:  # `--rounds 1` under human-phase2: its one round is the last, on the new policy alone
        raise OptionError(f"--algorithm pi-reuse with --rounds {rounds} would never reuse the bias policy: "
                          f"{never} (preset {preset_name}); give --rounds 2 or more", f"--rounds {rounds}")
    actions = []
    if args.policy:
        actions = list(option_policy(args.policy, f"--policy {args.policy}").greedy)  # its refusal names --policy
    config = SessionConfig(
        session=session, participant=args.participant, persona=who if sim else "", seed=args.seed,
        rounds=rounds, game_index=args.game_index, algorithm=args.algorithm,
        observed_source=args.observed_source or ("intended" if sim else "first-pick"),
        ignore_rule=ignore_rule, policy_actions=actions,
        learner=learner_overrides(schedule), software_version=__version__,
        reward_bonus=args.reward_bonus, streams=STREAMS_VERSION,
        ignore_window_ms=1500.0 if args.ignore_window_ms is None else args.ignore_window_ms,
        ignore_clock=args.ignore_clock or ("server" if sim else "page"), turn_back_ms=args.turn_back_ms, lspi=lspi)
    config.validate()
    return config


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--out", type=output_folder, default="recordings", help="folder of the recording (default recordings/); a session "
                   "whose recording (<session>.mcap or <session>.<k>.mcap) exists there is refused unless --force")
    add_force(p, "the session's existing recordings (<session>.mcap and <session>.<k>.mcap, and the journals a "
                 "cut one left beside them: recover a cut session first to keep what its journal holds); recover's "
                 "and view's outputs of the earlier session stay, named")
    add_robot_arguments(p)
    p.add_argument("--external", action="append", default=[], choices=("learner", "participant", "game", "recorder", "robot"),
                   help="leave this service to another process (`pairplay run`)")
    add_bus_arguments(p)


def print_interrupted(summary: dict, path: Path, why: str, rounds: int, taken: str = "the id stays taken",
                      verb: str = "session") -> int:
    """What a session stopped by a signal says, in ONE line, from `summary` (run_session's): the
    process must be gone within 2 s of the signal, so the file is not read back. The exit status is
    the signal's (cli/main.py: 130 SIGINT, 143 SIGTERM). A session stopped before its game started
    keeps its file (what came up, and that the signal stopped it: the recorder's end record): a
    session id is taken once it has a recording, and the stop stays on record; every verb then says
    the file holds no session (replay/check.py); `taken` says so, and what the verb offers (session:
    `--force` reuses the id; lab, which never replaces a person's recording, has no --force). A session
    whose game had completed every round when the signal came is complete (its SessionEnded says
    "completed"; verify and rebuild take it whole): the line says so, as every verb's after its work was
    done (cli/main.py), not "interrupted after 20 of 20 rounds"; the status is still the signal's. The line
    goes to stderr, as every verb's interrupted line (stdout holds results only: a complete session's summary),
    and starts `pairplay <verb>:` as every one-line message does (`verb`: session or lab; it had none)."""
    if summary.get("ended") == "completed":  # the signal came after the last round: nothing was cut short
        print(f"pairplay {verb}: interrupted ({why}) after the session had completed all {counted(rounds, 'round')}; recorded "
              f"{counted(summary['events'], 'event')} to {escaped(path)}; nothing was undone", file=sys.stderr)
    elif summary["started"]:
        print(f"pairplay {verb}: interrupted ({why}) after {summary['rounds_played']} of {counted(rounds, 'round')}; recorded "
              f"{counted(summary['events'], 'event')} to {escaped(path)}"
              + (f" ({counted(summary['unrecorded'], 'message')} shed or unrecorded, counted in it)" if summary['unrecorded'] else ""),
              file=sys.stderr)
    else:
        print(f"pairplay {verb}: interrupted ({why}) before the session started; recorded {counted(summary['events'], 'event')} to {escaped(path)}, "
              f"no session in it ({taken})", file=sys.stderr)
    return 0


def cut_line(verb: str, path: Path, again: int) -> str:
    """The one line of a verb whose shutdown a second signal (`again`) cut (session, lab, run recorder, protocol
    serve and pilot), saying what its recording is as the disk holds it (services/recorder.py `finished_whole`,
    `finished_count`), not as far as the cut shutdown got to note it: finished whole, with the events its end
    counts (the signal came after the file's end, before the verb said so), or cut, and how to complete it, or, cut
    before its session started (no SessionStarted in the file nor its journal), that it holds no session and can be
    removed with its journal: `pairplay recover` refuses such a file (replay/recover.py `NoSession`), and the line had
    told to recover it (a new user's trial). It
    said "may lack its end" of a whole file; and a second Ctrl-C as the summary was printed said "nothing more
    was written" with no summary, the recording whole (a new user's trial: once in 6 runs); `lab`'s line left out
    the count `session`'s gave (the summary the cut shutdown had filled, or not). Once the recording is finished
    the verb calls cli/interrupts.py `work_done` (a signal then cuts nothing: the summary is printed, and the
    status is still the signal's); this line is for the signal that came before that, inside the shutdown. A
    recorder closing in another thread (`protocol serve`'s game) is let finish its held step first
    (pairplay/signals.py `held_elsewhere_over`), as one in the main thread would."""
    from pairplay.replay.recover import NoSession, recover
    from pairplay.replay.wal import wal_path
    from pairplay.services.walmerge import admit

    head = f"pairplay {verb}: interrupted again ({signals.said(again)}) while stopping; "
    signals.held_elsewhere_over()  # a recording another thread is finishing (serve's game): its held step ends first
    if finished_whole(path):
        count = finished_count(path)
        events = f" ({counted(count, 'event')})" if count is not None else ""
        return head + f"{escaped(path)} was finished before it: the recording is whole{events}, its end written"
    journal = wal_path(path)
    try:  # what `pairplay recover` would do with it, decided as it decides (nothing is written here)
        recover(path, admit=admit, write=False)
    except NoSession as err:  # cut before the session started: recover refuses it, so the line does not name it
        beside = f" and its journal {journal}" if journal.exists() else ""
        return head + (f"{escaped(path)} {err.what}; it was cut before the session started: there is nothing to recover, "
                       f"{escaped(path)}{beside} can be removed")
    except Exception:  # (UserError: not readable as a recording yet; anything else recover meets, an OSError
        pass  # say): recover says why in its own line; a second signal's line is never lost to it (a traceback)
    return head + (f"{escaped(path)} holds what was recorded up to now and may lack its end: pairplay recover {command_word(path)} "
                   "completes it")


def aside_line(verb: str, path: Path, again: int, aside: list, started: bool | None) -> str:
    """`cut_line` of a `session --force` whose shutdown a second signal cut, once its earlier recordings
    (`aside`, services/recorder.py `set_aside`) were settled (`settle_aside`): what the disk then holds. Given
    back (the game had not started: the new file, which holds no session, removed), the line of a first
    signal there; else the recording's line and the earlier ones as they are: kept beside it, named
    *.replaced (not known whether the game had started), or removed (it had: --force replaced them). It said
    they were kept beside it, the replace done and no *.replaced on disk (a new user's trial)."""
    from pairplay.replay.wal import wal_path

    kept = set_aside_of(path)
    if aside and started is False and not kept:
        return (f"pairplay {verb}: interrupted again ({signals.said(again)}) while stopping, before the session "
                f"started; {escaped(path)}: the earlier recordings are kept (--force replaces them once a new session starts)")
    line = cut_line(verb, path, again)
    if kept:
        journal = wal_path(path)
        remove = f"remove it and its journal {journal.name}" if journal.exists() else "remove it"
        return line + (f"; the earlier recordings are kept beside it, named *{REPLACED} ({', '.join(p.name for p in kept)}): "
                       f"if it holds no session (the game had not started), {remove} and give them their names back")
    if aside:
        return line + "; the earlier recordings are removed: the game had started, and --force replaced them"
    return line


def read_back(path: Path, verb: str):
    """The recording a session just wrote, read back for its summary (`pairplay session`, `pairplay lab`)
    through the reader every verb uses (replay/reader.py `read_log`), so it is judged as they judge it: what it
    lacks (a damaged part, a cut, messages that do not decode: `EventLog.note`) is said in ONE line on stderr,
    naming the file, and the verb exits 1; the summary then counts what the file holds. Its summary read the
    file with no check: a recording that lost a chunk after it was closed was summed up as a session of
    fewer events, exit 0. (the EventLog, its `fold.Summed`): summed up as it is read, nothing of it kept (a
    5,000-round session's summary held its file's records, events and bytes: 930 MB)."""
    recorded, summed = sum_up(path)
    if recorded.note:
        print(f"pairplay {verb}: the recording {escaped(path)} read back is not whole: {recorded.note} (the summary counts "
              f"what it holds; `pairplay replay --verify` of it says more)", file=sys.stderr)
    return recorded, summed


def sum_up(path: Path):
    """(the EventLog, its `fold.Summed` keeping the robot's RobotActed) of the recording at `path`, read as it comes
    (reader.fold_log)."""
    from pairplay.replay.fold import Summed
    from pairplay.replay.reader import fold_log

    return fold_log(path, None, lambda: Summed(frozenset({"RobotActed"})))


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    try:
        check_robot_args(args)
    except ValueError as err:
        raise OptionError(str(err), "robot options") from None
    if "robot" not in args.external:  # a bridge elsewhere (`pairplay robot`) reaches its robot itself
        probe_robot_args(args)
    check_folder(args.out)
    path = Path(args.out) / f"{config.session}.mcap"
    if "recorder" not in args.external and not args.force:  # an external recorder checks its own folder
        check_new_recording(path, FORCE_SESSION_HINT)  # this verb has --force
    elif "recorder" not in args.external:  # --force sets recordings aside, never a folder: refused before the work
        check_not_folders(path)
    summary: dict = {"started": False}  # run_session's, once it has stopped
    aside: list = []
    if not args.force or "recorder" in args.external:
        code = _run(args, config, path, summary)
    else:
        # --force: the earlier recordings are set aside, not removed, until the new one holds a session (a
        # stop before the game started gives them back); before, a Ctrl-C there had already removed them
        aside = set_aside(path)
        try:
            code = _run(args, config, path, summary, kept=bool(aside))
        finally:  # "started" is None when a second Ctrl-C cut the shutdown short before it was known: both kept
            settle_aside(aside, path, replaced=summary.get("started"))
    if summary.get("cut"):  # said once the earlier recordings are settled: what the disk then holds
        print(aside_line("session", path, summary["cut"], aside, summary.get("started")), file=sys.stderr)
    return _left_beside(path, summary, code)


def _left_beside(path: Path, summary: dict, code: int) -> int:
    """`code`, once the outputs of an earlier session of this id left beside the new recording (recover's copy,
    view's .rrd: services/recorder.py `earlier_outputs`) are named in one line on stderr, -q or not: kept, never
    removed (they are the user's), and not this session's."""
    left = earlier_outputs(path) if summary.get("started") else []
    if left:
        from pairplay.cli.main import warn
        warn("session", f"{escaped(path)}: left beside it: {'; '.join(left)} (not this session's; kept: remove it "
                        "once it is not needed)")
    return code


def _run(args: argparse.Namespace, config: SessionConfig, path: Path, summary: dict, kept: bool = False) -> int:
    """The session once its recording's path is free (`run`); `summary`: run_session's. `kept`: --force set
    earlier recordings aside, given back if the game does not start (`run`)."""
    stop = threading.Event()
    stop_on_signals(stop)

    def announce(bus) -> None:
        # the first line says where we listen and what the game waits for (started elsewhere: --external)
        waits = waiting_for([f"{x} (started elsewhere)" for x in args.external if x != "game"])
        client = f" - client of {' '.join(args.connect)}" if args.connect else ""
        print(f"session {config.session}: bus listening on {bus.listening()}{client}"
              f"{' - ' + waits if waits else ''}", flush=True)
        if config.participant.startswith("human:"):
            print("a person plays on a board: `pairplay lab` serves one (this session waits for picks from "
                  "source 'board' on the bus)", flush=True)

    try:
        bus_options = options_from_args(args, default_mode="router")
        bus_options.to_dict()  # a bad --zenoh-config is the user's mistake: one line, before anything starts
        path = run_session(config, path, bus_options=bus_options,
                           external=tuple(args.external), stop=stop, on_bus=announce, summary=summary,
                           robot=None if "robot" in args.external else robot_choice(args))
        interrupts.work_done()  # the recording is finished: a signal from now on cuts nothing (see `cut_line`)
    except KeyboardInterrupt:  # a second signal: the shutdown of the first was cut short
        if "events" not in summary:  # run_session did not get to say whether the game had started
            summary["started"] = None
        if stop.is_set() and "recorder" not in args.external:
            again = signals.again or signal.SIGINT  # (a second SIGTERM cuts it too: pairplay/signals.py `wait_cut`)
            summary["cut"] = again  # its line is said by `run`, once the earlier recordings are settled
            return 128 + again
        raise
    except (ConfigFileError, BusOpenError) as err:
        print(f"pairplay session: {err}", file=sys.stderr)
        return 2
    testpause.pause("recording-finished")
    if "recorder" in args.external:
        if summary.get("not_recorded"):  # its recorder left the bus and none came back (services/recorderwatch.py)
            print(f"pairplay session: {escaped(summary['not_recorded'])}", file=sys.stderr)
            return 1
        if getattr(stop, "why", ""):  # said "over; the external recorder writes its file" of a session stopped
            # while it waited for a recorder that never came (trial36 W1)
            print(f"pairplay session: interrupted ({signals.said(stop.why)}); session {escaped(config.session)}: what "
                  "was recorded, if its external recorder joined, is in that recorder's file", file=sys.stderr)
            return 0
        if not getattr(args, "quiet", False):
            print(f"session {config.session} over; the external recorder writes its file")
        return 0
    if getattr(stop, "why", ""):
        if kept and not summary.get("started"):  # its file holds no session: the earlier ones get their names back
            print(f"pairplay session: interrupted ({signals.said(stop.why)}) before the session started; {escaped(path)}: the earlier "
                  f"recordings are kept (--force replaces them once a new session starts)", file=sys.stderr)
            return 0
        return print_interrupted(summary, path, signals.said(stop.why), config.rounds, "the id stays taken: --force reuses it")
    from pairplay.replay.delivery import delivery_line
    recorded, summed = read_back(path, "session")
    fold = summed.fold
    picks = fold.picks_per_round()
    if not getattr(args, "quiet", False):  # a summary of the file it wrote: -q leaves it out (cli/main.py QUIET_SUMMARIES)
        print(f"recorded {counted(summed.events, 'event')} to {escaped(path)}")
        print(f"rounds played: {len(picks)}; {PICKS_UNIT}: {picks[:10]}{' ...' if len(picks) > 10 else ''}")
        print(f"rejections: {len(fold.rejections)}; Q updates: {fold.counts.get('QUpdated', 0)}"
              + (f"; LSPI samples: {fold.counts.get('LSPIUpdated', 0)}" if config.algorithm == "lspi" else ""))
        robot = delivery_line(summed.kept)
        if robot:
            print(robot)
    e = fold.ended
    if e is None:
        print("ended: no SessionEnded recorded")
    elif e.reason != "completed":
        print(f"ended: {escaped(e.reason)}{f' ({escaped(e.detail)})' if e.detail else ''} after {e.rounds_played} of "
              f"{counted(config.rounds, 'round')}")
    if recorded.note:  # the session's recording lacks what the summary would count: not a clean run
        return 1
    return 0 if e is not None and e.reason in ("completed", "interrupted", "aborted") else 1
