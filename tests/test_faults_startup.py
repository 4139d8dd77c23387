"""Startup edges (issue 12 item 1: every wait is announced, has a deadline, and ends within 2 s of a signal).

- A process that connects to a router that is not up (`pairplay run ... --connect`, `pairplay robot
  ... --connect`) says so in one line and exits 2 at once: Zenoh's client fails its first connect at
  once, and pairplay does not retry (decided: an orchestrator starts the router first; a router that
  restarts mid-session is survived by the clients already running, docs/bus.md).
- A session or a game that waits for services it does not start (`pairplay session --connect R
  --external learner`, `pairplay run game --wait-for learner`) says on its first line what it waits for
  and for how long; when nothing comes the wait ends in one line naming what did not come (exit 2);
  SIGTERM in that state ends the process within the exit budget, its recording finished.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from pairplay.replay.reader import read_log
from pairplay.services.bus import EXIT_BUDGET_S, Bus, BusOptions
from pairplay.services.game import GameLogic
from pairplay.schemas.session import SessionConfig
from pairplay.services.runner import Node

from test_faults_signals import SLACK_S
from test_router import free_port, start_router

PY = [sys.executable, "-m", "pairplay"]


@pytest.mark.parametrize("args", [["run", "learner", "--session", "s1"],
                                  ["run", "game", "--participant", "sim:ashley", "--session", "s2"],
                                  ["robot", "--robot", "virtual", "--session", "s3"],
                                  ["session", "--participant", "sim:ashley", "--session", "s4"]],
                         ids=["run learner", "run game", "robot", "session"])
def test_connecting_to_a_router_not_up_is_one_line_and_exit_2(tmp_path, args):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    r = subprocess.run([*PY, *args, "--connect", endpoint], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "cannot open the bus" in r.stderr and f"--connect {endpoint}" in r.stderr


def test_a_game_waiting_for_its_services_names_what_did_not_come_by_its_deadline():
    port = free_port()
    router = start_router(port)
    bus = Bus(BusOptions(mode="client", connect=[f"tcp/127.0.0.1:{port}"]))
    try:
        game = Node(bus, GameLogic(SessionConfig(session="w0", participant="sim:ashley", persona="ashley", seed=1,
                                                          rounds=1)), "w0",
                    resume=False)
        with pytest.raises(TimeoutError, match="game: no learner, participant on the bus after 1 s"):
            game.start(wait_for=("learner", "participant"), wait_timeout_s=1.0)
    finally:
        bus.close()
        router.kill()
        router.wait()


def first_line(p: subprocess.Popen, box: dict) -> None:
    box["line"] = p.stdout.readline()


def test_waiting_for_services_started_elsewhere_is_announced_and_a_signal_ends_it(tmp_path):
    port = free_port()
    router = start_router(port)
    endpoint = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    procs = {
        "session": subprocess.Popen([*PY, "session", "--participant", "sim:ashley", "--session", "wait1", "--out",
                                     str(tmp_path), "--connect", endpoint, "--external", "learner"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env),
        "game": subprocess.Popen([*PY, "run", "game", "--participant", "sim:ashley", "--session", "wait2",
                                  "--connect", endpoint, "--wait-for", "learner", "--wait-for", "recorder"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)}
    try:
        lines = {}
        for name, p in procs.items():
            box: dict = {}
            reader = threading.Thread(target=first_line, args=(p, box), daemon=True)
            reader.start()
            reader.join(120)
            lines[name] = box.get("line", "")
        assert lines["session"].startswith("session wait1: bus listening on (no listener) - client of " + endpoint)
        assert lines["session"].rstrip().endswith("waiting up to 30 s for: learner (started elsewhere)")
        assert lines["game"].startswith("listening (no listener) - waiting up to 30 s for: learner, recorder")
        time.sleep(1.0)  # in the wait
        took = {}
        for name, p in procs.items():
            assert p.poll() is None, p.stderr.read()
            t0 = time.monotonic()
            p.send_signal(signal.SIGTERM)
            p.wait(EXIT_BUDGET_S + SLACK_S + 10)
            took[name] = time.monotonic() - t0
            assert p.returncode == 128 + signal.SIGTERM, (name, p.stderr.read())  # README's exit rule
        print("SIGTERM -> exit while waiting:", {k: round(v, 2) for k, v in took.items()})
        assert max(took.values()) < EXIT_BUDGET_S + SLACK_S, took
        end = read_log(tmp_path / "wait1.mcap").metadata["pairplay.recorder.end"]
        assert end["stopped_by"] == "SIGTERM" and end["session_ended"] == "false"
    finally:
        for p in (*procs.values(), router):
            if p.poll() is None:
                p.kill()
            p.wait()
