"""Checking what a line tells a user to type: every option it names exists on the verb showing it,
every `pairplay ...` command it names parses (tests/test_hints.py, tests/test_cli_mistakes.py)."""

from __future__ import annotations

import argparse
import contextlib
import io
import re

from pairplay.cli.main import VERBS, build_parser, options_of

OPTION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)")
COMMAND = re.compile(r"`(pairplay(?: [^`]*)?)`")


def verb_options(argv: list[str]) -> frozenset[str]:
    """The options of the verb (and action) `argv` starts with, as the command line takes them."""
    parser, chosen = build_parser(argv)
    with contextlib.redirect_stderr(io.StringIO()):
        try:
            args, _ = parser.parse_known_args(argv)
        except SystemExit:
            args = argparse.Namespace(verb=argv[0], action=argv[1] if len(argv) > 1 else None)
    return options_of(chosen, args) | {"--help", "-h"}


def bad_command(command: str) -> str:
    """Why `command` (`pairplay VERB ...`, placeholders for values allowed) would not parse; "" if it does.
    Placeholders in capitals or angle brackets stand for values (FILE, <id>, X.mcap)."""
    words = command.replace("...", " ").split()[1:]
    if not words:
        return ""
    if words[0].startswith("-"):
        return "" if words[0] in ("--help", "-h", "--version") else f"{words[0]} before a verb"
    if words[0].isupper() or words[0].startswith("<"):  # `pairplay VERB --help`: a placeholder verb
        return ""
    if words[0].endswith(":"):  # a message shown, `pairplay router: stopped (SIGTERM)`: its verb must exist
        return "" if words[0][:-1] in VERBS else f"no verb {words[0][:-1]!r}"
    if words[0] not in VERBS:
        return f"no verb {words[0]!r}"
    known = verb_options(words[:2])
    missing = [w.split("=")[0] for w in words if w.startswith("--") and w.split("=")[0] not in known]
    return f"{words[0]} has no {', '.join(missing)}" if missing else ""


def bad_options(argv: list[str], line: str) -> list[str]:
    """The options `line` (shown by the verb `argv` ran) names outside its `pairplay ...` commands that
    the verb lacks, and what is wrong with each command it names."""
    line = re.sub(r"^pairplay [^:]*: ", "", line)  # the line's own `pairplay VERB:` prefix
    line = _without_typed_options(line)
    wrong = [f"`{c}`: {why}" for c in COMMAND.findall(line) if (why := bad_command(c))]
    rest = COMMAND.sub("", line)
    rest = re.sub(r"\(see pairplay [^)]*--help\)", "", rest)  # the usage pointer names its own verb
    bare = re.findall(r"\bpairplay ((?:[a-z][\w-]* ?)+(?:[^\s;,()]+ ?)*)", rest)
    for c in bare:  # a command not in backquotes, up to the end of its clause
        if c.split()[0] in VERBS and (why := bad_command("pairplay " + c)):
            wrong.append(f"pairplay {c}: {why}")
    rest = re.sub(r"\bpairplay (?:[a-z][\w-]* ?)+(?:[^\s;,()]+ ?)*", "", rest)
    known = verb_options(argv)
    wrong += [o for o in OPTION.findall(rest) if o not in known]
    return wrong


def _without_typed_options(line: str) -> str:
    """`line` without the unknown options it echoes (`unknown option --forse (did you mean --force?)`, cli/main.py
    Parser.unrecognized): what the user typed, not what the line tells them to type; the option meant stays."""
    m = re.search(r"unknown options? (.*?)(?=; |\(see |$)", line)
    if not m:
        return line
    return line[:m.start(1)] + re.sub(r"(^|, )-\S+", r"\1", m.group(1)) + line[m.end(1):]
