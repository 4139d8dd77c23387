"""Game after game on one bus, nothing piles up: a study's steps leave no thread, socket or declaration behind.

`protocol pilot` and `protocol serve` run every game of a study on one Zenoh session
(services/protocol.py StudyRunner). Each game's session, player and subscriptions
declared ~40 things on that bus, each subscriber with a thread of zenoh-python's, and
the scripted board's and the combiner's Outboxes were never stopped: a new user's
12-game pilot went from 53 to 511 threads and 1.8 to 5.5 GB of address space, and
under `ulimit -v 3000000` game 5 could not start a thread. Now each game runs on a
scope of the bus (services/bus.py Bus.scope) released at its end.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from busutil import wait_until

from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner, scripted_players
from pairplay.services.robot.choice import RobotChoice

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
PERSONAS = ["tatiana", "blind"]


def os_threads() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("Threads:"):
            return int(line.split()[1])
    raise AssertionError("no Threads line in /proc/self/status")


def sockets() -> int:
    """Open sockets of this process: a Zenoh session's listener and links among them."""
    n = 0
    for fd in os.listdir("/proc/self/fd"):
        try:
            n += os.readlink(f"/proc/self/fd/{fd}").startswith("socket:")
        except OSError:  # closed meanwhile
            pass
    return n


def counts() -> tuple[int, int, int]:
    return len(threading.enumerate()), os_threads(), sockets()


def test_every_step_of_a_pilot_gives_back_its_threads_sockets_and_declarations(tmp_path):
    # the pilot with two players (the fewest a combination takes) of two games in phase 1 (the fewest a profile
    # takes), both in phase 2 too ("all"): each kind of step (a game of each phase, the combination) comes after
    # another on the one bus, six games in all
    data = StudyData.create(tmp_path / "study", STUDY, key_file=tmp_path / "keys.csv")
    ids = [data.register("phase1"), data.register("phase1")]
    after: list[tuple[str, tuple[int, int, int]]] = []
    with Bus(BusOptions()) as bus:
        # the virtual robot at a twentieth of its time: its bridge, driver and reply threads are a game's too
        runner = StudyRunner(data, bus, robot=RobotChoice("virtual?time_scale=0.05"))
        baseline: list[tuple[int, int, int]] = []

        def on_step(step, _result) -> None:
            if not baseline:  # the first game starts what lives as long as the bus (Zenoh's runtime)
                wait_until(lambda: False, 1.0)
                baseline.append(counts())
                return
            # a step's threads end as it returns or just after (a close left to a daemon thread): each count
            # comes back to the first game's, whatever ran before in this worker
            wait_until(lambda: all(c <= b for c, b in zip(counts(), baseline[0])), 10)
            after.append((step.label, counts()))
            # (threads in Python, in the OS, sockets): before, each game left ~35 threads
            assert all(c <= b for c, b in zip(after[-1][1], baseline[0])), (baseline[0], after)

        runner.warns_undelivered = False  # superseded suggestions are no news here
        runner.run_plan(scripted_players(runner, dict(zip(ids, PERSONAS))), on_step=on_step)
        assert data.next_step() is None and len(after) == 6  # 5 more games and the combination
        assert not bus._declared and not bus._scopes  # the study's bus itself declared nothing that stays
