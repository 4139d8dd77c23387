"""A second signal to `protocol serve` before its game's recording began says which game and what happens to it.

A new user's trial: the first signal stops a game the console had just started (its GameStarted journaled, its
recording not yet begun), a second one cuts the shutdown: serve said main's generic "interrupted ...; nothing more
was written" line, though the journal holds a started game with no end. Now the line names the game, says no
recording was begun, and what the next serve does with it. Real processes, real signals: the game held as it is
set up (pairplay/testpause.py `game-set-up`), the first signal handled as serve stops (`serve-stopping`), then the
second.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

from pairplay.replay.studydata import StudyData

from test_protocol_interrupted import STUDY, api, study_with

LIMIT_S = 300


def test_a_second_signal_before_the_games_recording_began_names_the_game_and_what_comes_next(tmp_path, pairplay_cli):
    data = study_with(tmp_path, STUDY.read_text())
    folder = data.folder
    pid = next(iter(data.state.participants))
    session = data.session_id(pid, "phase1", 0)
    moments = ("game-set-up", "serve-stopping")
    env = dict(os.environ, PYTHONUNBUFFERED="1",
               PAIRPLAY_TEST_PAUSE=";".join(f"{m}:{tmp_path / f'go-{m}'}" for m in moments))
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "serve", str(folder), "--pilot",
                             f"{pid}=blind"], cwd=tmp_path, env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    out = iter(proc.stdout)
    console = next(line for line in out if "experimenter console:" in line)
    threading.Thread(target=lambda: list(out), daemon=True).start()
    base, token = console.split("experimenter console: ", 1)[1].strip().split("/console?token=")
    err = iter(proc.stderr)
    threading.Thread(target=api, args=(f"{base}/api/console/next", token, {}), daemon=True).start()
    assert next(line for line in err if line.startswith("pairplay-test:")) == "pairplay-test: paused at game-set-up\n"
    proc.send_signal(signal.SIGINT)  # the first: serve stops, the game held before its recording began
    assert next(line for line in err if line.startswith("pairplay-test:")) == "pairplay-test: paused at serve-stopping\n"
    proc.send_signal(signal.SIGINT)  # the second, as serve waits for the game's end
    said = [line.rstrip("\n") for line in err]
    assert proc.wait(LIMIT_S) == 130, said
    recording = folder / "recordings" / f"{session}.mcap"
    assert not recording.exists()
    assert said[-1] == (f"pairplay protocol serve: interrupted again (Ctrl-C) while stopping; game {session} was "
                        f"stopped before its recording began: the journal holds its start and no end, and no "
                        f"recording of it was written ({recording}); the next serve, pilot or report journals it "
                        "aborted, and its step is played again"), said
    assert StudyData(folder).state.games[session].ended is None
    # as the line says
    ran = pairplay_cli("report", folder)
    assert (f"pairplay report: {session}: journaled aborted (stopped before its recording began); its step is played "
            "again") in ran.stderr.splitlines(), ran.stderr
    after = StudyData(folder)
    assert after.state.games[session].ended.outcome == "aborted"
    [step] = [s for s in after.plan() if s.kind == "play" and (s.participant, s.phase, s.game) == (pid, "phase1", 0)]
    assert not step.done and not step.blocked, step
