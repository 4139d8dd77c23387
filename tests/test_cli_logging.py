"""The command line's logging rule, for every verb: warnings and errors by default, -v/--verbose adds
INFO, -q/--quiet leaves errors only; a session interrupted by Ctrl-C prints its one summary line and
nothing on stderr. Before: `pairplay session` logged INFO for itself (three INFO/WARNING lines around
an interruption's summary, which took two lines), `run` and `robot` logged INFO, the rest WARNING."""

from __future__ import annotations

import logging
import os
import re
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
    # (a signal before the game started: "recorded 1 event to ...", its recorder's own; later: "N events")
    assert line.startswith("pairplay session: interrupted (Ctrl-C) ") and re.search(
        rf"\d+ events? to {re.escape(str(tmp_path / 'int1.mcap'))}", line), line


def test_quiet_silences_the_summaries_of_verbs_that_write_files_not_results_that_are_printed(tmp_path, capsys):
    """A new user's trial: `rebuild -q` still printed its per-file lines and `study -q` its tables and
    timings. -q now leaves stdout empty for a verb whose results are files (cli/main.py QUIET_SUMMARIES);
    a verb whose result is what it prints (profile) prints it either way, and errors still come."""
    from pathlib import Path

    from pairplay.cli.main import main

    sample = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
    runs = {"rebuild": ["rebuild", str(sample), "--out", str(tmp_path / "rb"), "--no-plot"],
            "study": ["study", "--out", str(tmp_path / "st"), "--personas", "blind", "--games", "2", "--rounds", "5",
                      "--eval-rounds", "2"]}
    for verb, args in runs.items():
        assert main(args + ["-q"]) == 0, verb
        out, err = capsys.readouterr()
        assert (out, err) == ("", ""), verb
    assert (tmp_path / "rb" / "sim-ashley.policy.json").is_file() and (tmp_path / "st" / "report.md").is_file()
    assert main(["profile", *map(str, sorted((tmp_path / "st" / "policies").rglob("*.json"))), "-q"]) == 0
    assert capsys.readouterr().out.strip()  # profile's result is its table
    assert main(runs["rebuild"] + ["-q"]) == 2  # its outputs exist: the refusal still comes, on stderr
    assert "exists" in capsys.readouterr().err


def test_quiet_silences_what_the_protocol_actions_and_the_session_verbs_say_they_wrote(tmp_path, pairplay_cli):
    """A new user's trial: `protocol init -q` printed the whole protocol (QUIET_SUMMARIES named verbs,
    and `protocol` is a verb whose actions are both: init writes a folder, status prints a result), and
    `session -q` its summary of the recording it wrote. Now an action whose result is files (init,
    mark-invalid, pilot) and the session's summary are silenced by -q; a printed result (register's id,
    status) and the listening line still come. A trial: `protocol check -q` printed the whole protocol; a
    check's result is its status (a mistake is one line on stderr, -q or not)."""
    folder = tmp_path / "study"
    done = pairplay_cli("protocol", "init", folder, "--study", "thesis-ch7", "-q")
    assert (done.returncode, done.stdout, done.stderr) == (0, "", ""), done
    done = pairplay_cli("protocol", "register", folder, "-q")
    assert done.returncode == 0 and done.stdout.strip() == "p01", done  # its result: the new id
    done = pairplay_cli("protocol", "check", "thesis-ch7", "-q")
    assert (done.returncode, done.stdout, done.stderr) == (0, "", ""), done  # its result: the status
    done = pairplay_cli("protocol", "check", "thesis-ch7")
    assert done.returncode == 0 and done.stdout.startswith("study thesis-ch7"), done  # without -q: the protocol
    (tmp_path / "bad.toml").write_text('robot = "virtual"\n' + (folder / "study.toml").read_text())
    done = pairplay_cli("protocol", "check", tmp_path / "bad.toml", "-q")
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1, done
    done = pairplay_cli("protocol", "status", folder, "-q")
    assert done.returncode == 0 and "p01" in done.stdout, done
    done = pairplay_cli("session", "--participant", "sim:blind", "--rounds", "1", "--session", "q1",
                        "--out", tmp_path / "rec", "-q")
    assert done.returncode == 0 and done.stderr == "", done
    assert done.stdout.startswith("session q1: bus listening on") and done.stdout.count("\n") == 1, done.stdout
    assert (tmp_path / "rec" / "q1.mcap").is_file()


def test_quiet_keeps_where_to_watch_a_view_and_leaves_out_the_bench_progress(tmp_path, monkeypatch, capsys):
    """-q keeps the results a user asked for and leaves out progress and chatter, every verb alike (cli/main.py
    rule). `view --serve -q` printed nothing, not even the address of the viewer it served (view was silenced
    whole, as a verb whose results are files); `bench -q` still said "measuring ..." and the load average."""
    import select
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from pairplay.cli.main import main
    from test_bench_goals import _one_source

    _one_source(monkeypatch, [])
    assert main(["bench", "--only", "fake", "-q"]) == 0
    out, err = capsys.readouterr()
    assert "0.40 s" in out and err == "", (out, err)  # the table is its result; no progress, no load line
    assert main(["bench", "--only", "fake"]) == 0
    assert "measuring fake" in capsys.readouterr().err  # without -q: its progress
    sample = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
    view = subprocess.Popen([sys.executable, "-m", "pairplay", "view", "--recording", str(sample), "--no-save",
                             "--serve", "--grpc-port", "0", "--web-port", "0", "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        # (before: nothing until the process ended, which --serve leaves to a Ctrl-C)
        ready = select.select([view.stdout], [], [], 60)[0]
        line = view.stdout.readline() if ready else ""
        assert line.startswith("web viewer: http://127.0.0.1:"), line
    finally:
        time.sleep(0.2)
        view.send_signal(signal.SIGINT)
        out, err = view.communicate(timeout=60)
    assert "saved" not in out and "viewed" not in out, out  # the summary: left out under -q
