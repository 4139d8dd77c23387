"""Times in the JSON are the MCAP/Foxglove time object, so JavaScript readers do not round them; old files
with integer times still read; the recorder's log and publish times are its own (issue 10, item 13)."""

import json
import threading
from pathlib import Path

import pytest
from mcap.reader import make_reader

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import Nanos, nanos_from_json, stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.schemas.keys import alive_key, event_key
from pairplay.schemas.robot import RobotActed
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.session import run_session

SAMPLES = Path(__file__).resolve().parent.parent / "recordings" / "samples"
JS_SAFE = 2**53


def numbers(node):
    if isinstance(node, bool):
        return
    if isinstance(node, (int, float)):
        yield node
    elif isinstance(node, dict):
        for v in node.values():
            yield from numbers(v)
    elif isinstance(node, list):
        for v in node:
            yield from numbers(v)


def test_times_encode_as_sec_nsec_and_read_back_exactly():
    t = 1_796_016_860_539_442_142
    e = stamped(ev.CardPicked(round=0, turn=0, card=3), session="s", source="participant", seq=1, time_ns=t)
    data = json.loads(encode_event(e))
    assert data["time_ns"] == {"sec": 1_796_016_860, "nsec": 539_442_142}
    assert decode_event(encode_event(e)).time_ns == t
    r = RobotActed(round=0, turn=0, attempt=0, action=1, backend="virtual", outcome="done", sent_ns=t, done_ns=t + 1)
    data = json.loads(encode_event(r))
    assert data["sent_ns"] == {"sec": 1_796_016_860, "nsec": 539_442_142} and data["received_ns"] == 0
    assert decode_event(encode_event(r)).done_ns == t + 1


def test_old_integer_times_still_read_and_bad_ones_are_refused():
    old = b'{"type":"CardPicked","round":0,"turn":0,"card":3,"session":"s","source":"p","seq":1,' \
          b'"time_ns":1796016860539442142}'
    assert decode_event(old).time_ns == 1796016860539442142
    for bad in ({"sec": 1, "nsec": 10**9}, {"sec": 1}, {"sec": 1, "nsec": -1}, {"sec": 1, "nsec": 2, "x": 3}, "5",
                {"sec": True, "nsec": 0}):
        with pytest.raises(ValueError):
            nanos_from_json(bad)
    with pytest.raises(Exception):
        decode_event(old.replace(b"1796016860539442142", b'{"sec":1,"nsec":1000000000}'))
    assert repr(Nanos(5)) == "5"


def js_rounded(path):
    """How many numbers in the recording's JSON payloads a JavaScript reader would round (> 2**53)."""
    n = 0
    with open(path, "rb") as f:
        for _, _, m in make_reader(f).iter_messages():
            n += sum(1 for x in numbers(json.loads(m.data)) if abs(x) > JS_SAFE)
    return n


def test_a_bus_session_has_no_number_a_javascript_reader_rounds_and_the_recorder_keeps_its_own_times(tmp_path):
    config = SessionConfig(session="jst", participant="sim:ashley", persona="ashley", seed=7, rounds=2, streams=2)
    ready, box = threading.Event(), {}

    def on_bus(bus):
        box["bus"] = bus
        ready.set()

    t = threading.Thread(target=lambda: box.setdefault("path", run_session(config, tmp_path / "jst.mcap",
                                                                          on_bus=on_bus, wait_also=("forger",))))
    t.start()
    assert ready.wait(10)
    with Bus(BusOptions(listen=[], connect=box["bus"].locators())) as forger:
        while alive_key("jst", "game") not in forger.alive_now(alive_key("jst", "*")) and t.is_alive():
            pass
        forged = stamped(ev.QuestionnaireAnswered(questionnaire="q", answers={}), session="jst", source="board",
                         seq=1, time_ns=1)  # an envelope that claims 1 ns
        forger.put(event_key("jst", "board", "QuestionnaireAnswered"), encode_event(forged))
        forger.alive(alive_key("jst", "forger"))
        t.join(60)
    path = box["path"]
    assert js_rounded(path) == 0
    with open(path, "rb") as f:
        messages = [m for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    logs = [m.log_time for m in messages]
    assert logs == sorted(logs)  # one clock, monotonic in the file
    assert all(m.publish_time == m.log_time for m in messages)  # never a time from an envelope
    assert min(m.publish_time for m in messages) > 10**18
    assert any(r.event.time_ns == 1 for r in read_log(path).events)  # the claim stays in the payload


@pytest.mark.parametrize("name", ["sim-ashley-fmt2.mcap", "human-board-fmt2.mcap", "catalogue-fmt2.mcap"])
def test_samples_of_the_fixed_code_have_exact_times_one_clock_and_metadata(name):
    path = SAMPLES / name
    assert js_rounded(path) == 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        messages = [m for _, _, m in reader.iter_messages(log_time_order=False)]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    logs = [m.log_time for m in messages]
    assert logs == sorted(logs) and all(m.publish_time == m.log_time for m in messages)
    assert metadata["pairplay.session"]["streams"] == "2"


def test_the_old_samples_keep_their_faults_and_still_read():
    """Format-1 samples are compatibility tests: integer times (rounded by JavaScript), the human sample's two
    clocks, the intruder's 1 ns publish time, no metadata in the catalogue."""
    assert js_rounded(SAMPLES / "sim-ashley.mcap") > 0
    with open(SAMPLES / "human-board.mcap", "rb") as f:
        logs = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert logs != sorted(logs)
    with open(SAMPLES / "sim-ashley.mcap", "rb") as f:
        assert min(m.publish_time for _, _, m in make_reader(f).iter_messages()) == 1
    assert read_log(SAMPLES / "catalogue.mcap").metadata == {}
    for name in ("sim-ashley.mcap", "human-board.mcap", "catalogue.mcap"):
        assert read_log(SAMPLES / name).whole
