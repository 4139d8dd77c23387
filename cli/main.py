"""`pairplay <verb>`: one command line whose verbs match what a researcher does.

Rule: a user's mistake is ONE line on stderr, `pairplay <verb>: <what>
(<where>)`, and exit 2: no verb (`pairplay: no verb given: one of study, ...
(see pairplay --help)`; it printed the whole help on stdout with exit 2), no
action of a verb that has them (`pairplay protocol: no action given: one of
check, init, ...`, `pairplay run`'s service alike), argparse's own refusals (Parser.error), any
`pairplay.errors.UserError` a verb raises, and an OSError (a file or port the
system refused), whenever it comes (before the work or during it: a full disk
part way). A session whose recording could not be written (`RecordingFailed`,
whichever verb ran it) is one line and exit 1, a session that failed (README's
exit table), and so is work lost with a worker process or a Dask cluster (`WorkerLost`:
killed by the out-of-memory killer, a scheduler that stopped answering), the line ending with what
was kept. Anything else is a bug of ours and keeps its traceback.

A signal, at any moment (while the verb loads, waits, works or shuts down),
ends the verb with 128 + its number: 130 for SIGINT (Ctrl-C), 143 for
SIGTERM (`exit_code_of`), after it finished what it can (a recording closed,
temporary outputs removed), with one line saying what it left. Verbs that
stop on signals themselves (services/bus.py `stop_on_signals`: session, lab,
router, replay, view, run, robot, protocol serve/pilot) print their own
summary line and return; the status is still the signal's. Before, the same
Ctrl-C gave 0 or 130 by the moment it came, and SIGTERM 0 or death by the
signal, by the verb. Every option's help shows its default
(HelpFormatter, applied to every verb here).

Logging, the same for every verb: warnings and errors only by default, `-v/--verbose`
adds the INFO lines (what the services do), `-q/--quiet` leaves nothing but
errors (and no progress bars). A verb whose results are files it writes
(`QUIET_SUMMARIES`: study, sweep, rebuild, protocol init and check, ...; session and lab
after their listening line) says on stdout what it wrote, and `-q` silences
that too (`view` its "saved" line, keeping where to watch it; `bench` its "measuring" and load lines, `run`
its "running in session" line: progress and chatter) (rebuild's per-file lines, the study's tables and timings and
`protocol init`'s protocol were printed under -q: new users' trials); a
session that did not complete still says how it ended; a verb whose result is what
it prints (`profile`, `replay --verify`'s verdict, `protocol status`, `bench`)
prints it either way, and the listening line of a bus verb (its endpoint) too. A warning about a
verb's result (an input not whole: damaged, cut, events that do not decode, a damage that lost none;
a partial output; turns a fit left out) is one line on stderr, `pairplay <verb>: <what>` (`warn`), -q
or not: a damaged input is never hidden (replay and counterfactual said theirs on stdout, and
counterfactual's, rebuild's and view's went with their summary under -q: a new user's trial). The
options stand after the verb or after its action (`pairplay protocol check
FILE -v`); `configure_logging` sets them for the run.

Each verb lives in its own module with `add_arguments(parser)` and
`run(args) -> int`; it is imported only when used, so `pairplay --help` and a
verb's start-up stay fast. To add a verb, add one line to VERBS.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import logging
import os
import re
import signal
import sys
import threading

from pairplay import __version__, environment, signals, testpause, threadstart
from pairplay.cli import interrupts
from pairplay.cli.interrupts import DeferredInterrupt
from pairplay.cli.args import check_study_folders
from pairplay.errors import UserError, WorkerLost, command_word, escaped, out_of_threads
from pairplay.nearest import nearest

# verb -> (module, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "study": ("pairplay.cli.study", "run the simulated study of thesis chapter 6"),
    "sweep": ("pairplay.cli.sweep", "run the simulated study over a grid of settings x seeds, locally or on Dask"),
    "bench": ("pairplay.cli.bench", "measure speed beside raw references, print a table"),
    "profile": ("pairplay.cli.profile", "user information (algorithm 3) of policy files, per participant"),
    "combine": ("pairplay.cli.combine", "merge policy files into one policy (algorithm 4)"),
    "view": ("pairplay.cli.view", "watch a session live or a recording in rerun: board, suggestion, Q-table"),
    "run": ("pairplay.cli.run", "run one service (game, learner, participant, recorder, combiner) on the bus"),
    "router": ("pairplay.cli.router", "a Zenoh router alone (the server host's hub); services connect as clients"),
    "session": ("pairplay.cli.session", "run a whole session over the bus, recorded to recordings/<session>.mcap"),
    "lab": ("pairplay.cli.lab", "a live session for a person: the touch-screen board, the robot, recorded"),
    "rebuild": ("pairplay.cli.rebuild", "fold recordings into policy files and learning curves"),
    "replay": ("pairplay.cli.replay", "re-publish a recording on the bus, or --verify it against fresh services"),
    "recover": ("pairplay.cli.recover", "complete a recording cut short by a crash"),
    "counterfactual": ("pairplay.cli.counterfactual",
                       "fit a simulated user to a recorded participant, then play other learners or policies against it"),
    "protocol": ("pairplay.cli.protocol", "a study with people (thesis ch. 7): check its TOML, make its folder, register, plan, pilot"),
    "participant": ("pairplay.cli.participant", "export or delete one participant's data (recordings, policies, answers)"),
    "report": ("pairplay.cli.report", "the human-world report (thesis 7.3) of a study folder"),
    "robot": ("pairplay.cli.robot", "perform a session's suggestions on a robot (virtual, IrisTK, Furhat), or --try one"),
}

# A word a user types as a verb that is another verb's action or option (verify x.mcap is `pairplay replay
# --verify`; init is `pairplay protocol init`): not a verb, it is answered with the command it
# stands for, before any verb it resembles (`record` resembles `recover`, but records nothing). Only words that
# mean one command: `check` (protocol check, replay --verify), `repair` (protocol repair, recover) and `play`
# (replay, lab) mean several, and the verb they resemble, if any, is said (pairplay/nearest.py).
# tests/test_cli_usage.py checks every command here parses.
VERB_ALIASES: dict[str, str] = {
    "verify": "pairplay replay --verify",
    "record": "pairplay session",
    "train": "pairplay study --train-only",
    "simulate": "pairplay study",
    "merge": "pairplay combine",
    "watch": "pairplay view",
    "try": "pairplay robot --try",
    "init": "pairplay protocol init",
    "register": "pairplay protocol register",
    "status": "pairplay protocol status",
    "pilot": "pairplay protocol pilot",
    "serve": "pairplay protocol serve",
    "export": "pairplay participant export",
    "delete": "pairplay participant delete",
    "help": "pairplay --help",
    "version": "pairplay --version",
}


class HelpFormatter(argparse.HelpFormatter):
    """Every option's help ends with its default, unless the help already states it
    (or there is none to state: no value, a flag that is off)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (not action.option_strings or default is None or default is False or default is argparse.SUPPRESS
                or default == []
                or "default" in text.lower() or "%(default)" in text):
            return text
        return text + " (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """argparse, with a usage mistake on ONE line: `pairplay <verb>: <what>`, exit 2.

    An unrecognized argument is reported by the innermost parser that met it (`pairplay protocol
    check: unknown option --bogus`), not by the top one, which is where argparse says it, in pairplay's
    words: each unknown option with the option of that parser it resembles (`unknown option --forse (did
    you mean --force?)`: argparse said "unrecognized arguments: --forse"), and before what is missing, which
    it may be misspelt (`protocol init st --studdy s.toml` said "required: --study").

    No abbreviations: argparse takes any unambiguous beginning of an option for it, so `--for` or `--fo` was
    `--force` and replaced outputs without a word (a new user's trial), and a typo that begins an option
    ran as that option; an option is given whole (`--for` is refused, naming --force)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)  # every parser of the command line: the verbs' and actions' too
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)  # what this parser was handed (`error`)
        namespace, extra = super().parse_known_args(args, namespace)
        if extra and not hasattr(namespace, "_usage_parser"):  # the innermost parser returns first
            namespace._usage_parser = self
        return namespace, extra

    def error(self, message: str):
        what = (self.choice_missing(message) or self.unknown_before_missing(message) or self.dash_value(message)
                or self.choice_near(message))
        self.exit(2, f"{self.prog}: {what} (see {self.prog} --help)\n")

    def choice_near(self, message: str) -> str:
        """argparse's `invalid choice: 'human-phse1' (choose from ...)` with the choice it resembles
        (pairplay/nearest.py, as every refusal of a name: `--preset human-phse1`, `--algorithm q-lerning` had
        no hint), a word that is not a verb with the command it stands for (VERB_ALIASES: the word
        verify had no hint: it is replay --verify), else `message` as it is."""
        m = re.fullmatch(r"(argument (\S+): invalid choice: '(.*)') \(choose from (.*)\)", message, re.S)
        if not m:
            return message
        what, word, choices = m.group(1), m.group(3), m.group(4)
        alias = VERB_ALIASES.get(word) if m.group(2) == "VERB" and self.prog == "pairplay" else None
        near = alias or nearest(word, re.findall(r"'([^']*)'", choices) or choices.split(", "))
        return f"{what} (did you mean '{near}'?) (choose from {choices})" if near else message

    def unrecognized(self, extra: list[str]) -> str:
        """The line of the arguments this parser did not take (`extra`, as argparse leaves them): each unknown
        option with the option it resembles (pairplay/nearest.py), then any stray word (`_option_for`: a
        recording given without its option). A word right after an unknown option is taken for its value and
        not said again (`--bogus 1`: the option is the mistake)."""
        options, words = [], []
        values = extra.index("--") if "--" in extra else len(extra)  # after `--`, words only
        for i, word in enumerate(extra):
            if i < values and self.unknown_option(word):
                options.append(word)
            elif i != values and not (0 < i <= values and self.unknown_option(extra[i - 1])):
                words.append(word)
        parts = []
        if options:
            said = []
            for option in options:
                name, known = option.split("=", 1)[0], [o for o in self._option_string_actions if o.startswith("--")]
                begun = [o for o in known if o.startswith(name)] if name.startswith("--") and len(name) > 2 else []
                near = begun[0] if len(begun) == 1 else nearest(name, known)  # (no abbreviations: said whole)
                said.append(f"{option} (did you mean {near}?)" if near else option)
            parts.append(f"unknown option{'s' * (len(options) > 1)} {', '.join(said)}")
        if words:
            parts.append(f"unexpected argument{'s' * (len(words) > 1)} {' '.join(words)}{_option_for(self, words)}")
        return "; ".join(parts)

    def unknown_option(self, word: str) -> bool:
        """Whether `word` is an option (it starts with '-', and is no negative number) this parser does not take,
        as argparse reads one: `--name=VALUE`, an unambiguous beginning of a long option, `-vq`."""
        if len(word) < 2 or not word.startswith("-") or re.fullmatch(r"-\d+|-\d*\.\d+", word):
            return False
        name = word.split("=", 1)[0]
        if name in self._option_string_actions or word == "--":
            return False
        if name.startswith("--"):
            return not (self.allow_abbrev and any(o.startswith(name) for o in self._option_string_actions))
        return word[:2] not in self._option_string_actions

    def unknown_before_missing(self, message: str) -> str:
        """argparse's `the following arguments are required: ...` said as the unknown options given, when some
        were (`unrecognized`): the missing one may be one of them misspelt (`--studdy s.toml` for --study),
        and they are refused either way; else ""."""
        if not message.startswith("the following arguments are required: "):
            return ""
        given = getattr(self, "_given", [])
        if "--" in given:  # what follows `--` is a value, never an option
            given = given[:given.index("--")]
        return self.unrecognized([w for w in given if self.unknown_option(w)])

    @staticmethod
    def dash_value(message: str) -> str:
        """argparse's `expected one argument` says how to give a value that starts with '-': argparse takes
        `--name -2+3` for two options (`--name=-2+3` is the one way), and said only that one was missing."""
        m = re.fullmatch(r"argument (\S+): expected one argument", message)
        if not m:
            return ""
        option = m.group(1).split("/")[-1]
        return f"{message}: give it after {option}, or as {option}=VALUE when the value starts with '-'"

    def choice_missing(self, message: str) -> str:
        """`no ACTION given: one of check, init, ...` when what is missing is a choice of words (a verb's
        action, `run`'s service), else "": the choices said on the line, not only its name."""
        prefix = "the following arguments are required: "
        if not message.startswith(prefix):
            return ""
        first = message[len(prefix):].split(", ")[0]
        for action in self._actions:
            if not action.option_strings and action.choices and first in (action.metavar, action.dest):
                return f"no {first.lower()} given: one of {', '.join(action.choices)}"
        return ""


def build_parser(argv: list[str]) -> tuple[argparse.ArgumentParser, argparse.ArgumentParser | None]:
    parser = Parser(prog="pairplay", description=__doc__.splitlines()[0], formatter_class=HelpFormatter)
    parser.add_argument("--version", action="version", version=f"pairplay {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    chosen = None
    for verb, (module, help_text) in VERBS.items():
        p = sub.add_parser(verb, help=help_text, description=help_text, formatter_class=HelpFormatter)
        if verb in argv[:1]:
            add_log_options(p)
            importlib.import_module(module).add_arguments(p)
            for action in p._actions:  # a verb's actions (protocol check, participant export) take them too
                if isinstance(action, argparse._SubParsersAction):
                    for nested in action.choices.values():
                        add_log_options(nested, argparse.SUPPRESS)
            chosen = p
    return parser, chosen


def add_log_options(p: argparse.ArgumentParser, default=False) -> None:
    """-v/--verbose and -q/--quiet (module rule); `default` SUPPRESS on a verb's action, so an
    option given before the action is not reset by it."""
    g = p.add_argument_group("output").add_mutually_exclusive_group()
    g.add_argument("-v", "--verbose", action="store_true", default=default,
                   help="also log what the services do (INFO)")
    g.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="log nothing but errors; no progress bars")


# verbs (or a verb's actions) whose stdout only says what they wrote to files: silenced by -q (module
# rule). `protocol` is both: init, mark-invalid and pilot write, status and register print results
# (init -q printed the whole protocol: a new user's trial); check's result is its status (a mistake: one line
# on stderr), its listing of the protocol a summary (`check -q` printed it: a trial). `session` and `lab` say their listening line
# first, so they leave out their summary themselves (cli/session.py, cli/lab.py), as `view` does (where to watch
# it, --serve or --spawn, is a result); `bench` and `run` leave out their progress and chatter.
QUIET_SUMMARIES = frozenset({"study", "sweep", "rebuild", "recover", "combine", "counterfactual", "report",
                             "participant", "protocol init", "protocol mark-invalid", "protocol pilot",
                             "protocol check"})
# the verbs whose second word is an action (their add_subparsers, dest "action": `_named`, `_who`)
VERBS_WITH_ACTIONS = frozenset({"protocol", "participant"})
LOG_FORMAT = "%(levelname)s %(name)s: %(message)s"
_handler: logging.Handler | None = None


def configure_logging(verbose: bool, quiet: bool) -> int:
    """Send log records of the chosen level and above to stderr (module rule); return the level.
    One handler of ours on the root logger, replaced on each call (tests call `main` many times)."""
    global _handler
    level = logging.INFO if verbose else logging.ERROR if quiet else logging.WARNING
    root = logging.getLogger()
    if _handler is not None:
        root.removeHandler(_handler)
    _handler = logging.StreamHandler(sys.stderr)
    _handler.setLevel(level)
    _handler.setFormatter(logging.Formatter(LOG_FORMAT))
    root.addHandler(_handler)
    if root.getEffectiveLevel() > level:
        root.setLevel(level)
    return level


def main(argv: list[str] | None = None, exiting: bool = False) -> int:
    """Run one verb (module rule); its exit status. `exiting`: the process ends with this status
    (entry): a signal from here on stops nothing and is recorded (cli/interrupts.py `late`), for `entry` to
    say up to its last step (`_end`); not left to the interpreter's teardown (where Python's default handler
    killed the process: 130 with no line)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    in_main = threading.current_thread() is threading.main_thread()
    saved = {s: signal.getsignal(s) for s in signals.SIGNALS} if in_main else {}
    try:
        code = _main(argv, _arm if exiting and in_main else None)
        if exiting and in_main:  # one noted while the command loaded, when it returned before it armed (a mistake)
            interrupts.late = interrupts.late or signals.take()
    except KeyboardInterrupt:  # a signal before the verb ran (while its modules load)
        if in_main:
            interrupts.work_done()  # stopped: a signal from now on raises nothing more (as in _main)
        verb = _named(argv)
        print(f"pairplay{' ' + verb if verb else ''}: {interrupted_what()}; nothing more was written", file=sys.stderr)
        code = exit_code_of(signal_received() or signal.SIGINT)
    try:
        if in_main and (exiting or code not in INTERRUPTED):
            interrupts.work_done()  # the work is over (done, refused or interrupted): a signal now stops nothing
        if in_main and code not in INTERRUPTED:
            code = said_late(argv, code)
        return code
    finally:
        interrupts.received = 0  # said in this call's status; a later main() starts afresh
        if not exiting:
            interrupts.late = 0
        outputs = sys.modules.get("pairplay.outputs")
        if outputs is not None:
            outputs.written.clear()  # (`nothing_more`: this call's outputs)
        signals.stopping = signals.again = 0
        if not exiting:
            for s, handler in saved.items():
                signal.signal(s, handler)


def said_late(argv: list[str], code: int) -> int:
    """`code`, or the status of a signal that came once the work was done (cli/interrupts.py `late`, taken),
    with its one line saying so (module rule)."""
    late, interrupts.late = interrupts.late, 0
    if not late:
        return code
    verb = _named(argv)
    done = "" if code == 0 else f" with status {code}"
    print(f"pairplay{' ' + verb if verb else ''}: {interrupted_what(late)} after it had finished{done}; nothing was "
          "undone", file=sys.stderr)
    return exit_code_of(late)


def warn(verb: str, line: str) -> None:
    """A warning about a verb's result: one line on stderr, `pairplay <verb>: <line>`, -q or not (module rule);
    a path's or a value's control characters escaped (pairplay/errors.py `escaped`)."""
    print(f"pairplay {verb}: {escaped(line)}", file=sys.stderr, flush=True)


def left_journals(verb: str, recordings) -> None:
    """`warn` of each recording read whose recorder's journal beside it holds what it lacks (replay/recover.py
    `journal_left`): every verb that reads a recording says it, whatever else it said of the file."""
    from pairplay.replay.recover import journal_left
    for path in recordings:
        line = journal_left(path)
        if line:
            warn(verb, f"{path}: {line}")


@contextlib.contextmanager
def _summary_silenced(quiet: bool):
    """stdout dropped while a verb of QUIET_SUMMARIES runs under -q (module rule); stderr untouched."""
    if not quiet:
        yield
        return
    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        yield


def nothing_more() -> str:
    """The end of the line of a verb a signal stopped part way: the outputs it had put in place before the signal
    (pairplay/outputs.py `written`, those still there: a verb removes what its journal could not take,
    replay/copies.py), kept whole, then that nothing more was written. It said only "nothing more was written",
    of a `rebuild` whose folder was in place (a signal as it went on to its journal lines or its listing). The
    outputs module is only looked up: a verb that writes none never loads it."""
    outputs = sys.modules.get("pairplay.outputs")
    kept = [p for p in dict.fromkeys(getattr(outputs, "written", ())) if os.path.lexists(p)]
    if not kept:
        return "nothing more was written"
    shown = ", ".join(map(str, kept[:3])) + (f" and {len(kept) - 3} more" if len(kept) > 3 else "")
    return f"{shown} {'was' if len(kept) == 1 else 'were'} written whole before it and kept; nothing more was written"


def signal_received() -> int:
    """The number of the signal that stopped the verb (SIGINT, SIGTERM), 0 if none came: the one
    stop_on_signals saw (services/bus.py `signalled`), else the one cli/interrupts.py raised for."""
    bus = sys.modules.get("pairplay.services.bus")
    name = getattr(bus, "signalled", None)
    if name:
        return int(signal.Signals[name])
    return interrupts.received


def exit_code_of(signum: int) -> int:
    """The exit status of a verb stopped by signal `signum` (module rule): 128 + its number."""
    return 128 + signum


def interrupted_what(signum: int = 0) -> str:
    """`interrupted (Ctrl-C)` or `interrupted (SIGTERM)`: the start of a stopped verb's line
    (`signum`, else the signal that stopped the verb)."""
    signum = signum or signal_received()
    return f"interrupted ({signals.said(signum or signal.SIGINT)})"


QUIET_TRACKER = "ignore::UserWarning:multiprocessing.resource_tracker"
INTERRUPTED = tuple(exit_code_of(s) for s in signals.SIGNALS)  # 130, 143, 129: SIGINT, SIGTERM, SIGHUP


def entry() -> None:
    """The `pairplay` command (and `python -m pairplay`): `main()`, then exit with its code (`_end`)."""
    # The pools' semaphores are unlinked by multiprocessing's resource tracker when we end with os._exit
    # (`_end`): its report of them ("leaked semaphore objects") is that clean-up, not a fault, and would
    # add lines to an interruption's one line. The tracker is a child process: it reads this variable.
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (os.environ.get("PYTHONWARNINGS"), QUIET_TRACKER)))
    threadstart.guard()  # a thread that dies as it starts is refused, not waited for (pairplay/threadstart.py)
    try:
        code = main(exiting=True)
    except SystemExit as done:  # argparse's --help, --version and usage lines (Parser.error): the same end
        if done.code is not None and type(done.code) is not int:
            raise  # a message to print: the interpreter's own exit says it (none of ours)
        code = done.code or 0
        interrupts.work_done()  # (its handler: a signal from here on is said by `_end`, as any verb's)
        interrupts.late = interrupts.late or signals.take()  # one that came as it parsed (cli/start.py noted it)
    _end(code, sys.argv[1:])


def _end(code: int, argv: list[str]) -> None:
    """End the process with `code`, or with the status of a signal that came up to its last step, said.

    What the interpreter's exit does that can be seen is done here, under main()'s handler (a signal is
    recorded, cli/interrupts.py `late`): threads that are not daemons joined, the exit handlers run
    (multiprocessing's clean-up, logging's, rerun's flush), a completed verb's garbage collected (its
    finalizers: an open file flushed), stdout and stderr flushed. Then both signals are ignored, a late one is
    said (`said_late`), and the process ends with os._exit: the status is decided only there, and nothing
    follows it but the exit. The interpreter's teardown of its objects is skipped, always. It took 1.3-3 s
    after `counterfactual` had printed what it wrote (numba's, matplotlib's objects torn down; load 14) with
    SIGINT ignored: a Ctrl-C there exited 0, no line, 7 of 10 times (a new user's trial). It aborted the
    process after an interrupted compile ("double free detected" in CI: native objects half-built; with
    cli/interrupts.py, which keeps Ctrl-C out of numba's compiler), and after a session with a thread of ours
    still running ("FATAL: exception not rethrown", SIGABRT: a Zenoh close left to the exit by a shutdown's
    deadline); it took 6-15 s after `protocol serve` had returned (load 40-60), past the 2 s a signalled
    process has (issue 12). Every output is closed or removed before main() returns (the verbs' context
    managers)."""
    import gc

    cut = code in INTERRUPTED or _threads_left() or _signalled()
    if not cut:  # (a thread of ours left, an interrupted compile's objects: not waited for, not collected)
        threading._shutdown()  # as the interpreter's exit: the threads that are not daemons (a library's) joined
    atexit._run_exitfuncs()  # what was registered to run at exit still runs (multiprocessing's clean-up)
    if not cut:
        gc.collect()
    # after the collection: a semaphore finalized there tells the tracker, which a stopped tracker would start again
    if "multiprocessing.resource_tracker" in sys.modules:  # (never imported: no tracker, and no import here)
        from pairplay.processes import stop_resource_tracker
        stop_resource_tracker()  # ended and reaped before we end: no child of the verb outlives it
    _flush()
    testpause.pause("exiting")
    for s in signals.SIGNALS:  # the status is decided now (signal.signal runs a pending handler first)
        signal.signal(s, signal.SIG_IGN)
    if code not in INTERRUPTED:
        code = said_late(argv, code)
        _flush()
    os._exit(code)


def _flush() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()


def _signalled() -> bool:
    """Whether a verb was stopped by SIGINT/SIGTERM (services/bus.py `stop_on_signals`): its outputs are
    finished, and the interpreter's teardown is skipped, as after an interruption: it took 6-15 s after
    `protocol serve` had returned (Zenoh's and uvicorn's native objects torn down; measured at load 40-60),
    past the 2 s a signalled process has (issue 12)."""
    bus = sys.modules.get("pairplay.services.bus")
    return bool(getattr(bus, "signalled", None))


def _threads_left() -> bool:
    """Whether a thread besides the main one is still running (all of ours are daemons)."""
    main_thread = threading.main_thread()
    return any(t is not main_thread and t.is_alive() for t in threading.enumerate())


def _arm() -> None:
    """The command's own handler in place, once its modules are loaded (cli/start.py noted a signal until
    then: `signals.record`), and KeyboardInterrupt at once for one noted meanwhile. Not before: a
    KeyboardInterrupt raised inside a module's import can land in msgspec building a Decoder's type
    information, which then crashed the process (SIGSEGV: `schemas/jsonfile.py`'s module-level Decoder,
    2-3 in 15 runs of test_start_signals' SIGTERM at 0.07 s of CPU; 19 of 200 in isolation, a Decoder's
    construction interrupted by a KeyboardInterrupt from a timer; msgspec 0.23.0)."""
    DeferredInterrupt().install()
    early = signals.take()  # one that came while the command loaded (cli/start.py's handler noted it)
    if early:
        interrupts.received = early
        raise KeyboardInterrupt


def _main(argv: list[str], arm=None) -> int:
    misplaced = _options_before_the_verb(argv)
    if misplaced:
        print(escaped(f"pairplay: options go after the verb: pairplay {misplaced[0]} {' '.join(misplaced[1:])} ... "
                      f"(see pairplay {misplaced[0]} --help)"),
              file=sys.stderr)
        return 2
    parser, chosen = build_parser(argv)
    args, extra = parser.parse_known_args(argv)
    if extra:  # said by the parser of the verb (or its action) that met them, naming it
        args._usage_parser.error(args._usage_parser.unrecognized(extra))
    if not args.verb:  # a mistake: one line, as any (module rule); `pairplay --help` prints the help on stdout
        print(f"pairplay: no verb given: one of {', '.join(VERBS)} (see pairplay --help)", file=sys.stderr)
        return 2
    configure_logging(args.verbose, args.quiet)
    try:  # before the verb's modules load: they read pairplay's environment variables as they do
        environment.check()
    except UserError as err:
        print(f"pairplay {args.verb}: {err.line()}", file=sys.stderr)
        return 2
    module = importlib.import_module(VERBS[args.verb][0])
    if arm is not None:  # its modules loaded (build_parser imported the verb's): a signal raises from now on
        arm()
    running = code = None
    try:
        if interrupts.received:  # a signal came while loading and something swallowed its KeyboardInterrupt
            raise KeyboardInterrupt
        check_study_folders(args.verb, chosen, args)  # before any work: a people's study folder is protocol's
        running = True
        with _summary_silenced(args.quiet and (args.verb in QUIET_SUMMARIES or _who(args) in QUIET_SUMMARIES)):
            try:
                code = int(module.run(args) or 0)
            finally:  # the study folders' locks its outputs took (replay/copies.py), however it ended, and its
                copies = sys.modules.get("pairplay.replay.copies")  # outputs' own (pairplay/outputs.py `hold`)
                if copies is not None:
                    copies.release_held()
                outputs = sys.modules.get("pairplay.outputs")
                if outputs is not None:
                    outputs.release_held()
        stopped = signal_received()  # at once: a signal the verb's own handler (a bus verb's) met while it ran
        interrupts.work_done()
        if stopped:
            return exit_code_of(stopped)  # stopped by a signal: its status (module rule); the verb said so
        interrupts.late = interrupts.late or signal_received()  # came once it had returned: main() says so
        return code
    except BrokenPipeError:  # the reader went away (`pairplay combine ... | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 0
    except KeyboardInterrupt as err:
        interrupts.work_done()  # stopped: a signal from now on (a second, a copy sent again) raises nothing more
        if code is not None or (running and err.__traceback__.tb_next is None):  # raised here: run had returned
            interrupts.late = interrupts.late or interrupts.received or signal.SIGINT
            return code or 0
        # (what it removed, if the signal came as it waited to journal its outputs: replay/copies.py Interrupted)
        print(f"pairplay {_who(args)}: {interrupted_what()}; {escaped(getattr(err, 'said', '') or nothing_more())}",
              file=sys.stderr)
        return exit_code_of(signal_received() or signal.SIGINT)
    except SystemError as err:  # Ctrl-C inside a compiled kernel: numba reports it as a SystemError around it
        if not isinstance(err.__cause__ or err.__context__, KeyboardInterrupt):
            raise
        interrupts.work_done()  # (as a KeyboardInterrupt's)
        print(f"pairplay {_who(args)}: {interrupted_what()}; {nothing_more()}", file=sys.stderr)
        return exit_code_of(signal_received() or signal.SIGINT)
    except UserError as err:  # a fix naming an option this verb lacks is left out (errors.UserError)
        print(f"pairplay {_who(args)}: {err.line(options_of(chosen, args))}", file=sys.stderr)
        return 2
    except WorkerLost as err:  # a worker process or a cluster lost: one line, what stayed, exit 1 (errors.py)
        print(f"pairplay {_who(args)}: {escaped(str(err))}; {escaped(nothing_more())}", file=sys.stderr)
        return 1
    except OSError as err:  # the file system or network refused: the user's setup, not our bug
        print(f"pairplay {_who(args)}: {escaped(os_error_line(err))}", file=sys.stderr)
        return 2
    except MemoryError:  # the machine's or the process's limit (`ulimit -v`), like a full disk: the user's setup
        # (a trial under `ulimit -v 2000000`: `view` ended in a traceback while rerun's modules loaded)
        print(f"pairplay {_who(args)}: out of memory (the machine's memory or the process's limit, `ulimit -v`, "
              f"ran out); outputs are written whole or not at all: run it again with more memory", file=sys.stderr)
        return 2
    except Exception as err:
        if out_of_threads(err):  # the same kind as MemoryError: a limit of the user's setup (errors.py)
            print(f"pairplay {_who(args)}: out of threads (a new thread could not start: the process's memory "
                  f"limit, `ulimit -v`, or the machine's thread limit ran out): run it again with more memory (a "
                  f"higher `ulimit -v`)", file=sys.stderr)
            return 2
        line = recording_failed_line(err)
        if line is None:
            raise
        print(f"pairplay {_who(args)}: {escaped(line)}", file=sys.stderr)
        return 1  # a session that failed: README's exit table


def recording_failed_line(err: BaseException) -> str | None:
    """The line of a session whose recording could not be written (services/recorder.py
    `RecordingFailed`: a full disk, a file size limit), else None. Every verb that runs a session
    (session, lab, protocol pilot) says it so and exits 1 (README's exit table: a session that
    failed); before, only `session` did, and `lab` or `protocol pilot` on a full disk ended in a
    traceback. The recorder's module is only looked up: a verb that runs no session never loads it."""
    recorder = sys.modules.get("pairplay.services.recorder")
    if recorder is None or not isinstance(err, recorder.RecordingFailed):
        return None
    path = err.path or "the recording"
    return (f"writing {path} failed ({err.reason}); the session stopped; the file is readable up to the "
            f"failure: pairplay recover {command_word(err.path) if err.path else path}")


def options_of(verb: argparse.ArgumentParser | None, args: argparse.Namespace) -> frozenset[str]:
    """The options a user can give the verb that ran (`verb`'s parser), and its action's when it has
    one (`protocol init --key-file`): what a line's hints may name."""
    if verb is None:
        return frozenset()
    found = set()
    for action in verb._actions:
        found.update(action.option_strings)
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, action.dest, None) or "")
            if chosen is not None:
                found.update(o for a in chosen._actions for o in a.option_strings)
    return frozenset(found)


def _option_for(parser: argparse.ArgumentParser, extra: list[str]) -> str:
    """`; a recording is given with --recording X` when a stray word is what one of the parser's options
    takes (a file that exists, an option whose value is such a file: metavar REC for an .mcap), else "".
    A new user's trial typed `pairplay view rec.mcap`, told only "unrecognized arguments"."""
    words = [w for w in extra if not w.startswith("-")]
    if len(words) != 1 or not os.path.isfile(words[0]):
        return ""
    takes = [a for a in parser._actions if a.option_strings and a.metavar == "REC" and a.nargs is None]
    if not words[0].endswith(".mcap") or len(takes) != 1:
        return ""
    return f"; a recording is given with {takes[0].option_strings[0]} {words[0]}"


def _named(argv: list[str]) -> str:
    """The verb of `argv` as its lines name it, with its action where it has one (`protocol serve`: `_who`), ""
    if argv names no verb: for the lines main() says without the parsed arguments (a signal as the verb loaded,
    or once it had finished). They named the verb alone (`pairplay protocol: ...` of `protocol serve`)."""
    if not argv or argv[0] not in VERBS:
        return ""
    action = argv[1] if len(argv) > 1 and not argv[1].startswith("-") else ""
    return f"{argv[0]} {action}" if action and argv[0] in VERBS_WITH_ACTIONS else argv[0]


def _who(args: argparse.Namespace) -> str:
    """The verb, and its action where it has one (`participant export`), as its usage errors say it."""
    action = getattr(args, "action", None)
    return f"{args.verb} {action}" if isinstance(action, str) else args.verb


def _options_before_the_verb(argv: list[str]) -> list[str]:
    """[verb, option, ...] when options (with their values) stand before a verb (`pairplay -v session
    ...`, `pairplay --out x study`), else []. The verb's options are parsed by the verb's parser only
    (build_parser adds them when the verb comes first): before, `pairplay -v session --participant X`
    said every option of the verb was unrecognized, and `pairplay --out x study` "invalid choice: 'x'"."""
    if not argv or not argv[0].startswith("-") or {"-h", "--help", "--version"} & set(argv):
        return []
    verb = next((i for i, arg in enumerate(argv) if arg in VERBS), None)
    if verb is None:
        return []
    return [argv[verb], *argv[:verb]]


def os_error_line(err: OSError) -> str:
    """`<what> (<where>)` of an OSError: its strerror and the file or address it is about."""
    what = err.strerror or str(err) or type(err).__name__
    where = err.filename if err.filename is not None else ""
    if err.filename2 is not None:
        where = f"{where} -> {err.filename2}"
    return f"{what} ({where})" if where else what


if __name__ == "__main__":
    entry()
