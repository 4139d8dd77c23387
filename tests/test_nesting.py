"""A value nested too deeply is malformed input, refused and recorded like any other (schemas/nesting.py).

A hostile user's trial (trial28 F18): one 9 KB message, `{"a":` 1,500 times, put on a live session's keys made msgspec
raise RecursionError, which nothing caught: the recorder died ("recorder error RecursionError"), the robot bridge's
thread died, the learner logged a traceback, the session stopped with its recording cut; `pairplay recover` then died
on the same message in the journal, so the session's end could not be added. Every decoder of outside data turns it
into the library's own DecodeError now, so every caller refuses it where it refused any malformed input.
"""

from __future__ import annotations

import json
import threading
import tomllib

import msgspec
import numpy as np
import pytest

from pairplay.replay.reader import read_log
from pairplay.replay.wal import JournalWriter
from pairplay.schemas import events as ev
from pairplay.schemas.keys import alive_key, event_key
from pairplay.services.session import run_session

from busutil import connector, wait_until
from damageutil import small_chunked_session
from test_bus_bad_input import CLEAN_Q, CONFIG, SESSION

DEEP_OBJECT = b'{"a":' * 1500 + b"1" + b"}" * 1500  # 9,001 bytes: under the bus's payload limit
DEEP_ARRAY = b"[" * 3000 + b"]" * 3000


def test_every_decoder_of_outside_data_says_too_deep_in_its_own_error():
    from pairplay.schemas import nesting
    from pairplay.schemas.checked import check_event
    from pairplay.schemas.events import decode_event
    from pairplay.schemas.journal import decode_line

    in_a_field = b'{"type":"CardPicked","round":0,"turn":0,"card":1,"x":' + DEEP_OBJECT + b"}"  # skipped: recursed too
    for decode in (decode_event, check_event, decode_line, nesting.JsonDecoder().decode, nesting.json_decode):
        for payload in (DEEP_OBJECT, in_a_field):
            with pytest.raises(msgspec.DecodeError, match="nested too deeply"):
                decode(payload)
    with pytest.raises(msgspec.DecodeError, match="nested too deeply"):
        nesting.json_decode(DEEP_ARRAY)
    with pytest.raises(msgspec.DecodeError, match="nested too deeply"):
        nesting.msgpack_decode(b"\x91" * 3000 + b"\x01")
    with pytest.raises(json.JSONDecodeError, match="nested too deeply"):
        nesting.json_loads(DEEP_ARRAY)
    with pytest.raises(tomllib.TOMLDecodeError, match="nested too deeply"):
        nesting.toml_loads("a = " + "[" * 3000 + "]" * 3000)


def test_deeply_nested_messages_on_a_live_session_are_rejected_recorded_and_the_session_plays_on(tmp_path):
    path = tmp_path / "bad1.mcap"
    box, ready, failed = {}, threading.Event(), []

    def on_bus(bus):
        box["bus"] = bus
        ready.set()

    def run():
        try:
            run_session(CONFIG, path, on_bus=on_bus, nodes_out=box, wait_also=("intruder",))
        except BaseException as err:  # noqa: BLE001 - said by the assertion below
            failed.append(err)

    runner = threading.Thread(target=run)  # the game waits for the intruder's token: the messages land first
    runner.start()
    assert ready.wait(10)
    keys = [event_key(SESSION, source, tag) for source, tag in (("participant", "CardPicked"), ("game", "TurnResolved"),
                                                                ("learner", "SuggestionMade"), ("board", "CardPicked"),
                                                                ("robot", "RobotActed"))]
    with connector(box["bus"]) as intruder:
        everyone = {alive_key(SESSION, s) for s in ("recorder", "learner", "participant", "game")}
        assert wait_until(lambda: everyone <= intruder.alive_now(alive_key(SESSION, "*")))
        for key in keys:
            intruder.put(key, DEEP_OBJECT)
            intruder.put(key, DEEP_ARRAY)
        intruder.alive(alive_key(SESSION, "intruder"))
        runner.join(60)
    assert not runner.is_alive() and not failed, failed
    assert np.array_equal(box["learner"].logic.learner.q, CLEAN_Q)  # it learned what a clean session learns
    recorded = read_log(path)
    assert not recorded.truncated and not recorded.bad
    ended = [r.event for r in recorded.events if isinstance(r.event, ev.SessionEnded)]
    assert [e.reason for e in ended] == ["completed"]
    rejected = [r.event for r in recorded.events if isinstance(r.event, ev.MessageRejected)]
    assert sum("nested too deeply" in r.reason for r in rejected) >= len(keys) * 2, [r.reason for r in rejected]


def test_recover_adds_a_cut_sessions_end_past_a_deeply_nested_message_in_its_journal(tmp_path_factory, tmp_path,
                                                                                     pairplay_cli):
    whole = small_chunked_session(tmp_path_factory.mktemp("deep") / "whole.mcap", "left")
    path = tmp_path / "left.mcap"
    data = whole.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    records = read_log(whole).events
    j = JournalWriter(path, "left")
    for n, r in enumerate(records):
        if n == len(records) // 2:
            j.add((event_key("left", "participant", "CardPicked"), DEEP_OBJECT))
        j.add((r.key, r.payload))
    j.close()
    ran = pairplay_cli("recover", path, cwd=tmp_path)
    assert ran.returncode == 0 and "Traceback" not in ran.stderr, (ran.stdout, ran.stderr)
    recovered = read_log(tmp_path / "left.recovered.mcap")
    assert any(isinstance(r.event, ev.SessionEnded) for r in recovered.events)
