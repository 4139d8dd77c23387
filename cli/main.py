"""`pairplay <verb>`: one command line whose verbs match what a researcher does.

Rule: a user's mistake is ONE line on stderr, `pairplay <verb>: <what>
(<where>)`, and exit 2: argparse's own refusals (Parser.error), any
`pairplay.errors.UserError` a verb raises, and an OSError (a file or port the
system refused); Ctrl-C is one line and exit 130. Anything else is a bug of
ours and keeps its traceback. Every option's help shows its default
(HelpFormatter, applied to every verb here).

Each verb lives in its own module with `add_arguments(parser)` and
`run(args) -> int`; it is imported only when used, so `pairplay --help` and a
verb's start-up stay fast. To add a verb, add one line to VERBS.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import os
import sys
import threading

from pairplay import __version__
from pairplay.cli.interrupts import DeferredInterrupt
from pairplay.errors import UserError

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
    """argparse, with a usage mistake on ONE line: `pairplay <verb>: <what>`, exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def build_parser(argv: list[str]) -> tuple[argparse.ArgumentParser, argparse.ArgumentParser | None]:
    parser = Parser(prog="pairplay", description=__doc__.splitlines()[0], formatter_class=HelpFormatter)
    parser.add_argument("--version", action="version", version=f"pairplay {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    chosen = None
    for verb, (module, help_text) in VERBS.items():
        p = sub.add_parser(verb, help=help_text, description=help_text, formatter_class=HelpFormatter)
        if verb in argv[:1]:
            importlib.import_module(module).add_arguments(p)
            chosen = p
    return parser, chosen


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before the verb ran (while its modules load)
        verb = argv[0] if argv and argv[0] in VERBS else ""
        print(f"pairplay{' ' + verb if verb else ''}: interrupted (Ctrl-C); nothing more was written", file=sys.stderr)
        return 130


QUIET_TRACKER = "ignore::UserWarning:multiprocessing.resource_tracker"


def entry() -> None:
    """The `pairplay` command (and `python -m pairplay`): `main()`, then exit with its code.

    After an interruption (exit 130) the exit handlers run and the process ends
    with os._exit, skipping only the interpreter's teardown of its objects (a
    second guard besides cli/interrupts.py, which keeps Ctrl-C out of numba's
    compiler: native objects half-built by an interrupted compile aborted the
    process at exit with "double free detected" in CI). Every output is already
    closed or removed by then (the verbs' context managers ran while
    KeyboardInterrupt unwound the stack). The same when a thread of ours is still
    running once the verb returned (a start a signal did not wait for, loading
    compiled kernels; a Zenoh close or publish left to the exit by a shutdown's
    deadline): the teardown would end it inside native code, and the process
    aborted ("FATAL: exception not rethrown", SIGABRT) after its recording was
    finished."""
    DeferredInterrupt().install()
    # The pools' semaphores are unlinked by multiprocessing's resource tracker when we end with os._exit
    # (below): its report of them ("leaked semaphore objects") is that clean-up, not a fault, and would
    # add lines to an interruption's one line. The tracker is a child process: it reads this variable.
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (os.environ.get("PYTHONWARNINGS"), QUIET_TRACKER)))
    code = main()
    if code == 130 or _threads_left():
        atexit._run_exitfuncs()  # what was registered to run at exit still runs (multiprocessing's clean-up)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)
    sys.exit(code)


def _threads_left() -> bool:
    """Whether a thread besides the main one is still running (all of ours are daemons)."""
    main_thread = threading.main_thread()
    return any(t is not main_thread and t.is_alive() for t in threading.enumerate())


def _main(argv: list[str]) -> int:
    parser, _ = build_parser(argv)
    args = parser.parse_args(argv)
    if not args.verb:
        parser.print_help()
        return 2
    module = importlib.import_module(VERBS[args.verb][0])
    try:
        return int(module.run(args) or 0)
    except BrokenPipeError:  # the reader went away (`pairplay combine ... | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 0
    except KeyboardInterrupt:
        print(f"pairplay {args.verb}: interrupted (Ctrl-C); nothing more was written", file=sys.stderr)
        return 130
    except SystemError as err:  # Ctrl-C inside a compiled kernel: numba reports it as a SystemError around it
        if not isinstance(err.__cause__ or err.__context__, KeyboardInterrupt):
            raise
        print(f"pairplay {args.verb}: interrupted (Ctrl-C); nothing more was written", file=sys.stderr)
        return 130
    except UserError as err:
        print(f"pairplay {args.verb}: {err.line()}", file=sys.stderr)
        return 2
    except OSError as err:  # the file system or network refused: the user's setup, not our bug
        print(f"pairplay {args.verb}: {os_error_line(err)}", file=sys.stderr)
        return 2


def os_error_line(err: OSError) -> str:
    """`<what> (<where>)` of an OSError: its strerror and the file or address it is about."""
    what = err.strerror or str(err) or type(err).__name__
    where = err.filename if err.filename is not None else ""
    if err.filename2 is not None:
        where = f"{where} -> {err.filename2}"
    return f"{what} ({where})" if where else what


if __name__ == "__main__":
    entry()
