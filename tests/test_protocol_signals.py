"""What `protocol serve` and `protocol pilot` say when a signal stops them mid-game (a new user's trial).

Real `pairplay` processes on loopback, a real study folder whose first game a persona plays on the bus
(`serve --pilot`, or `pilot`), real signals. Before:
- a second SIGTERM as serve stopped said `pairplay protocol: interrupted (SIGTERM); nothing more was written`,
  a recording on disk: now the line is cli/session.py `cut_line`'s, naming the file (whole, or `pairplay recover`
  it), under the sub-verb's whole name; likewise a second signal to pilot;
- one signal said `stopped (Ctrl-C)` (serve) or `interrupted (Ctrl-C)` (pilot) and named no game: now the line
  names the game it stopped, how the journal ended it and its recording.
The second signal lands in the recorder's end-and-journal step (pairplay/testpause.py `recorder-whole`): in serve
that step runs in the console's thread, and the line waits for it (pairplay/signals.py `held_elsewhere_over`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from test_cut_signals import Held, whole
from test_protocol_interrupted import STUDY, api, study_with

# phase 1's games long enough that a signal after the first round meets the game still running
LONG = STUDY.read_text().replace('rounds = 2\nalgorithm = "q-learning"', 'rounds = 100\nalgorithm = "q-learning"')
assert LONG != STUDY.read_text()


def serving(tmp_path, moment: str) -> tuple[Held, str]:
    """A `protocol serve --pilot p01=blind` whose console started p01's first game, once the game has played a round;
    (held process, the game's recording as serve names it)."""
    data = study_with(tmp_path, LONG)
    pid = next(iter(data.state.participants))
    held = Held(tmp_path, moment, ["protocol", "serve", str(data.folder), "--pilot", f"{pid}=blind"],
                "experimenter console:")
    assert held.ready.wait(300), "never ready"
    line = next(line for line in held.out + held.err if "experimenter console:" in line)
    base, token = line.split("experimenter console: ", 1)[1].strip().split("/console?token=")
    api(f"{base}/api/console/next", token, {})
    while (live := api(f"{base}/api/console/state", token)["live"]).get("round", 0) < 1:
        assert held.proc.poll() is None, "".join(held.out + held.err)
        time.sleep(0.05)  # (polling the console's state, as its page does: no assert on time)
    return held, f"{data.folder}/recordings/{live['session']}.mcap"


def test_a_second_sigterm_as_serve_stops_a_game_names_its_recording(tmp_path):
    held, recording = serving(tmp_path, "recorder-whole")
    code, err = held.run(signal.SIGTERM, signal.SIGTERM)
    assert code == 143, err
    assert err[-1].startswith(f"pairplay protocol serve: interrupted again (SIGTERM) while stopping; {recording} was "
                              "finished before it: the recording is whole ("), err
    assert whole(tmp_path / recording)
    assert "Traceback" not in "".join(err), err


def test_one_ctrl_c_on_serve_mid_game_names_the_game_it_stopped(tmp_path):
    held, recording = serving(tmp_path, "never")
    held.proc.send_signal(signal.SIGINT)
    code = held.proc.wait(300)
    for r in held.readers:
        r.join(10)
    err = [line.rstrip("\n") for line in held.err]
    session = recording.rsplit("/", 1)[1].removesuffix(".mcap")
    assert code == 130, err
    assert err[-1].startswith(f"pairplay protocol serve: stopped (Ctrl-C); game {session} stopped after "), err
    assert "of 100 rounds, journaled aborted (interrupted (SIGINT)); recorded " in err[-1], err
    assert err[-1].endswith(f"events to {recording}"), err
    assert whole(tmp_path / recording)


def piloting(tmp_path, moments: str) -> tuple[subprocess.Popen, list[str], str]:
    """A `protocol pilot` of one participant held at `moments` (pairplay/testpause.py: `;`-joined, each let go by
    `go-<moment>` in tmp_path); (process, its stderr lines as they come, its first game's recording)."""
    data = study_with(tmp_path, LONG)
    session = data.session_id(next(iter(data.state.participants)), "phase1", 0)
    env = dict(os.environ, PYTHONUNBUFFERED="1",
               PAIRPLAY_TEST_PAUSE=";".join(f"{m}:{tmp_path / f'go-{m}'}" for m in moments.split(";")))
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "pilot", str(data.folder), "--personas",
                             "blind"], cwd=tmp_path, env=env, text=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    return proc, iter(proc.stderr), f"{data.folder}/recordings/{session}.mcap"


def held_at(proc, err, moment: str, tmp_path, sig: int) -> None:
    """Wait until `proc` says it is held at `moment`, send `sig`, let it go."""
    assert next(line for line in err if line.startswith("pairplay-test:")) == f"pairplay-test: paused at {moment}\n"
    proc.send_signal(sig)
    (tmp_path / f"go-{moment}").touch()


def test_a_second_ctrl_c_as_pilot_stops_a_game_names_its_recording(tmp_path):
    proc, err, recording = piloting(tmp_path, "game-set-up;recorder-whole")
    held_at(proc, err, "game-set-up", tmp_path, signal.SIGINT)  # the first: the game stops
    held_at(proc, err, "recorder-whole", tmp_path, signal.SIGINT)  # the second, as its recording is finished
    said = [line.rstrip("\n") for line in err]
    assert proc.wait(300) == 130, said
    assert said[-1].startswith(f"pairplay protocol pilot: interrupted again (Ctrl-C) while stopping; {recording} was "
                               "finished before it: the recording is whole"), said
    assert whole(Path(recording))


def test_one_ctrl_c_on_pilot_as_a_game_starts_names_the_game_it_stopped(tmp_path):
    proc, err, recording = piloting(tmp_path, "game-set-up")
    held_at(proc, err, "game-set-up", tmp_path, signal.SIGINT)
    said = [line.rstrip("\n") for line in err]
    session = recording.rsplit("/", 1)[1].removesuffix(".mcap")
    assert proc.wait(300) == 130, said
    assert said[-1].startswith(f"pairplay protocol pilot: interrupted (Ctrl-C); game {session} stopped before it "
                               "started, journaled aborted (interrupted (SIGINT)); recorded "), said
    assert f" to {recording}; `pairplay protocol status " in said[-1], said
    assert whole(Path(recording))


def test_the_lines_main_says_without_parsed_arguments_name_a_sub_verb_whole():
    """cli/main.py's lines of a signal as the verb loaded, or once it had finished, named `protocol` of
    `protocol serve` (as its handler of a verb's KeyboardInterrupt did, now `_who`)."""
    from pairplay.cli.main import _named

    assert _named(["protocol", "serve", "folder", "--pilot", "p01=blind"]) == "protocol serve"
    assert _named(["participant", "export", "x"]) == "participant export"
    assert _named(["protocol", "--help"]) == "protocol"
    assert _named(["session", "--rounds", "3"]) == "session"
    assert _named(["nonsense"]) == "" and _named([]) == ""
