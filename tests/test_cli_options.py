"""Every number option of every verb (and action) has a type from cli/args.py that states its range.

Before: a bare `type=int` or `type=float` let a value no verb can use through argparse:
`pairplay combine POLICIES --seed -5` (and `profile`) ended in core/rng.py's ValueError, a traceback
and exit 1; `pairplay session --ignore-window-ms nan` started the bus, the session's config went out
with the window as JSON null, the recorder refused SessionStarted (two WARNING lines and a stub
recording that took the session id); `--turn-back-ms -5`, `--ignore-window-ms -3` and
`lab --linger nan` were taken as given."""

from __future__ import annotations

import argparse

import pytest

from pairplay.cli import args as options
from pairplay.cli.main import VERBS, build_parser, main

from test_cli_usage import MINIMAL


def _parsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for nested in action.choices.values():
                yield from _parsers(nested)


@pytest.mark.parametrize("verb", list(VERBS))
def test_no_number_option_is_a_bare_int_or_float(verb):
    _, chosen = build_parser([verb])
    bare = [f"{p.prog} {'/'.join(a.option_strings) or a.dest}" for p in _parsers(chosen) for a in p._actions
            if a.type in (int, float)]
    assert not bare, f"give these a type from cli/args.py (a range): {bare}"


def test_the_seed_range_is_core_rngs():
    from pairplay.core.rng import SEED_RANGE
    assert (0, options.SEED_MAX) == SEED_RANGE


@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "-1", "3601", "1e300"])
def test_a_duration_is_a_finite_number_0_to_an_hour(text):
    with pytest.raises(argparse.ArgumentTypeError):
        options.duration(text)


# verb's arguments -> a piece of the one line; each is refused by argparse, before any work
REFUSED = {
    "combine --seed -5": (["combine", "p.json", "--seed", "-5"], "--seed: a seed is 0..18446744073709551615, got -5"),
    "profile --seed -5": (["profile", "p.json", "--seed", "-5"], "--seed: a seed is 0..18446744073709551615, got -5"),
    "session --seed 2**64": (["session", *MINIMAL["session"]] + ["--seed", str(2**64)], "--seed: a seed is 0.."),
    "study --seed -1": (["study", "--seed", "-1"], "--seed: a seed is 0..18446744073709551615, got -1"),
    "counterfactual --seed 2**64": (["counterfactual", "r.mcap", "--seed", str(2**64)], "a seed is 0.."),
    "session --ignore-window-ms nan": (["session", *MINIMAL["session"]] + ["--ignore-window-ms", "nan"], "not a finite number"),
    "session --ignore-window-ms -3": (["session", *MINIMAL["session"]] + ["--ignore-window-ms", "-3"], "must be at least 0"),
    "session --turn-back-ms -5": (["session", *MINIMAL["session"]] + ["--turn-back-ms", "-5"], "must be at least 0"),
    "session --lspi-ridge nan": (["session", *MINIMAL["session"]] + ["--lspi-ridge", "nan"], "--lspi-ridge: not a finite number"),
    "session --lspi-every 0": (["session", *MINIMAL["session"]] + ["--lspi-every", "0"], "--lspi-every: must be at least 1"),
    "run game --turn-back-ms inf": (["run", "game", "--participant", "sim:blind", "--turn-back-ms", "inf"],
                                    "not a finite number"),
    "lab --linger nan": (["lab", *MINIMAL["lab"]] + ["--linger", "nan"], "--linger: not a finite number"),
    # the game's wait for its recorder's return was a fixed 30 s (trial33 K's leftover): an option, checked as --linger
    "run game --settle nan": (["run", "game", "--participant", "sim:blind", "--wait-for", "recorder", "--settle", "nan"],
                              "--settle: not a finite number: 'nan'"),
    "run game --settle -1": (["run", "game", "--participant", "sim:blind", "--wait-for", "recorder", "--settle", "-1"],
                             "--settle: must be at least 0, got -1"),
    "run game --settle 1e9": (["run", "game", "--participant", "sim:blind", "--wait-for", "recorder", "--settle",
                               "1e9"], "--settle: must be 0..3600 (seconds to wait: an hour at most), got 1e9"),
    "study --lspi-ridge 0": (["study", "--lspi-ridge", "0"], "--lspi-ridge: must be above 0"),
    "sweep --workers 0": (["sweep", "g.toml", "--workers", "0"], "--workers: must be at least 1"),
    "bench --runs 0": (["bench", "--runs", "0"], "--runs: must be at least 1"),
    "protocol register --count 0": (["protocol", "register", "folder", "--count", "0"], "--count: must be at least 1"),
    "view --speed inf": (["view", "--recording", "r.mcap", "--speed", "inf"], "--speed: must be max (or 0, as fast"),
    # bounds of what sizes time (a new user's trial, 2026-12-01): `--speed nan` replayed nothing with exit 0,
    # `--speed 1e-300` and `--linger 1e300` were OverflowError tracebacks, `--turn-back-ms 1e300` held a pair for ever
    "replay --speed nan": (["replay", "r.mcap", "--speed", "nan"], "--speed: must be max (or 0, as fast as possible) "
                                                                    "or 0.0001..1e+06 times real time"),
    "replay --speed 1e-300": (["replay", "r.mcap", "--speed", "1e-300"], "got 1e-300"),
    "view --speed 1e-300": (["view", "--recording", "r.mcap", "--speed", "1e-300"], "--speed: must be max"),
    "lab --linger 1e300": (["lab", *MINIMAL["lab"]] + ["--linger", "1e300"],
                           "--linger: must be 0..3600 (seconds to wait: an hour at most), got 1e300"),
    "session --turn-back-ms 1e300": (["session", *MINIMAL["session"]] + ["--turn-back-ms", "1e300"],
                                     "--turn-back-ms: must be 0..60000"),
    "session --ignore-window-ms 1e9": (["session", *MINIMAL["session"]] + ["--ignore-window-ms", "1e9"],
                                       "--ignore-window-ms: must be 0..60000"),
    # a refused value is echoed as typed, integers as numbers are (a trial: `--seed 1_0...0` was said in the
    # digits Python parsed, `--rounds 0_0` as "got 0"): the line points at what is on the command line
    "session --rounds 0_0": (["session", *MINIMAL["session"]] + ["--rounds", "0_0"],
                             "--rounds: must be at least 1, got 0_0 "),
    "session --seed 1_0...0": (["session", *MINIMAL["session"]] + ["--seed", "1_" + "0" * 22],
                               "--seed: a seed is 0..18446744073709551615, got 1_" + "0" * 22 + " "),
    "session --game-index 2**63": (["session", *MINIMAL["session"]] + ["--game-index", "9_223_372_036_854_775_808"],
                                "got 9_223_372_036_854_775_808 "),
    "sweep --workers 99_999": (["sweep", "g.toml", "--workers", "99_999"], "got 99_999 "),
    "view --web-port 7_0000": (["view", "--recording", "r.mcap", "--web-port", "7_0000"],
                               "--web-port: a port is 0..65535, got 7_0000 "),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_number_out_of_range_is_one_line_and_exit_2_before_any_work(case, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may be written: the folder stays empty
    argv, expected = REFUSED[case]
    with pytest.raises(SystemExit) as stopped:
        main(argv)
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err, err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("sid", ["x.1", ".", "..", "a\\b", "x.recovered"])
def test_a_session_id_that_could_name_another_sessions_file_is_refused(sid, capsys):
    """A new user's trial (2026-11-30): `--session x.1` was taken, its file was part 1 of session x,
    and `session --session x --force` deleted it; `.` and `..` made hidden recordings."""
    from pairplay.cli.main import main

    with pytest.raises(SystemExit) as done:
        main(["session", "--participant", "sim:blind", "--rounds", "1", "--session", sid])
    assert done.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "session id" in err[0] and "recording files" in err[0], err
