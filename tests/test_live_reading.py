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
