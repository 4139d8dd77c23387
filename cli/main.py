"""`pairplay <verb>`: one command line whose verbs match what a researcher does.

Each verb lives in its own module with `add_arguments(parser)` and
`run(args) -> int`; it is imported only when used, so `pairplay --help` and a
verb's start-up stay fast. To add a verb, add one line to VERBS.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# verb -> (module, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "study": ("pairplay.cli.study", "run the simulated study of thesis chapter 6"),
    "bench": ("pairplay.cli.bench", "measure speed beside raw references, print a table"),
    "profile": ("pairplay.cli.profile", "user information (algorithm 3) of policy files, per participant"),
    "combine": ("pairplay.cli.combine", "merge policy files into one policy (algorithm 4)"),
    "view": ("pairplay.cli.view", "watch a session live or a recording in rerun: board, suggestion, Q-table"),
    "run": ("pairplay.cli.run", "run one service (game, learner, participant, recorder, combiner) on the bus"),
    "session": ("pairplay.cli.session", "run a whole session over the bus, recorded to recordings/<session>.mcap"),
    "lab": ("pairplay.cli.lab", "a live session for a person: the touch-screen board, the robot, recorded"),
    "rebuild": ("pairplay.cli.rebuild", "fold recordings into policy files and learning curves"),
    "replay": ("pairplay.cli.replay", "re-publish a recording on the bus, or --verify it against fresh services"),
    "recover": ("pairplay.cli.recover", "complete a recording cut short by a crash"),
    "protocol": ("pairplay.cli.protocol", "a study with people (thesis ch. 7): check its TOML, make its folder, register, plan, pilot"),
    "participant": ("pairplay.cli.participant", "export or delete one participant's data (recordings, policies, answers)"),
    "report": ("pairplay.cli.report", "the human-world report (thesis 7.3) of a study folder"),
    "robot": ("pairplay.cli.robot", "perform a session's suggestions on a robot (virtual, IrisTK, Furhat), or --try one"),
}


def build_parser(argv: list[str]) -> tuple[argparse.ArgumentParser, argparse.ArgumentParser | None]:
    parser = argparse.ArgumentParser(prog="pairplay", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    chosen = None
    for verb, (module, help_text) in VERBS.items():
        p = sub.add_parser(verb, help=help_text, description=help_text)
        if verb in argv[:1]:
            importlib.import_module(module).add_arguments(p)
            chosen = p
    return parser, chosen


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
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


if __name__ == "__main__":
    sys.exit(main())
