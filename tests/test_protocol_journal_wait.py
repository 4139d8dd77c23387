"""A `protocol serve` stopped by a signal waits for its running game's end to be journaled (StudyRunner.wait_journaled,
its own last fact), but not for ever, and a second signal of either kind cuts the wait. Before: the wait had no limit
(a journal write that never came, a hung disk, held the process for ever) and only a second SIGINT ended it: a second
SIGTERM, what a supervisor sends, was not heard. A real process: a real study folder, bus and runner, its signal
handling serve's own (services/bus.py stop_on_signals), a game whose end is owed to the journal and never written."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_protocol_interrupted import STUDY, study_with

SERVE_TAIL = r"""
import sys, threading
from pairplay.replay.studydata import StudyData
from pairplay.services import protocol
from pairplay.cli.protocol import stop_runners_on_signals
from pairplay.services.bus import Bus, BusOptions

protocol.JOURNALED_WAIT_S = float(sys.argv[2])
stop, runners = threading.Event(), []
stop_runners_on_signals(stop, runners)
with Bus(BusOptions(), stop=stop) as bus:
    runner = protocol.StudyRunner(StudyData(sys.argv[1]), bus)
    runners.append(runner)
    runner._journaled.clear()  # a game is running: its end is owed to the journal, and its write never comes
    print("serving", flush=True)
    while not stop.wait(0.2):
        pass
    runner.interrupt(stop)
    try:  # as cli/protocol.py _serve
        print("journaled" if runner.wait_journaled() else "gave up", flush=True)
    except KeyboardInterrupt:
        print("cut", flush=True)
"""


def _serving(folder: Path, wait_s: float) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", SERVE_TAIL, str(folder), str(wait_s)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    assert proc.stdout.readline() == "serving\n", proc.stderr.read()
    return proc


def _ended(proc: subprocess.Popen, within_s: float) -> str:
    try:
        out, err = proc.communicate(timeout=within_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(f"still waiting {within_s} s after the signal")
    return out.strip()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return study_with(tmp_path_factory.mktemp("wait"), STUDY.read_text()).folder


def test_the_wait_for_the_journal_is_bounded(folder):
    proc = _serving(folder, 0.5)
    proc.send_signal(signal.SIGTERM)
    assert _ended(proc, 10) == "gave up"


def test_a_second_sigterm_cuts_the_wait_as_a_second_sigint_does(folder):
    proc = _serving(folder, 600)
    proc.send_signal(signal.SIGTERM)
    time.sleep(0.5)  # (in the wait now)
    began = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    assert _ended(proc, 10) == "cut" and time.monotonic() - began < 5


def test_a_second_signal_cuts_the_session_s_wait_for_its_recorder_thread_in_the_main_thread_only(monkeypatch):
    """services/session.py waits for its recorder thread's last step without a limit (cut, the file would be finished
    under the batch it writes); a second SIGINT cut that join, a second SIGTERM was not heard. `signals.wait_cut`
    ends on either in the main thread; in another (a study's game thread) it only waits, the signal the main
    thread's to act on."""
    import threading

    from pairplay import signals

    hung = threading.Event()
    thread = threading.Thread(target=hung.wait, daemon=True)
    thread.start()
    monkeypatch.setattr(signals, "again", signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        signals.wait_cut(thread)
    waited: list = []
    other = threading.Thread(target=lambda: waited.append(signals.wait_cut(thread, 0.2)))
    other.start()
    other.join(10)
    assert waited == [False]
    hung.set()
    assert signals.wait_cut(thread, 10)
