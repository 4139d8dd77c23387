"""Reading a recording its recorder is still writing (a new user's trial): `replay --verify`,
`rebuild`, `view` and `counterfactual` took it for a crashed file ("the file is cut (a crash?)").
They now say it is live and read as far as it goes (pairplay/livelock.py: the recorder's lock)."""

from __future__ import annotations

from pathlib import Path

from pairplay.livelock import LIVE, hold, release
from pairplay.replay.reader import read_log

SAMPLE = Path(__file__).resolve().parent.parent / "recordings" / "samples" / "sim-ashley.mcap"


def test_a_recording_being_written_is_read_as_live_not_cut(tmp_path, pairplay_cli):
    whole = read_log(SAMPLE)
    assert whole.whole and not whole.live
    data = SAMPLE.read_bytes()
    cut = tmp_path / "live.mcap"
    cut.write_bytes(data[: len(data) // 2])  # what a writer has flushed so far: no summary, no footer
    assert read_log(cut).truncated and not read_log(cut).live  # a file left behind: cut
    fd = hold(cut)  # its recorder's lock, as a live recorder holds it
    try:
        log = read_log(cut)
        assert log.live and log.error.startswith(LIVE), log.error
        r = pairplay_cli("replay", str(cut), "--verify")
        assert "a crash?" not in r.stdout and LIVE in r.stdout, r.stdout
    finally:
        release(fd)
    r = pairplay_cli("replay", str(cut), "--verify")
    assert "a crash?" in r.stdout, r.stdout


def test_a_view_of_a_live_recording_is_saved_as_partial_and_says_it_is_live(tmp_path, pairplay_cli):
    """A new user's trial: `pairplay view --recording` of a file its recorder was writing saved live.rrd, a part of
    the session under the complete view's name. It is saved as live.partial.rrd, the line saying the file is live;
    once the recording is no longer live, the same view saves live.rrd."""
    data = SAMPLE.read_bytes()
    cut = tmp_path / "live.mcap"
    cut.write_bytes(data[: len(data) // 2])
    fd = hold(cut)
    try:
        r = pairplay_cli("view", "--recording", str(cut), cwd=tmp_path, timeout=180)
    finally:
        release(fd)
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "live.rrd").exists() and (tmp_path / "live.partial.rrd").stat().st_size > 0
    [line] = r.stdout.splitlines()
    assert line.startswith(f"saved {tmp_path / 'live.partial.rrd'}: ") and f"partial: {cut} {LIVE}" in line, line


def test_run_recorder_refuses_a_live_recording_before_it_listens(tmp_path, pairplay_cli):
    """`pairplay run recorder` beside a live recording printed its `listening ...` line, then refused: an
    orchestrator reading the first line took it for a recorder that runs. The refusal now comes first, alone."""
    (tmp_path / "s1.mcap").write_bytes(SAMPLE.read_bytes())
    fd = hold(tmp_path / "s1.mcap")
    try:
        r = pairplay_cli("run", "recorder", "--session", "s1", "--out", str(tmp_path), cwd=tmp_path)
    finally:
        release(fd)
    assert r.returncode == 2 and r.stdout == "", (r.stdout, r.stderr)
    [line] = r.stderr.splitlines()
    assert LIVE in line, line
