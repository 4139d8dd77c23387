"""With the robot unreachable, the console says so and says why each suggestion failed (trial27 F13).

A new user's trial: `protocol serve --robot iristk://127.0.0.1:1` warned on the terminal only, and the console's
robot line read "iristk://127.0.0.1:1: failed " (RobotActed's `error` left out): nothing on the page said the
robot was unreachable. A real `protocol serve` process, a scripted participant (`--pilot`) so that a game plays
without a board, and the console's state over HTTP: its `robot_warning` holds the start-up warning, and the robot
line after the game holds the failure's reason.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

from pairplay.replay.studydata import StudyData

from test_console_api import call

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def test_the_console_shows_the_unreachable_robot_and_why_its_suggestions_failed(tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    data.register_many("phase1")
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "serve", "study", "--robot",
                             "iristk://127.0.0.1:1", "--pilot", "p01=blind"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        url = next(line.split(": ", 1)[1].strip() for line in proc.stdout if line.startswith("experimenter console:"))
        base, token = url.split("/console?token=")
        _, state = call(f"{base}/api/console/state?token={token}")
        assert "the robot did not accept a connection" in state["robot_warning"], state["robot_warning"]
        assert "iristk://127.0.0.1:1" in state["robot_warning"]
        status, answer = call(f"{base}/api/console/next?token={token}", {})
        assert status == 200, answer
        deadline = time.monotonic() + 300  # ends a hung test only; the loop waits for the step's end
        while time.monotonic() < deadline:
            _, state = call(f"{base}/api/console/state?token={token}")
            if not state["busy"] and state["games"]:
                break
            time.sleep(0.1)
        robot = state["live"]["robot"]
        assert robot.startswith("iristk://127.0.0.1:1: failed (") and robot.split("(", 1)[1].split(")")[0].strip(), \
            state["live"]
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
