"""`pairplay protocol`: a study with people (thesis 7.2): check, example, init, register, consent, status, serve, pilot.

Rule: every subcommand works on a study folder (replay/studydata.py) and
prints what it did; a mistake (a bad study file, an unknown participant, a step
the plan refuses) is one line on stderr and exit 2. `pilot` runs the open
steps of the plan with scripted participants (core personas touching the board
through services/scripted.py), the whole protocol without people: a dress
rehearsal. With people, `serve` runs the study's lab server (the lab of
services/lab with the console's routes, services/console/server.py): the
experimenter's console behind a token printed at start, each game's board
page (the console links it), the questionnaire the board becomes after each
game; `--pilot p02=blind` lets personas play some participants' games.
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import tempfile
import time
from pathlib import Path

from pairplay import signals, testpause
from pairplay.cli.args import int_between, key_chunk, output_file, output_folder, session_id, time_ns
from pairplay.core.personas import persona
from pairplay.inputs import check_input, check_option_file
from pairplay.lists import comma_items
from pairplay.replay import biases, studyjournal
from pairplay.replay.studydata import (JOURNAL, REGISTER_AT_ONCE, TABLES, StudyData, StudyDataError, consent_words,
                                       repair_journal)
from pairplay.schemas.study import (StudyFileError, bundled_studies, bundled_text, example_text, no_study_file,
                                    parse_study, study_file_of)
from pairplay.errors import command_word, escaped
from pairplay.numbers import counted

EXAMPLE_NAME = "thesis-ch7"


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    c = sub.add_parser("check", help="check a study file and print its protocol")
    c.add_argument("study_file", help=f"a study TOML file, or a bundled study's name ({EXAMPLE_NAME}: the example)")
    e = sub.add_parser("example", help="print the shipped example study file (the thesis's chapter 7)")
    e.set_defaults(study_file=EXAMPLE_NAME)
    i = sub.add_parser("init", help="make a study folder from a study file")
    i.add_argument("folder", type=output_folder)
    i.add_argument("--study", required=True,
                   help=f"the study TOML file, or a bundled study's name ({EXAMPLE_NAME}: the example)")
    i.add_argument("--key-file", type=output_file(),
                   help="a CSV of id,name kept OUTSIDE the study folder (optional; without it no name is accepted)")
    r = sub.add_parser("register", help="register a participant: prints their pseudonymous id")
    r.add_argument("folder", type=Path)
    r.add_argument("--phase", help="the phase they first play (default: the first)")
    r.add_argument("--name", default="", help="written to the key file only (refused without one)")
    r.add_argument("--count", type=int_between(1, REGISTER_AT_ONCE, "as the console: one request registers a few dozen at most"),
                   default=1, help=f"register this many (default 1, at most {REGISTER_AT_ONCE})")
    r.add_argument("--consent", action="store_true",
                   help="they signed the study's consent form (its consent_form) now: records their consent; "
                        "without it they play only as personas (a rehearsal) until `protocol consent`")
    co = sub.add_parser("consent", help="record a registered participant's informed consent (given now, to the "
                                        "study's consent form)")
    co.add_argument("folder", type=Path)
    co.add_argument("participant", type=key_chunk("participant id"))
    co.add_argument("--form", help="the version of the form they signed, one the study has had (default: the "
                                   "study's consent form now)")
    co.add_argument("--given-at", type=time_ns, metavar="ISO-TIME",
                    help="when they signed, if before now (a consent held on paper), not before the study folder "
                         "was made: journaled as given then, recorded now; without a zone, this computer's local time")
    cf = sub.add_parser("consent-form", help="the study's consent form from now on (an ethics amendment): people "
                                             "who consented to an earlier one play once they consent to it")
    cf.add_argument("folder", type=Path)
    cf.add_argument("form", help='the new form\'s version ("v2 2026-11")')
    s = sub.add_parser("status", help="the plan: every step, done or next, and why a step is blocked")
    s.add_argument("folder", type=Path)
    pl = sub.add_parser("pilot", help="run the open steps of the plan with scripted participants (core personas)")
    pl.add_argument("folder", type=Path)
    pl.add_argument("--personas", required=True,
                    help="comma-separated personas, one per registered participant in order (e.g. tatiana,blind)")
    pl.add_argument("--robot", help="override the study's robot (virtual, none, iristk://..., furhat://...)")
    sv = sub.add_parser("serve", help="serve the experimenter's console for a study folder (prints its URL and token)")
    sv.add_argument("folder", type=Path)
    sv.add_argument("--listen", default="127.0.0.1:0",
                    help="HOST:PORT of the web server (default loopback, a free port; beyond loopback use TLS, "
                         "see README)")
    sv.add_argument("--robot", help="override the study's robot (virtual, none, iristk://..., furhat://...)")
    sv.add_argument("--certfile", help="TLS certificate (PEM): serve https/wss (as `pairplay lab`)")
    sv.add_argument("--keyfile", help="TLS private key (PEM) of --certfile")
    sv.add_argument("--pilot",
                    help="ID=PERSONA,...: these participants are played by core personas on the bus (a dress "
                         "rehearsal from the console; the others play on the board page)")
    rp = sub.add_parser("repair", help="set aside the journal's last line a crash cut (it blocks every verb until then)")
    rp.add_argument("folder", type=Path)
    m = sub.add_parser("mark-invalid", help="keep a game out of the plan, the combination and the report")
    m.add_argument("folder", type=Path)
    m.add_argument("session", type=session_id)
    m.add_argument("--reason", required=True)


def _bundled(name: str) -> bool:
    """`name` (a study file argument) names a bundled study: a file of that name here comes first."""
    return name in bundled_studies() and not Path(name).exists()


def _study_file(name: str) -> tuple[str, str]:
    """(text, source) of a study file argument: a file, or a bundled study's name (a name that is neither
    is refused with the bundled ones: `--study thesis-ch8` said only "No such file or directory")."""
    if _bundled(name):
        return bundled_text(name), f"{name} (shipped example)" if name == EXAMPLE_NAME else f"{name} (bundled study)"
    path = study_file_of(name)  # a study folder: its own study file
    name = str(path)
    check_input(path, StudyFileError)  # before opening: a pipe blocked (pairplay/inputs.py)
    try:
        return path.read_text(encoding="utf-8-sig"), name  # as load_study: a byte order mark is fine
    except UnicodeDecodeError:  # as load_study says it (a random or binary file was a traceback)
        raise StudyFileError(f"{name}: cannot read: not UTF-8 text") from None
    except FileNotFoundError:
        raise no_study_file(name) from None
    except OSError as err:  # as load_study says it
        raise StudyFileError(f"{name}: cannot read: {err.strerror or err}") from None


def _repair(folder: Path) -> int:
    """`protocol repair FOLDER` (replay/studyjournal.py): what it set aside, and what it means."""
    done = repair_journal(folder)
    journal = folder / JOURNAL
    if done.aside is not None:
        print(escaped(f"set aside the cut last line of {journal} ({counted(len(done.torn), 'byte')}, what a crash left "
                      f"of the event it wrote) in {folder / done.aside.name}; the journal keeps its "
                      f"{counted(done.kept, 'whole line')}: the study goes on from them (a game whose end was cut is "
                      "journaled from its recording by the next serve, pilot or report)"))
        # the tables held what the torn line said (a consent's row): written again from the journal left
        print(escaped(f"{', '.join(TABLES)} written again from the journal's {counted(done.kept, 'whole line')}"))
        pid = studyjournal.torn_registration(done.torn)
        kind, named = studyjournal.torn_event(done.torn)
        if pid:
            print(escaped(f"the cut line was the registration of {pid}: that id will not be given again; its "
                          "key-file line, if any, stays (`protocol status` lists it)"))
        elif kind == "ConsentGiven" and named:  # the tables said it held: written again, without it
            print(escaped(f"the cut line was {named}'s consent (ConsentGiven): it is not recorded now; record it "
                          f"again (`pairplay protocol consent {command_word(folder)} {command_word(named)}`)"))
        elif kind:
            print(escaped(f"the cut line was a {kind}" + (f" of {named}" if named else "")))
    elif done.newline:
        print(escaped(f"{journal}: its last line was whole but for its end of line: added; nothing set aside "
                      f"({counted(done.kept, 'line')})"))
    else:
        print(escaped(f"{journal}: nothing to repair: every line is whole ({counted(done.kept, 'line')})"))
    return 0


def describe(study) -> list[str]:
    lines = [f"study {study.study.id}: {study.study.title}",
             f"  seed {study.study.seed}, ignore window {study.study.ignore_window_ms:g} ms, robot {study.study.robot}, "
             f"wrong-suggestion button {'on' if study.study.wrong_suggestion_button else 'off'}",
             f"  consent form: {study.study.consent_form!r}" if study.study.consent_form else
             "  consent form: not named (consent is recorded without its version: set [study] consent_form)"]
    for p in study.phase:
        cfg = study.learner_config(p)
        lines.append(f"  {p.id}: {p.players} players, {counted(p.games, 'game')} x {counted(p.rounds, 'round')}, {p.algorithm} "
                     f"({p.preset}: epsilon {cfg.epsilon_start:g} - {cfg.epsilon_step:g}/round"
                     + (f", psi x{cfg.psi_round_decay:g}/round, new policy alone from round {cfg.reuse_rounds + 1}"
                        if p.algorithm == "pi-reuse" and cfg.reuse_rounds is not None else "")
                     + ")" + (f", bias = combination of {p.bias}" if p.bias else "")
                     + (f", questionnaire {', '.join(p.questionnaires)} after each game" if p.questionnaires else ""))
    for name, q in study.questionnaire.items():
        kinds = {}
        for item in q.item:
            kinds[item.kind] = kinds.get(item.kind, 0) + 1
        lines.append(f"  questionnaire {name}: {counted(len(q.item), 'item')} ("
                     + ", ".join(f"{v} {k}" for k, v in kinds.items()) + ")")
    return lines


def run(args) -> int:
    try:
        return _run(args)
    except (StudyFileError, StudyDataError, KeyError) as err:
        print(f"pairplay protocol {args.action}: {err.args[0] if isinstance(err, KeyError) else err}",
              file=sys.stderr)
        return 2
    # an OSError (a full disk part way) is said by cli/main.py, as every verb's: `what (where)`; said
    # here it was `pairplay protocol init: : No space left on device` when it named no file


def _run(args) -> int:
    if args.action == "example":
        sys.stdout.write(example_text())
        return 0
    if args.action == "check":
        text, source = _study_file(args.study_file)
        print("\n".join(describe(parse_study(text, source))))
        return 0
    if args.action == "init":
        from pairplay.outputs import check_folder, hold
        hold(args.folder, "protocol init")  # two inits of one new folder: one writer per output (pairplay/outputs.py)
        check_folder(args.folder)  # a place the system refuses, named as given, before anything is written
        study_path = args.study
        if _bundled(args.study):
            parent = args.folder.resolve().parent
            parent.mkdir(parents=True, exist_ok=True)
            # a name of its own (O_EXCL): `.thesis-ch7.toml` there, the user's, was replaced and then removed
            fd, name = tempfile.mkstemp(prefix=f".{args.study}.", suffix=".toml", dir=parent)
            tmp = Path(name)
            try:
                with open(fd, "w", encoding="utf-8") as f:
                    f.write(bundled_text(args.study))
            except OSError as err:  # a full disk: said of the folder asked for, not of our file, which goes
                tmp.unlink(missing_ok=True)
                raise OSError(err.errno, err.strerror, str(args.folder)) from None
            study_path = tmp
        elif not Path(study_path).exists():  # named with its option, as every refusal of an option's value
            raise StudyDataError(str(no_study_file(study_path)), "--study")
        else:
            text, source = _study_file(study_path)  # a name neither a file nor bundled: the bundled ones said
            parse_study(text, source)
        try:  # (another study's folder: its study file, schemas/study.py study_file_of)
            data = StudyData.create(args.folder, study_file_of(study_path), args.key_file)
        finally:
            if study_path != args.study:  # ours, the bundled study's copy
                Path(study_path).unlink()
        print(escaped(f"study folder {data.given} ({data.study.study.id}); key file: {data.key_file or 'none'}"))
        print("\n".join(escaped(line) for line in describe(data.study)))
        return 0
    if args.action == "repair":
        return _repair(args.folder)
    # every action but status writes the folder: it holds the folder's writer lock for the verb's length (serve: as
    # long as it serves; one writer per study folder, pairplay/folderlock.py); status reads beside a writer
    with StudyData(args.folder, writer="" if args.action == "status" else f"protocol {args.action}") as data:
        return _on_folder(data, args)  # the lock released when the verb ends (in a process that goes on: tests)


def _on_folder(data: StudyData, args) -> int:
    if args.action != "status":  # the others write in it: a folder one may not write in is one line now, named as
        from pairplay.outputs import check_folder  # given (serve served its console and failed at each step)
        check_folder(args.folder)
    if args.action == "register":
        for pid in data.register_many(args.phase or data.study.phase[0].id, args.count, args.name,
                                      consent=args.consent):
            print(pid)
        data.write_tables()
        if not args.consent:  # a note, not a result: a person's game waits for their consent
            print(f"pairplay protocol register: no consent recorded: a person plays once it is "
                  f"(`pairplay protocol consent {command_word(data.given)} ID`, or --consent at registration); a persona "
                  "(pilot) needs none", file=sys.stderr)
        return 0
    if args.action == "consent":
        given = data.record_consent(args.participant, args.form, args.given_at)
        data.write_tables()
        print(escaped(f"{args.participant}: consent recorded: {consent_words(given)}"))
        if problem := data.consent_problem(args.participant):  # a form of before (on paper): they still wait
            print(escaped(f"pairplay protocol consent: {args.participant} has {problem}: their next game waits for "
                          "their consent to it"), file=sys.stderr)
        return 0
    if args.action == "consent-form":
        _, earlier = data.change_consent_form(args.form)
        data.write_tables()
        print(escaped(f"consent form from now on: {data.consent_form!r} (the study file's {data.study.study.consent_form!r}"
                      " stays as it was made)"))
        if earlier:  # each next game waits: said now, not at the board
            print(escaped(f"consent to an earlier form only: {', '.join(earlier)}: their next game waits for their "
                          f"consent to {data.consent_form!r} (`pairplay protocol consent {command_word(data.given)} ID`)"))
        return 0
    if args.action == "status":
        if not data.state.participants:  # an empty plan is not a complete one
            print(f"nobody is registered: `pairplay protocol register {command_word(data.given)}` first")
        notes, key_problem = data.id_notes()  # ids some record shows, the journal does not register (a crash
        if key_problem:  # between the key line and the journal line, a hand edit); an unreachable key file is said
            print(escaped(key_problem))
        for pid, note in notes.items():
            print(escaped(f"{pid}: {note}"))
        if data.state.consent_form is not None:  # an amendment: the form is not the study file's
            print(escaped(f"consent form: {data.consent_form!r} (`protocol consent-form`; the study file's: "
                          f"{data.study.study.consent_form!r})"))
        for pid in data.state.participants:  # a person's game is refused until it is recorded
            if problem := data.consent_problem(pid):
                print(escaped(f"{pid}: {problem}: plays only as a persona until `pairplay protocol consent "
                              f"{command_word(data.given)} {command_word(pid)}`"))
        for problem in data.fold_problems():  # a hand edit the tables cannot fold: every writing verb refuses it
            print(escaped(f"{data.given / JOURNAL}: does not fold into consistent tables: {problem}: every verb that "
                          f"writes the folder refuses it until the line is put back (a backup of {JOURNAL})"))
        # a game started and never ended (a second signal, a crash): what its recording holds and what the next
        # serve, pilot or report does with it, on its step's line (it showed "[open]", no word of it)
        unended: dict[tuple, list[str]] = {}
        for g in data.state.games.values():
            if note := data.unended_note(g):
                unended.setdefault((g.participant, g.phase, g.game), []).append(note)
        for step in data.plan():
            mark = "done" if step.done else ("blocked" if step.blocked else "waits" if step.waits else "open")
            notes = [step.blocked] if step.blocked and not step.done else []
            notes += [f"waits for consent: {step.waits}; a persona may play it (pilot)"] if step.waits and not \
                step.blocked else []
            notes += [step.note] if step.note else []  # a bias policy made with a game marked invalid since
            notes += unended.get((step.participant, step.phase, step.game), []) if step.kind == "play" else []
            print(escaped(f"[{mark:7}] {step.label}" + "".join(f"  ({n})" for n in notes)))
        return 0
    if args.action == "mark-invalid":  # a game left without its end is journaled first: its mark is of its end
        built_missing_policies(data, "protocol mark-invalid")
        marked = data.mark_invalid(args.session, args.reason)
        print(escaped(data.marked_line(marked)))  # (and what it did to a bias policy combined from the game)
        return 0
    if args.action in ("pilot", "serve"):
        # a completed game a signal left without its policy gets it now, from its recording
        built_missing_policies(data, f"protocol {args.action}")
        return _pilot(data, args) if args.action == "pilot" else _serve(data, args)
    raise AssertionError(args.action)


def built_missing_policies(data: StudyData, verb: str) -> None:
    """StudyData.build_missing_policies, each game it built or could not build said on stderr (a note,
    not a result: the verb goes on)."""
    for line in data.build_missing_policies():
        print(f"pairplay {verb}: {escaped(line)}", file=sys.stderr, flush=True)


def _items(text: str, option: str) -> list[str]:
    """The items of a comma-separated option (pairplay/lists.py: an empty one is refused, not skipped)."""
    try:
        return comma_items(text)
    except ValueError as exc:
        raise StudyDataError(f"{option} {exc}") from None


def _persona(key: str, option: str) -> str:
    """The key of the persona `key` names; StudyDataError naming `option` if none (it said only "unknown persona
    'ashly' ...", not which option held it: every refusal of an option's value names the option)."""
    try:
        return persona(key).key
    except KeyError as err:
        raise StudyDataError(err.args[0], option) from None


def _robot(args):
    """(RobotChoice or None, overridden?) from --robot; StudyDataError if it is wrong."""
    from pairplay.services.robot.choice import NO_ROBOT, RobotChoice, check_choice
    if not args.robot:
        return None, False
    if args.robot == NO_ROBOT:
        return None, True
    choice = RobotChoice(args.robot)
    try:
        check_choice(choice)
    except ValueError as err:
        raise StudyDataError(str(err)) from None
    return choice, True


def warn_unreachable(runner, verb: str) -> None:
    """A WARNING line if the study's robot does not accept a connection now. Not a refusal: the console
    and the plan go on (the robot may be switched on before the first game; each game's line says how
    many suggestions reached it)."""
    from pairplay.services.robot.choice import robot_unreachable
    if runner.robot is None:
        return
    why = robot_unreachable(runner.robot.url)
    if why:
        runner.robot_warning = (f"the robot did not accept a connection when `protocol {verb}` started: {why} "
                                f"({runner.robot.url.split('?')[0]}); its games record what it cannot deliver as failed")
        print(f"pairplay protocol {verb}: warning: the robot does not accept a connection now: {why} "
              f"(--robot {runner.robot.url.split('?')[0]}); its games record what it cannot deliver as failed",
              file=sys.stderr, flush=True)


def _serve(data: StudyData, args) -> int:
    import threading

    from pairplay.cli.lab import parse_listen
    try:  # the lab's parser, its range check with it: 99999 was taken as port 34463 (trial36 P1)
        host, port = parse_listen(args.listen)
    except ValueError as err:
        raise StudyDataError(str(err)) from None
    robot, overridden = _robot(args)
    if bool(args.certfile) != bool(args.keyfile):
        raise StudyDataError("--certfile and --keyfile go together")
    for option, f in (("--certfile", args.certfile), ("--keyfile", args.keyfile)):
        if f:  # before the bus and the console start: uvicorn opens them only then (a pipe blocked it)
            check_option_file(f, option)
    pilot = {}
    for pair in _items(args.pilot, "--pilot") if args.pilot is not None else []:
        pid, equals, key = pair.partition("=")
        if not equals:  # `--pilot p01` was "unknown persona ''"
            raise StudyDataError(f"{pair!r} is not ID=PERSONA (p01=tatiana)", "--pilot")
        try:
            data.participant(pid)
        except StudyDataError as err:
            raise StudyDataError(err.what, "--pilot") from None
        if pid in pilot:  # one silently won: say it
            raise StudyDataError(f"{pid} named twice", "--pilot")
        pilot[pid] = _persona(key, "--pilot")
    stop = threading.Event()
    runners = []
    # a signal stops the running game at once, with its name and the shutdown's deadline (its recording finished)
    stop_runners_on_signals(stop, runners)
    try:
        _serving(data, args, stop, runners, pilot, robot, overridden, host, port)
    except KeyboardInterrupt:  # a second signal cut the shutdown: the game's recording as the disk holds it
        return cut(runners, "serve", stop)
    print(f"pairplay protocol serve: stopped ({signals.said(getattr(stop, 'why', '')) or 'done'})"
          f"{stopped_line(runners, stop)}", file=sys.stderr)  # not a result
    return 0


def _serving(data: StudyData, args, stop, runners: list, pilot: dict, robot, overridden: bool, host: str,
             port: int) -> None:
    """`_serve` once its options are checked: the console served until `stop` (a signal)."""
    from pairplay.services.bus import Bus, BusOptions, shutdown_wait
    from pairplay.services.console.server import StudyLabServer
    from pairplay.services.lab.reach import plain_beyond_loopback
    from pairplay.services.protocol import JOURNALED_WAIT_S, StudyRunner

    with Bus(BusOptions(mode="router"), stop=stop) as bus:
        runner = StudyRunner(data, bus, robot=robot)
        runners.append(runner)
        runner.scripted = pilot
        if overridden and robot is None:
            runner.robot = None
        try:
            server = StudyLabServer(runner, host=host, port=port, ssl_certfile=args.certfile,
                                    ssl_keyfile=args.keyfile).start()
        except OSError as err:
            raise StudyDataError(f"cannot serve the console: {err.strerror or err}", f"--listen {args.listen}") from None
        warning = plain_beyond_loopback(host.strip("[]"), tls=bool(args.certfile))  # as `pairplay lab`'s: the
        if warning:  # console's token, which exports and deletes participants' data, is sent in clear text
            print(f"pairplay protocol serve: {warning}", file=sys.stderr, flush=True)
        warn_unreachable(runner, "serve")
        print(f"experimenter console: {server.console_url}", flush=True)
        print(f"bus (boards and scripted players connect here): {bus.listening()}", flush=True)
        cut = True  # a second Ctrl-C (KeyboardInterrupt) cuts the shutdown short: nothing more is waited for
        try:
            while not stop.wait(0.2):
                pass
            cut = False
        finally:
            runner.interrupt(stop)  # a game still running stops now (stop.why, stop.deadline)
            if not cut:  # its end is this process's own last fact: journaled, however loaded the machine, before
                # the bounded waits on the rest of the step (before, the join below took what the deadline left,
                # nothing at load 15+, and the process exited without the game's GameEnded)
                # (bounded, and a second signal of either kind cuts it: a journal write that never came held it)
                testpause.pause("serve-stopping")  # (a test's second signal lands here: the first is handled)
                if not runner.wait_journaled():
                    print(f"pairplay protocol serve: gave up after {JOURNALED_WAIT_S:.0f} s waiting for the journal "
                          f"to record the end of game {runner.live.session}; `pairplay protocol status "
                          f"{command_word(data.given)}` "
                          "shows the study, and the next serve journals the game from its recording", file=sys.stderr)
            if server.console.thread is not None:
                server.console.thread.join(shutdown_wait(stop, 10.0, reserve=0.3))
            server.close(shutdown_wait(stop, 10.0, reserve=0.2))


def stop_runners_on_signals(stop, runners: list) -> None:
    """SIGINT/SIGTERM stop the verb (services/bus.py stop_on_signals) and each of `runners`' running game: the game
    running as the signal came, and that no step follows, noted in the handler itself (StudyRunner.signal_came:
    what `cut` and `stopped_line` read, whichever thread gets there first), the games' stop flags set by the
    handler's thread (StudyRunner.interrupt)."""
    from pairplay.services.bus import stop_on_signals

    stop_on_signals(stop, then=lambda: [r.interrupt(stop) for r in runners],
                    now=lambda: [r.signal_came(stop) for r in runners])


def stopped_line(runners: list, stop) -> str:
    """"; game S ..." of the game a signal stopped (services/protocol.py StudyRunner.stopped), as `session` says its
    own (cli/session.py print_interrupted): how far it got, how the journal ended it, its recording; "" if none
    was running. serve said only "stopped (Ctrl-C)" and pilot "interrupted (Ctrl-C)" of a game they cut (a new
    user's trial)."""
    from pairplay.services.bus import signal_taken

    game = runners[0].stopped if runners and signal_taken(stop) else None
    if game is None:
        return ""
    summary, ended = game.summary, runners[0].data.state.games.get(game.session)
    ended = ended.ended if ended is not None else None
    if summary.get("ended") == "completed":  # the signal came after its last round (its questionnaire, its end)
        how = f"had completed all {counted(game.rounds, 'round')}"
    elif not summary.get("started") and "events" in summary:
        how = "stopped before it started"
    else:
        how = f"stopped after {summary.get('rounds_played', 0)} of {counted(game.rounds, 'round')}"
    recorded = f"recorded {counted(summary['events'], 'event')} to {game.path}" if "events" in summary else \
        f"its recording {game.path}"
    journal = f"journaled {ended.outcome}" + (f" ({ended.reason})" if ended.reason else "") if ended is not None \
        else "its end not journaled (the next serve, pilot or report journals it from its recording)"
    return escaped(f"; game {game.session} {how}, {journal}; {recorded}")


def cut(runners: list, verb: str, stop) -> int:
    """What serve or pilot says when a second signal cut its shutdown (KeyboardInterrupt): the line of
    cli/session.py `cut_line` of the game the first signal stopped (its recording: whole, or `pairplay recover` it),
    the signal's status; of one stopped before its recording began, that, and what the journal holds of it and what
    the next serve does with it (replay/studydata.py `build_missing_policies`: journaled aborted, played again).
    With no game running, the KeyboardInterrupt goes on to cli/main.py's line. Which game, decided from what the
    first signal's handler set (services/bus.py `signal_taken`, StudyRunner.signal_came), not from `stop.is_set()`:
    the thread that sets it may not have run yet (the generic line came instead, once at load 5.4)."""
    from pairplay.cli.session import cut_line
    from pairplay.replay.wal import wal_path
    from pairplay.services.bus import signal_taken

    game = runners[0].stopped if runners and signal_taken(stop) else None
    if game is None:
        raise KeyboardInterrupt
    again = signals.again or signal.SIGINT  # (either signal cuts it: pairplay/signals.py `wait_cut`)
    signals.held_elsewhere_over()  # a recorder the game's thread is starting or finishing: its held step ends first
    started = runners[0].data.state.games.get(game.session)
    if game.path.exists() or wal_path(game.path).exists():
        # a game whose end the journal does not hold yet: what becomes of it (it was left "running", unsaid)
        owed = (f"; game {game.session}: the journal holds its start and no end: the next serve, pilot or report "
                "journals it from its recording (`pairplay protocol status "
                f"{command_word(runners[0].data.given)}` says how)") if started is not None and started.ended is None else ""
        print(cut_line(f"protocol {verb}", game.path, again) + escaped(owed), file=sys.stderr)
        return 128 + again
    # stopped before its recording began: main's "nothing more was written" hid a started game with no end
    ended = started.ended if started is not None else None
    what = (f"journaled {ended.outcome}" + (f" ({ended.reason})" if ended.reason else "") + f"; no recording of it "
            f"was written ({game.path})" if ended is not None else
            "the journal holds its start and no end, and no recording of it was written "
            f"({game.path}); the next serve, pilot or report journals it aborted, and its step is played again")
    print(escaped(f"pairplay protocol {verb}: interrupted again ({signals.said(again)}) while stopping; game "
                  f"{game.session} was stopped before its recording began: {what}"), file=sys.stderr)
    return 128 + again


def _pilot(data: StudyData, args) -> int:
    import threading

    from pairplay.services.bus import Bus, BusOptions, signal_taken
    from pairplay.services.protocol import StudyRunner, scripted_players
    from pairplay.services.robot.choice import NO_ROBOT, RobotChoice, check_choice

    # every name is read before they are counted: a misspelt one (`ashly`) is said with the one it resembles,
    # not as a count that is wrong (it was: the count was checked first, and a name past the count never)
    keys = [_persona(k, "--personas") for k in _items(args.personas, "--personas")]
    ids = list(data.state.participants)
    if len(keys) != len(ids):
        raise StudyDataError(f"--personas names {counted(len(keys), 'persona')} for {counted(len(ids), 'registered participant')} "
                             f"({', '.join(ids) or 'none'})")
    personas = dict(zip(ids, keys))
    robot = None
    if args.robot:
        robot = RobotChoice(args.robot) if args.robot != NO_ROBOT else None
        if robot is not None:
            try:
                check_choice(robot)
            except ValueError as err:
                raise StudyDataError(str(err)) from None
    t0 = time.perf_counter()
    stop, runners = threading.Event(), []
    # a signal stops the running game at once, with its name and the shutdown's deadline; no step after it
    stop_runners_on_signals(stop, runners)
    with Bus(BusOptions(), stop=stop) as bus:
        runner = StudyRunner(data, bus, robot=robot)
        runners.append(runner)
        if args.robot == NO_ROBOT:
            runner.robot = None
        runner.warns_undelivered = False  # each game's step line below says what its robot delivered
        warn_unreachable(runner, "pilot")

        def said(step, result) -> None:
            what = f"{counted(len(result.users), 'user')} {biases.combined_words(data.state, result)}" \
                if step.kind == "combine" else f"{result.ended.outcome}, {counted(result.ended.rounds_played, 'round')}"
            if getattr(result, "partial", ""):  # a combination of a partial policy, as `pairplay profile` says it
                what += f"; PARTIAL profile: {result.partial}"
            robot = runner.delivery.get(getattr(result, "session", ""), "")
            what += f"; {robot}" if robot else ""
            played = dataclasses.replace(step, scripted=getattr(result, "scripted", ""))  # "p01 (scripted: blind)"
            print(escaped(f"{time.perf_counter() - t0:7.1f} s  {played.label}: {what}"), flush=True)
        try:
            runner.run_plan(scripted_players(runner, personas), on_step=said)
        except StudyDataError:
            if not signal_taken(stop):
                raise
        except KeyboardInterrupt:  # a second signal cut the shutdown: the game's recording as the disk holds it
            return cut(runners, "pilot", stop)
    if signal_taken(stop):  # (run_plan ends on the handler's flag: `stop` may not be set yet)
        print(escaped(f"pairplay protocol pilot: interrupted ({signals.said(stop.why)}){stopped_line(runners, stop)}; ")
              + f"`pairplay protocol status {command_word(data.given)}` shows what is left", file=sys.stderr)
        return 0
    print(f"plan complete; `pairplay report {command_word(data.given)}` writes the report")  # typed, the folder
    return 0
