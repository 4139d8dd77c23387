"""Two short writers of one study folder that collide: the second waits for the first (a new user's trial).

The folder lock (pairplay/folderlock.py) refused a second writer at once, "stop it", even when the holder was a
register or an export that ended a moment later: a script's `protocol register` beside an export failed. Now a
short holder is waited for (up to folderlock.WAIT_S, the waiter saying on stderr for whom), and a long one
(`protocol serve`, `protocol pilot`) is still refused at once, named (tests/test_study_guard.py: every verb
beside a running server).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pairplay import folderlock
from pairplay.replay.studydata import StudyData, StudyDataError

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


@pytest.fixture
def folder(tmp_path) -> Path:
    StudyData.create(tmp_path / "study", STUDY).close()
    return tmp_path / "study"


def test_a_register_waits_for_a_short_holder_says_for_whom_and_registers(folder):
    fd = folderlock.take(folder, "participant export")  # this process holds the folder, as a short verb
    register = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "register", str(folder), "--consent"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        said = register.stderr.readline()  # it waits, and says so, before the holder ends
        assert said.startswith(f"pairplay protocol register: waiting up to {folderlock.WAIT_S:g} s for another "
                               "pairplay that writes this study folder: participant export "
                               f"(pid {os.getpid()}, since "), said
        assert said.endswith(f"({folder})\n") and register.poll() is None, said
    finally:
        folderlock.release(fd)
    out, err = register.communicate(timeout=60)
    assert register.returncode == 0 and out == "p01\n" and err == "", (out, err)


def test_a_short_holder_that_does_not_end_in_time_is_refused_after_the_wait(folder, monkeypatch):
    monkeypatch.setattr(folderlock, "WAIT_S", 0.3)
    fd = folderlock.take(folder, "report")
    try:
        start = time.monotonic()
        with pytest.raises(StudyDataError) as refused:
            StudyData(folder, writer="protocol register")
        assert time.monotonic() - start >= 0.3
    finally:
        folderlock.release(fd)
    assert str(refused.value).startswith(f"another pairplay writes this study folder: report (pid {os.getpid()}, ")
    assert str(refused.value).endswith(f"; waited 0.3 s for it to finish (one writer per study folder): run this "
                                       f"again when it has ({folder})")
    assert StudyData(folder, writer="protocol register").register("phase1") == "p01"  # free now


# folderlock.LONG_HOLDERS, each with what to do about it: a pilot has no console (trial33 H: "work in its console")
@pytest.mark.parametrize("long, fix", [("protocol serve", "stop it, or work in its console"),
                                       ("protocol pilot", "wait for it to end, or stop it")])
def test_a_long_holder_is_refused_at_once_and_named(folder, long, fix):
    with StudyData(folder, writer=long):
        start = time.monotonic()
        with pytest.raises(StudyDataError, match=rf"^another pairplay writes this study folder: {long} \(pid "
                                                 rf"{os.getpid()}, since .*\); one writer per study folder: {fix} "):
            StudyData(folder, writer="protocol register")
        assert time.monotonic() - start < 2.0  # no wait (WAIT_S is 8 s): it holds the folder for hours


def test_a_wait_for_a_short_holder_ends_at_once_once_the_verb_stops_on_a_signal(folder, monkeypatch):
    """A verb that stops on signals itself (services/bus.py stop_on_signals) raises nothing in its handler: its
    lock waits went on for the whole WAIT_S after the signal. The signal it took (pairplay/signals.py `stopping`)
    ends the wait at once, as the KeyboardInterrupt of the other verbs does, and the lock is not taken."""
    from pairplay import signals

    fd = folderlock.take(folder, "report")
    try:
        monkeypatch.setattr(signals, "stopping", 15)
        start = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            folderlock.take(folder, "protocol register", folderlock.WAIT_S)
        assert time.monotonic() - start < 1.0
    finally:
        folderlock.release(fd)
    taken = folderlock.take(folder, "protocol register", folderlock.WAIT_S)  # a free lock is taken, stopping or not
    assert taken is not None
    folderlock.release(taken)
