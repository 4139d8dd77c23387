"""Every verb that reads recordings takes an interrupted session's file (a new user's trial, 2026-11-30).

`replay --verify` assumed a session ran to its end (a false FAIL at the
interrupted round, tests/test_verify_stopped.py); here the other readers of a
recording are given files of sessions stopped mid-round by SIGINT (written as
the recorder writes them: real MCAP files) and must use what was recorded:
rebuild (flagging the policies partial), profile and combine of those
policies, view, counterfactual, and verify through the command line.
"""

from __future__ import annotations

import json

import pytest

from pairplay.cli.main import main
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig

from test_verify_stopped import stopped_events


def write_recording(path, events) -> None:
    w = EventLogWriter(path)
    for e in events:
        w.write(event_key(e.session, e.source, type(e).__name__), encode_event(e), log_time_ns=e.time_ns)
    w.close()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two games of one simulated participant, each stopped by SIGINT in its second round."""
    folder = tmp_path_factory.mktemp("stopped")
    paths = []
    for game in (0, 1):
        config = SessionConfig(session=f"blind-g{game}", participant="sim:blind", persona="blind", seed=3,
                               rounds=3, game_index=game)
        whole = stopped_events(config, 10**9)
        second_round = next(i for i, e in enumerate(whole) if type(e).__name__ == "RoundStarted" and e.round == 1)
        path = folder / f"blind-g{game}.mcap"
        write_recording(path, stopped_events(config, second_round + 25, after=3))
        paths.append(path)
    return paths


def test_verify_passes_up_to_the_stop(recordings, capsys):
    assert main(["replay", str(recordings[0]), "--verify"]) == 0
    out = capsys.readouterr().out
    assert "verify: PASS" in out and "verified up to where the session stopped: interrupted (SIGINT) after 1 of 3" in out


def test_rebuild_profile_and_combine_use_what_was_recorded(recordings, tmp_path, capsys):
    rebuilt = tmp_path / "rebuilt"
    assert main(["rebuild", *map(str, recordings), "--out", str(rebuilt), "--no-plot"]) == 0
    err = capsys.readouterr().err  # warnings: on stderr (cli/main.py `warn`)
    assert err.count("PARTIAL session: interrupted (SIGINT) after 1 of 3 rounds") == 2, err
    policy = json.loads((rebuilt / "blind-g0.policy.json").read_text())
    assert policy["partial"].startswith("interrupted (SIGINT)")
    assert main(["profile", str(rebuilt)]) == 0
    assert main(["combine", str(rebuilt), "-o", str(tmp_path / "merged.json")]) == 0
    assert (tmp_path / "merged.json").exists()


def test_view_draws_it(recordings, tmp_path, capsys):
    rrd = tmp_path / "v.rrd"
    assert main(["view", "--recording", str(recordings[0]), "--out", str(rrd), "--speed", "0"]) == 0
    assert rrd.stat().st_size > 1000


def test_counterfactual_fits_the_rounds_it_holds(recordings, tmp_path, capsys):
    out = tmp_path / "cf"
    assert main(["counterfactual", str(recordings[0]), "--fit-only", "--out", str(out)]) == 0
    assert list(out.glob("*.usermodel.json"))
