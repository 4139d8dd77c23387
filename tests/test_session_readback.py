"""`pairplay session` and `pairplay lab` read their own recording back for their summary through the reader every
verb uses (replay/reader.py): a recording that is not whole when read back (a damaged chunk, a cut, a message that
does not decode) is said in one line on stderr naming the file, and the verb exits 1.

Before, both summed up whatever the file held with no check: a session whose recording lost a chunk after it was
closed said "recorded N events", its rounds and exit 0, as a whole session. The damage here is real damage done to
the real recording a real session (or lab, on a real bus) has just finished, before the verb reads it back.
"""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from busutil import wait_until

from damageutil import damage, damaged_when_written

from pairplay.livelock import is_live
from pairplay.replay.reader import read_any_log, read_log

LINGER_S = 10  # the lab's pages show the end this long before it reads its recording back (the damage's time)
WORDS = {"chunk": "is not whole: damaged: chunk ", "cut": "is not whole: truncated: ",
         "undecodable": "is not whole: 1 message in it does not decode ("}


@pytest.mark.parametrize("how", ["chunk", "cut", "undecodable"])
def test_a_session_whose_recording_is_not_whole_when_read_back_says_so_and_exits_1(tmp_path, monkeypatch, capsys,
                                                                                    how):
    import pairplay.cli.session as cli_session
    from pairplay.cli.main import main

    damaged_when_written(monkeypatch, cli_session, how)  # the real one's recording, finished and closed
    code = main(["session", "--participant", "sim:blind", "--rounds", "2", "--session", "rb", "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    path = tmp_path / "rb.mcap"
    [line] = [x for x in err.splitlines() if x.startswith("pairplay session:")]
    assert line.startswith(f"pairplay session: the recording {path} read back ") and WORDS[how] in line, line
    assert "Traceback" not in err and code == 1, (code, err)
    assert f"recorded {len(read_log(path).events)} events to {path}" in out, out  # what it holds, counted


def test_a_lab_session_whose_recording_is_not_whole_when_read_back_says_so_and_exits_1(tmp_path):
    """A real `pairplay lab` process: its game is aborted by the experimenter's event on its bus, and while the
    pages linger its finished recording loses a chunk; the summary then reads it back.

    Before, the pages did not linger (run_session sets the lab's stop flag at its end, and the linger waited on
    that flag: services/lab/server.py `linger`), so the lab read its recording back ~1 s after the game's end,
    racing this damage: read while `write_bytes` had cut the file to nothing it said "truncated: ... (byte 0)"
    (CI, 1 run in 3). Now the lab is checked to be still lingering once the damage is done (whole at once:
    damageutil `_replace`), so its read-back comes after it, always."""
    from pairplay.schemas.events import SessionAborted, encode_event
    from pairplay.schemas.keys import event_key
    from pairplay.services.bus import Bus, BusOptions
    from pairplay.schemas.envelope import stamped

    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "lab", "--participant", "human:p9", "--session", "lb",
                             "--rounds", "1", "--linger", str(LINGER_S), "--out", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    path = tmp_path / "lb.mcap"
    try:
        lines = [proc.stdout.readline() for _ in range(4)]
        assert lines[3].startswith("bus listening on "), lines
        endpoint = lines[3].split()[3]
        with Bus(BusOptions(listen=[], connect=[endpoint])) as bus:
            # the game has started once its recording (flushed every 25 ms) holds its SessionStarted
            assert wait_until(lambda: path.is_file() and read_any_log(path).of("SessionStarted"), 30), "no game started"
            abort = stamped(SessionAborted(reason="the test ends it"), session="lb", source="experimenter", seq=1,
                            time_ns=time.time_ns())
            bus.put(event_key("lb", "experimenter", "SessionAborted"), encode_event(abort))
            # the session is over and its recording finished (its recorder gone): the pages linger 20 s
            assert wait_until(lambda: path.is_file() and not is_live(path)
                              and read_log(path).of("SessionEnded"), 30), "the recording was not finished"
            finished = time.monotonic()
        damage(path, "chunk")
        assert proc.poll() is None, "the lab did not linger: it read its recording back before the damage"
        out, err = proc.communicate(timeout=60)
        # it lingered (its end began before `finished`: 2 s for this test's polling and a loaded machine)
        assert time.monotonic() - finished >= LINGER_S - 2, time.monotonic() - finished
    finally:
        if proc.poll() is None:
            proc.kill()
    [line] = [x for x in err.splitlines() if x.startswith("pairplay lab:")]
    assert line.startswith(f"pairplay lab: the recording {path} read back ") and WORDS["chunk"] in line, line
    assert "Traceback" not in err and proc.returncode == 1, (proc.returncode, err)


def test_every_pairplay_command_a_message_names_is_a_verb():
    """The read-back line named `pairplay verify`, a verb that does not exist (it is `pairplay replay --verify`).
    Every `pairplay <word>` quoted in backticks in the CLI's and services' texts is a verb of the CLI."""
    import re
    from pathlib import Path

    from pairplay.cli.main import VERBS

    root = Path(__file__).resolve().parents[1]
    named = {(f.relative_to(root).as_posix(), m.group(1))
             for package in ("cli", "services", "replay", "report", "schemas", "pairplay")
             for f in (root / package).rglob("*.py")
             for m in re.finditer(r"`pairplay ([a-z][a-z-]*)", f.read_text(encoding="utf-8"))}
    assert named
    assert not [(f, verb) for f, verb in named if verb not in VERBS], [(f, v) for f, v in named if v not in VERBS]
