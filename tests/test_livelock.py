"""A live recording is locked (pairplay/livelock.py): no verb replaces or removes a file a live
recorder holds, --force or not, and of two sessions of one id started at the same moment the one
refused prints nothing before its one line. Before: `pairplay session --session dupF --force` while
dupF was still recording removed its file, and the first session then reported "recorded 38252
events to recF/dupF.mcap" of a file holding the second one's events."""

import os
import signal
import subprocess
import sys
import time

import pytest

from pairplay.cli.main import main
from pairplay.livelock import LIVE, is_live
from pairplay.replay.reader import read_log
from pairplay.replay.wal import wal_path
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services import recorder as recorder_module
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.recorder import Recorder, RecordingExists
from pairplay.services.session import run_session

from hints import bad_options
from test_session_ids import earlier_recording


def _one_line(capsys, verb):
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and err.startswith(f"pairplay {verb}: "), (out, err)
    return err


@pytest.mark.parametrize("verb", ["session", "lab"])
def test_a_live_recording_is_never_replaced_by_a_new_session_of_its_id(tmp_path, capsys, verb):
    live = Recorder(None, "dupF", tmp_path / "dupF.mcap")  # a recorder writing now (it holds the file)
    try:
        inode = os.stat(tmp_path / "dupF.mcap").st_ino
        who = "sim:deaf" if verb == "session" else "human:p1"
        force = ["--force"] if verb == "session" else []
        assert main([verb, "--participant", who, "--rounds", "2", "--session", "dupF", "--out", str(tmp_path),
                     *force]) == 2
        err = _one_line(capsys, verb)
        assert LIVE in err and "--session" in err and "--force" not in err, err  # the hint is right
        assert bad_options([verb], err) == []  # it names only the verb's own options (tests/hints.py)
        assert os.stat(tmp_path / "dupF.mcap").st_ino == inode
    finally:
        live.close()
    assert not is_live(tmp_path / "dupF.mcap")  # closed: a file left behind, --force may replace it again


def test_a_recording_made_since_the_check_is_not_truncated_and_the_second_recorder_is_refused(tmp_path, monkeypatch):
    """Two recorders of one id started at the same moment: both passed the check; one creates the file."""
    first = Recorder(None, "race", tmp_path / "race.mcap")
    try:
        first.writer.flush(0)
        size = (tmp_path / "race.mcap").stat().st_size
        monkeypatch.setattr(recorder_module, "check_new_recording", lambda *a, **k: None)  # the other's check passed
        monkeypatch.setattr(recorder_module, "free_path", lambda p: p)  # ... when there was no file yet
        with pytest.raises(RecordingExists) as refused:
            Recorder(None, "race", tmp_path / "race.mcap")
        assert refused.value.live and LIVE in str(refused.value)
        assert (tmp_path / "race.mcap").stat().st_size == size  # not truncated
    finally:
        first.close()
    assert read_log(tmp_path / "race.mcap").whole


def test_a_restarted_recorder_is_refused_while_the_earlier_one_still_records(tmp_path):
    """`pairplay run recorder` restarted within a live session continues the session's file in its own,
    but only when the earlier recorder is gone: beside a live one, both would record the session."""
    live = Recorder(None, "twice", tmp_path / "twice.mcap")
    try:
        with pytest.raises(RecordingExists) as refused:
            Recorder(None, "twice", tmp_path / "twice.mcap", restart=True)
        assert refused.value.live and not (tmp_path / "twice.1.mcap").exists()
    finally:
        live.close()
    Recorder(None, "twice", tmp_path / "twice.mcap", restart=True).close()  # gone: continued
    assert (tmp_path / "twice.1.mcap").exists()


def test_a_session_refused_for_a_live_id_has_said_nothing_first(tmp_path):
    live = Recorder(None, "twin", tmp_path / "twin.mcap")
    said = []
    try:
        with pytest.raises(RecordingExists) as refused:
            run_session(SessionConfig(session="twin", participant="sim:ashley", persona="ashley", seed=1, rounds=1),
                        tmp_path / "twin.mcap", bus_options=BusOptions(mode="peer", listen=("tcp/127.0.0.1:0",)),
                        on_bus=lambda bus: said.append(bus.locators()))
        assert refused.value.live and said == []  # refused before the "bus listening on" line
    finally:
        live.close()


@pytest.mark.parametrize("args", [
    ["recover", "{other}", "-o", "{live}", "--force"],
    ["view", "--recording", "{other}", "--out", "{live}", "--force"],
    ["recover", "{live}"],
    ["recover", "{live}", "--discard-journal"],
])
def test_no_verb_replaces_or_reads_as_cut_a_live_recording_or_its_journal(tmp_path, capsys, args):
    whole = earlier_recording(tmp_path / "whole.mcap").read_bytes()
    other = tmp_path / "other.mcap"
    other.write_bytes(whole[:len(whole) * 3 // 4])  # cut: recover writes its output
    live = Recorder(Bus(BusOptions(mode="peer", listen=("tcp/127.0.0.1:0",))), "livid", tmp_path / "livid.mcap")
    live.start()  # its journal too
    try:
        before = (tmp_path / "livid.mcap").stat().st_ino
        assert is_live(tmp_path / "livid.mcap") and is_live(wal_path(tmp_path / "livid.mcap"))
        argv = [a.format(other=other, live=tmp_path / "livid.mcap") for a in args]
        assert main(argv) == 2
        err = _one_line(capsys, args[0])
        assert LIVE in err, err
        assert (tmp_path / "livid.mcap").stat().st_ino == before and wal_path(tmp_path / "livid.mcap").exists()
        assert not list(tmp_path.glob("livid.recovered*"))
    finally:
        live.close()
        live.bus.close()


def test_session_force_refuses_a_running_sessions_recording_and_it_keeps_its_own_events(tmp_path):
    """The trial's repro, two real processes: the first keeps its file and reports its own events."""
    first = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:blind", "--rounds",
                              "3000", "--session", "dupF", "--out", "recF", "--listen", "tcp/127.0.0.1:0"],
                             cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = first.stdout.readline()
        assert "bus listening on" in line, (line, first.stderr.read() if first.poll() is not None else "")
        recording, deadline = tmp_path / "recF" / "dupF.mcap", time.monotonic() + 60
        while not (recording.exists() and recording.stat().st_size > 0):  # playing, its file written (the trial's
            assert time.monotonic() < deadline and first.poll() is None  # repro slept 5 s: 5 s of CPU playing)
            time.sleep(0.05)
        second = subprocess.run([sys.executable, "-m", "pairplay", "session", "--participant", "sim:deaf", "--rounds",
                                 "20", "--session", "dupF", "--out", "recF", "--force", "--listen", "tcp/127.0.0.1:0"],
                                cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert second.returncode == 2 and second.stdout == "", second
        assert len(second.stderr.strip().splitlines()) == 1 and LIVE in second.stderr, second.stderr
        first.send_signal(signal.SIGINT)
        out, err = first.communicate(timeout=60)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    log = read_log(tmp_path / "recF" / "dupF.mcap")
    started = [r.event.config.participant for r in log.events if isinstance(r.event, ev.SessionStarted)]
    assert started == ["sim:blind"], started
    assert "recorded " in err and "recF/dupF.mcap" in err, err
