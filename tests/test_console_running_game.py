"""The console's API refuses what its page refuses for a running game, and an export leaves out its files
(trial27 F10).

A new user's trial: with a game running, `POST /api/console/control/invalid` journaled a SessionMarkedInvalid
before the game's GameEnded (the page's button is disabled while the game runs; `protocol mark-invalid` is
refused by the folder's lock), and `POST /api/console/export` shipped the half-written recording (no footer)
with its recorder's journal, the README calling it "every event of the game". Real server, real bus, HTTP: the
mark is refused in one line (`StudyData.mark_invalid`, the one rule), the export leaves the running game's files
out and says so in its answer and its README.
"""

from __future__ import annotations

import io
import time
import zipfile
from pathlib import Path

from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import ConsoleServer
from pairplay.services.protocol import StudyRunner

from test_console_api import call

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def _until(server, what, limit_s: float = 60.0) -> dict:
    """The console's state once `what(state)` holds (polled; the limit only ends a hung test)."""
    deadline = time.monotonic() + limit_s
    while True:
        _, state = call(f"{server.url}/api/console/state?token={server.token}")
        if what(state) or time.monotonic() > deadline:
            return state
        time.sleep(0.05)


def test_a_running_game_is_not_marked_invalid_and_its_files_are_left_out_of_an_export(tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        t = server.token
        try:
            call(f"{server.url}/api/console/register?token={t}", {"phase": "phase1", "count": 2, "consent": True})
            status, answer = call(f"{server.url}/api/console/next?token={t}", {})
            assert status == 200, answer
            state = _until(server, lambda s: any(g["outcome"] == "running" for g in s["games"])
                           and any((data.folder / "recordings").glob("*.mcap*")) and s["live"]["state"] == "playing")
            [game] = state["games"]
            assert game["outcome"] == "running", state
            session = game["session"]

            status, answer = call(f"{server.url}/api/console/control/invalid?token={t}",
                                  {"session": session, "reason": "x"})
            assert status == 400 and answer["error"] == f"{session}: the game is running: abort it or wait for its end"

            status, answer = call(f"{server.url}/api/console/export?token={t}", {"participant": "p01"})
            assert status == 200, answer
            assert answer["left_out"] == [f"{session}: running: its files are left out; export again after its end"]
            with zipfile.ZipFile(io.BytesIO((data.folder / "exports" / "p01.zip").read_bytes())) as z:
                assert not [n for n in z.namelist() if session in n], z.namelist()
                readme = z.read("README.txt").decode()
            assert "running when exported: its files are left out" in readme, readme

            call(f"{server.url}/api/console/control/abort?token={t}", {"reason": "the test ends"})
            state = _until(server, lambda s: not s["busy"])
        finally:
            server.close()
    assert not state["busy"]
    journal = [type(e).__name__ for e in StudyData(tmp_path / "study").read_journal()]
    assert "SessionMarkedInvalid" not in journal and journal.count("GameEnded") == 1, journal
