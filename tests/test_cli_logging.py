"""The command line's logging rule, for every verb: warnings and errors by default, -v/--verbose adds
INFO, -q/--quiet leaves errors only; a session interrupted by Ctrl-C prints its one summary line and
nothing on stderr. Before: `pairplay session` logged INFO for itself (three INFO/WARNING lines around
an interruption's summary, which took two lines), `run` and `robot` logged INFO, the rest WARNING."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys

import pytest

from pairplay.cli.main import VERBS, build_parser, configure_logging

from test_cli_usage import MINIMAL


def parsed(argv):
    parser, _ = build_parser(argv)
    return parser.parse_args(argv)


@pytest.mark.parametrize("verb", list(VERBS))
def test_every_verb_takes_verbose_and_quiet_after_it_and_after_its_action(verb):
    base = [verb, *MINIMAL[verb]]
    args = parsed(base)
    assert (args.verbose, args.quiet) == (False, False)
    assert parsed(base + ["-v"]).verbose and parsed(base + ["--quiet"]).quiet
    if verb in ("protocol", "participant"):  # before the action too, and not reset by it
        assert parsed([verb, "-v", *MINIMAL[verb]]).verbose
    with pytest.raises(SystemExit):
        parsed(base + ["-v", "-q"])  # one or the other


@pytest.mark.parametrize("verbose, quiet, shown", [(False, False, ["WARNING", "ERROR"]),
                                                   (True, False, ["INFO", "WARNING", "ERROR"]),
                                                   (False, True, ["ERROR"])])
def test_the_levels_each_option_lets_through(capsys, verbose, quiet, shown):
    configure_logging(verbose, quiet)
    try:
        log = logging.getLogger("pairplay.test")
        log.info("i")
        log.warning("w")
        log.error("e")
        lines = capsys.readouterr().err.strip().splitlines()
        assert [line.split()[0] for line in lines] == shown
    finally:
        configure_logging(False, False)


def test_an_interrupted_session_prints_its_one_interrupted_line_on_stderr_and_no_result_on_stdout(tmp_path):
    """Before: the line went to stdout (session and view), where every other verb says it on stderr."""
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:ashley", "--rounds",
                          "1000", "--session", "int1", "--out", str(tmp_path)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        first = p.stdout.readline()
        assert first.startswith("session int1: bus listening on"), first
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 130 and out == "", out  # 128 + SIGINT, whatever the moment (cli/main.py)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    (line,) = lines
    assert line.startswith("pairplay session: interrupted (SIGINT) ") and f"events to {tmp_path / 'int1.mcap'}" in line, line
