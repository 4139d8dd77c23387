"""A SessionConfig's every field alone is checked where the config is made, and where it is decoded.

Before, msgspec's constructor checked nothing: `pairplay.SessionConfig(rounds="20")` was taken and refused only
when run_session ran (tests/test_python_api.py has those cases now), and a recording or a message whose
SessionStarted held a config out of range (rounds 0) was taken by the reader and the recorder: `pairplay replay
--verify` of such a file was a traceback (validate's ValueError), `rebuild` rebuilt it, exit 0. Now its
`__post_init__` (schemas/public.py rule) refuses it as malformed input: a verb says in one line that the file's
SessionStarted does not decode and why; the live recorder refuses it and records the refusal. Every config a
pairplay recorded (recordings/samples: the formats and versions we keep) still decodes.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from pairplay.replay.reader import read_any_log, read_log
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import events as ev
from pairplay.schemas.events import decode_event
from pairplay.schemas.keys import event_key

from busutil import collect, listener, recorder_process

SAMPLES = sorted((Path(__file__).parent.parent / "recordings" / "samples").glob("*.mcap"))


@pytest.mark.parametrize("sample", SAMPLES, ids=[p.name for p in SAMPLES])
def test_every_recorded_config_we_keep_still_decodes(sample):
    log = read_log(sample)
    assert not log.bad, log.bad
    [start] = log.of("SessionStarted")
    assert start.config.rounds >= 1


def with_rounds_zero(payload: bytes) -> bytes:
    """A SessionStarted's JSON, its config's rounds 0 (no SessionConfig can be made so: written as bytes)."""
    data = json.loads(payload)
    data["config"]["rounds"] = 0
    return json.dumps(data, separators=(",", ":")).encode()


def test_a_recording_whose_config_is_out_of_range_is_refused_in_one_line(tmp_path):
    source = read_log(next(p for p in SAMPLES if p.name == "sim-ashley-fmt2.mcap"))
    path = tmp_path / "zero.mcap"
    writer = EventLogWriter(path)
    for name, data in source.metadata.items():
        writer.add_metadata(name, data)
    for r in source.events:
        payload = with_rounds_zero(r.payload) if r.key.endswith("/SessionStarted") else r.payload
        writer.write(r.key, payload, log_time_ns=r.log_time_ns)
    writer.close()
    for verb in (["replay", "--verify"], ["rebuild"]):
        ran = subprocess.run([sys.executable, "-m", "pairplay", *verb, str(path)], cwd=tmp_path, text=True,
                             capture_output=True, timeout=120)
        assert ran.returncode == 2, (verb, ran.stdout, ran.stderr)
        [line] = ran.stderr.splitlines()
        assert "SessionStarted: rounds must be >= 1, got 0" in line and "Traceback" not in ran.stderr, line
    assert not (tmp_path / "rebuilt").exists()


def test_a_message_whose_config_is_out_of_range_is_refused_and_recorded_by_the_recorder(tmp_path):
    """A real `pairplay run recorder` on a real bus: a SessionStarted claiming the game, its config's rounds 0."""
    from test_forge import forge

    from pairplay.schemas.session import SessionConfig

    s = "zero"
    config = SessionConfig(session=s, participant="sim:ashley", persona="ashley", seed=1, rounds=3)
    key, payload = forge(s, ev.SessionStarted(config=config), 1)
    with listener() as bus, recorder_process(bus, s, tmp_path) as proc:
        refusals = collect(bus, event_key(s, "recorder", "MessageRejected"))
        bus.put(key, with_rounds_zero(payload))
        refusal = decode_event(refusals.get(timeout=60)[1])
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 143
    assert refusal.key == key and "rounds must be >= 1, got 0" in refusal.reason, refusal
    log = read_any_log(tmp_path / f"{s}.mcap")  # (a file of no session: what read_log refuses)
    assert not log.of("SessionStarted")
    assert len([e for e in log.of("MessageRejected") if e.key == key]) == 1  # (its seq unread: it does not decode)
