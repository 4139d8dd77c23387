"""What a service run on its own says, on a real loopback bus (trial34 J).

Before: `pairplay run recorder` said nothing at its end (rc 0): not the file, not the count, the one line a
person looks for on the recorder's host (`pairplay session` says "recorded N events to PATH"); `pairplay robot
--connect` printed "bus " with nothing after it (a client listens nowhere; other verbs say "(no listener)").
"""

from __future__ import annotations

import signal
import subprocess

from busutil import listener, wait_until
from cli_zygote import shared

from pairplay.replay.reader import read_log
from pairplay.schemas.keys import alive_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import BusOptions
from pairplay.services.session import run_session


def test_a_recorder_run_on_its_own_says_what_it_recorded(tmp_path):
    s = "says1"
    with listener() as bus:
        rec = shared().start(["run", "recorder", "--session", s, "--out", str(tmp_path / "out"), "--connect",
                              bus.locators()[0]], stderr=subprocess.DEVNULL)
        try:
            assert wait_until(lambda: alive_key(s, "recorder") in bus.alive_now(alive_key(s, "*")), 30)
            config = SessionConfig(session=s, participant="sim:ashley", persona="ashley", seed=3, rounds=2)
            run_session(config, tmp_path / "unused.mcap", external=("recorder",),
                        bus_options=BusOptions(listen=[], connect=bus.locators()))
            assert rec.wait(60) == 0
            said = rec.stdout.read().splitlines()
        finally:
            if rec.poll() is None:
                rec.kill()
                rec.wait()
    path = tmp_path / "out" / f"{s}.mcap"
    assert said[-1] == f"recorded {len(read_log(path).events)} events to {path}", said


def test_a_robot_bridge_that_listens_nowhere_says_so():
    with listener() as bus:
        robot = shared().start(["robot", "--session", "says2", "--connect", bus.locators()[0]],
                               stderr=subprocess.DEVNULL)
        try:
            first = robot.stdout.readline()
            robot.send_signal(signal.SIGTERM)
            robot.wait(60)
        finally:
            if robot.poll() is None:
                robot.kill()
                robot.wait()
    assert first == "robot bridge for session says2 on virtual; bus listening on (no listener)\n", first


def test_a_recorder_again_over_a_file_of_no_session_says_the_way_out_its_stop_gave(tmp_path, pairplay_cli):
    """A recorder stopped before its session began keeps the id taken ("remove the file ... to reuse it"); a second
    one on that id said only "has a recording already; no live session on the bus sent what it holds; choose
    another --session" of a file that holds no session (trial34 E)."""
    s = "again1"
    with listener() as bus:
        rec = shared().start(["run", "recorder", "--session", s, "--out", str(tmp_path), "--connect",
                              bus.locators()[0]])
        try:
            assert wait_until(lambda: alive_key(s, "recorder") in bus.alive_now(alive_key(s, "*")), 30)
            rec.send_signal(signal.SIGINT)
            assert rec.wait(60) == 130
            stopped = rec.stderr.read()
        finally:
            if rec.poll() is None:
                rec.kill()
                rec.wait()
        assert "holds no session (the id stays taken: remove the file" in stopped, stopped
        ran = pairplay_cli("run", "recorder", "--session", s, "--out", tmp_path, "--connect", bus.locators()[0])
    assert ran.returncode == 2 and len(ran.stderr.splitlines()) == 1, ran
    assert f"session {s} has a recording already; it holds no session (its recorder stopped before the session " \
           f"began): remove {s}.mcap to reuse the id, or choose another --session" in ran.stderr, ran
