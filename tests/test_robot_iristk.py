"""The IrisTK broker client: the wire protocol of appendix D, against a broker and a Furhat double."""

from __future__ import annotations

import dataclasses
import json
import time

import msgspec
import pytest
from robot_doubles.harness import FAMILIES, FAST, OBSERVED, TARGET, Collector, suggestion
from robot_doubles.iristk_broker import IrisTKBroker, name_filter_matches
from robot_doubles.iristk_furhat import IrisTKFurhat, valid_time

from pairplay.core.actions import code_of_parts
from pairplay.core.geometry import card_col, card_row
from pairplay.services.robot import open_robot
from pairplay.services.robot.calibration import load_calibration
from pairplay.services.robot.transport import Wire
from pairplay.services.robot.iristk_protocol import (
    BadFrame, EventFrame, FrameReader, Line, NameFilter, event_frame, event_time, make_event,
)

CALIBRATION = load_calibration()
EXACT = code_of_parts(2, 0, 0, 0)


# -- the wire format --------------------------------------------------------------------------
def test_an_event_frame_counts_the_trailing_newline_and_reads_back_byte_by_byte():
    event = make_event("action.speech", "id-1", "pairplay", 0, text="Maybe up, héhé", abort=True)
    frame = event_frame(event)
    header, body = frame.split(b"\n", 1)
    assert header == f"EVENT action.speech {len(body)}".encode() and body.endswith(b"}\n")
    reader = FrameReader()
    frames = [f for byte in frame + b"CONNECTED\n" for f in reader.feed(bytes([byte]))]
    assert frames == [EventFrame("action.speech", body[:-1]), Line("CONNECTED")]
    assert json.loads(frames[0].payload) == event


def test_a_count_that_leaves_the_newline_out_is_read_too():
    payload = b'{"event_name":"monitor.speech.end"}'
    frames = FrameReader().feed(f"EVENT monitor.speech.end {len(payload)}\n".encode() + payload + b"\nCONNECTED\n")
    assert frames == [EventFrame("monitor.speech.end", payload), Line("CONNECTED")]


def test_bad_headers_cost_their_line_only():
    frames = FrameReader().feed(b"EVENT x abc\nEVENT\nEVENT a 1 2\n\xff\xfe\nEVENT ok 3\n{}\n")
    assert [type(f) for f in frames] == [BadFrame, BadFrame, BadFrame, BadFrame, EventFrame]
    assert frames[-1] == EventFrame("ok", b"{}")


def test_events_carry_the_class_a_java_time_and_no_nulls():
    event = make_event("action.gesture", "id", "pairplay", 1_700_000_000_123_456_789, name="nod", agent=None)
    assert event["class"] == "iristk.system.Event" and "agent" not in event
    assert valid_time(event["event_time"]) and event["event_time"].endswith(".123")
    assert valid_time(event_time(0))


@pytest.mark.parametrize("spec, name, expected", [
    ("**", "action.speech", True), ("action.**", "action.speech.stop", True),
    ("action.*", "action.speech", True), ("action.*", "action.speech.stop", False),
    ("monitor.**", "action.speech", False), ("action.**;!action.speech", "action.speech", False),
    ("action.**;!action.speech", "action.gaze", True), ("sense.*;action.gaze", "action.gaze", True),
    ("!monitor.**", "action.gaze", True), ("", "action.speech", False),
])
def test_name_filters_agree_with_the_broker_double(spec, name, expected):
    assert NameFilter(spec).matches(name) is expected
    if spec:  # the double's independent matcher says the same
        assert name_filter_matches(spec, name) is expected


# -- against the broker and the Furhat doubles -------------------------------------------------
@pytest.fixture
def stage():
    broker = IrisTKBroker().start()
    furhat = IrisTKFurhat(broker.port).start()
    collector = Collector()
    drivers = []

    def robot(url=None, config=FAST):
        driver = open_robot(url or f"iristk://127.0.0.1:{broker.port}", collector.on_acted, config=config,
                            calibration=CALIBRATION, on_rejected=collector.on_rejected)
        drivers.append(driver)
        return driver

    yield broker, furhat, collector, robot
    for driver in drivers:
        driver.close()
    furhat.close()
    broker.stop()


def performed(furhat, name):
    return [e for n, e in furhat.performed if n == name]


def test_handshake_connect_subscribe_and_close(stage):
    broker, furhat, collector, robot = stage
    driver = robot()
    assert broker.wait_for(lambda b: ("pairplay", "monitor.**") in b.subscribes)
    assert ("furhat", "pairplay") in broker.connects
    # the broker told us what the robot listens to, before CONNECTED: taken as information
    assert driver.transport.broker_filter == "action.**"
    driver.close()
    assert broker.wait_for(lambda b: "pairplay" in b.closes)
    assert broker.illegal == []


@pytest.mark.parametrize("family", list(FAMILIES))
def test_each_family_reaches_the_robot_as_iristk_events(stage, family):
    broker, furhat, collector, robot = stage
    driver = robot()
    driver.perform(suggestion(FAMILIES[family], seq=7))
    assert driver.wait_idle(5)
    (acted,) = collector.acted
    assert acted.suggestion_seq == 7 and acted.backend == f"iristk://127.0.0.1:{broker.port}"
    # gazes promise no reply: RobotActed may come before the robot has read them
    assert furhat.wait_for(lambda f: len(f.performed) == len(acted.commands))
    events = [e for _, e in furhat.performed]
    card, target, rest = CALIBRATION.cards[OBSERVED], CALIBRATION.cards[TARGET], CALIBRATION.rest
    if family == "exact speech":
        (say,) = events
        assert say["text"] == f"Try at row {card_row(TARGET) + 1} and column {card_col(TARGET) + 1}" and say["abort"] is True
        assert acted.outcome == "done" and acted.replies == ["monitor.speech.start", "monitor.speech.end"]
    elif family == "direction speech":
        assert [e["text"] for e in events] == ["Maybe right"]
    elif family == "smile":
        assert [(e["event_name"], e["name"]) for e in events] == [("action.gesture", "smile")]
        assert acted.outcome == "done" and acted.replies == ["monitor.gesture.end"]
    elif family == "nod":
        gaze, nod = events
        assert gaze["location"] == {"class": "iristk.util.Location", "x": card.x, "y": card.y, "z": card.z}
        assert gaze["mode"] == "default" and nod["name"] == "nod"
    elif family == "head turn":
        assert [e["event_name"] for e in events] == ["action.gaze"] * 3
        assert all(e["mode"] == "headpose" for e in events)
        assert (events[0]["location"]["x"], events[-1]["location"]["z"]) == (card.x, rest.z)
        assert events[1]["location"]["x"] > card.x  # turn right: towards column 5, +x in this calibration
        assert acted.outcome == "sent"
    elif family == "gaze":
        (gaze,) = events
        assert (gaze["location"]["x"], gaze["location"]["z"]) == (target.x, target.z)
    assert len(acted.commands) == len(events) and furhat.dropped == []
    # what RobotActed records is what went on the wire, byte for byte
    assert [json.loads(c.split("\n", 1)[1]) for c in acted.commands] == events
    for relayed in broker.events:
        assert relayed.declared == len(relayed.payload) and relayed.payload.endswith(b"\n")
    assert broker.illegal == []


def test_robot_replies_are_matched_by_event_id_into_robot_acted(stage):
    broker, furhat, collector, robot = stage
    driver = robot()
    driver.perform(suggestion(code_of_parts(2, 0, 1, 0)))  # exact speech + nod
    assert driver.wait_idle(5)
    (acted,) = collector.acted
    speech = performed(furhat, "action.speech")[0]
    acks = {r["event_name"]: r["action"] for r in furhat.replies}
    assert acks["monitor.speech.start"] == speech["event_id"] == acks["monitor.speech.end"]
    assert sorted(acted.replies) == ["monitor.gesture.end", "monitor.speech.end", "monitor.speech.start"]
    assert 0 < acted.received_ns <= acted.sent_ns <= acted.acked_ns <= acted.done_ns


def test_a_new_suggestion_aborts_the_speech_still_playing(stage):
    broker, furhat, collector, robot = stage
    furhat.speech_s = 5.0  # long speech: still playing when the next suggestion comes
    driver = robot()
    driver.perform(suggestion(EXACT, attempt=0, seq=1))
    assert furhat.wait_for(lambda f: len(f.replies) == 1)  # speech started
    driver.perform(suggestion(code_of_parts(0, 1, 0, 0), attempt=1, seq=2))  # smile: no speech of its own
    driver.perform(suggestion(code_of_parts(3, 0, 0, 0), attempt=2, seq=3))  # "Maybe up": aborts by itself
    assert furhat.wait_for(lambda f: len(performed(f, "action.speech")) == 2)
    names = [n for n, _ in furhat.performed]
    assert names == ["action.speech", "action.speech.stop", "action.gesture", "action.speech"]
    assert performed(furhat, "action.speech")[1]["abort"] is True
    assert collector.wait_for(lambda c: {1, 2} <= set(c.by_seq()))
    assert collector.by_seq()[1].outcome == "aborted"
    assert collector.by_seq()[1].replies == ["monitor.speech.start"]


def until(condition, timeout: float = 5.0) -> bool:
    """Poll a condition that nothing signals (the driver's connection state)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def test_broker_drop_mid_session_loses_and_repeats_nothing(stage):
    broker, furhat, collector, robot = stage
    driver = robot()
    targets = [c for c in range(18) if c != OBSERVED][:12]

    def suggest(i: int, wait: bool = True) -> None:
        driver.perform(dataclasses.replace(suggestion(EXACT, seq=i), target=targets[i]))
        if wait:
            assert collector.wait_for(lambda c: len(c.acted) == i + 1)

    for i in range(4):
        suggest(i)
    broker.drop_all()  # the broker cuts every connection mid-session
    for i in range(4, 8):
        suggest(i)
    broker.stop()  # the broker is down for a while: suggestions wait, the client retries
    assert until(lambda: not driver.connected)
    suggest(8, wait=False)
    suggest(9, wait=False)
    broker.start()  # ... and comes back on the same port
    for i in range(10, 12):
        suggest(i, wait=False)
    assert collector.wait_for(lambda c: len(c.acted) == len(targets), timeout=10)
    texts = [e["text"] for e in performed(furhat, "action.speech")]
    expected = [f"Try at row {card_row(t) + 1} and column {card_col(t) + 1}" for t in targets]
    assert texts == expected  # every suggestion once, in order
    ids = [e["event_id"] for _, e in furhat.performed]
    assert len(ids) == len(set(ids))
    assert driver.reconnects >= 2 and furhat.joins >= 3
    by_seq = collector.by_seq()
    assert all(by_seq[i].outcome == "done" for i in range(8))
    assert by_seq[8].reconnects == 1 and by_seq[8].commands  # held while down, sent after


def test_malformed_frames_from_the_robot_side_are_reported_and_skipped(stage):
    broker, furhat, collector, robot = stage
    driver = robot()
    assert broker.wait_for(lambda b: ("pairplay", "monitor.**") in b.subscribes)
    broker.inject("pairplay", b"HELLO there\nEVENT monitor.speech.start abc\n")
    broker.inject("pairplay", b"EVENT monitor.speech.start 9\nnot json\nEVENT monitor.speech.end 3\n[]\n")
    assert collector.wait_for(lambda c: len(c.rejected) == 4)
    driver.perform(suggestion(EXACT))
    assert driver.wait_idle(5)
    assert collector.acted[0].outcome == "done" and driver.reconnects == 0
    reasons = " | ".join(r for r, _ in collector.rejected)
    assert "unknown line" in reasons and "EVENT header" in reasons and "not JSON" in reasons


def test_an_unknown_ticket_fails_with_the_reason(stage):
    broker, furhat, collector, robot = stage
    config = msgspec.structs.replace(FAST, iristk_ticket="lab", give_up_s=0.3)
    driver = robot(config=config)
    driver.perform(suggestion(EXACT))
    assert driver.wait_idle(5)
    (acted,) = collector.acted
    assert acted.outcome == "failed" and "CONNECT" in acted.error and acted.commands == []


def test_events_wait_until_the_robot_has_joined_the_broker(stage):
    broker, furhat, collector, robot = stage
    furhat.close()
    assert broker.wait_for(lambda b: len(b.clients) == 0)
    driver = robot()
    driver.perform(suggestion(EXACT))
    assert broker.wait_for(lambda b: ("pairplay", "monitor.**") in b.subscribes)
    assert collector.acted == [] and broker.events == []  # held: nobody would hear it
    late = IrisTKFurhat(broker.port).start()
    try:
        assert driver.wait_idle(5)
        assert collector.acted[0].outcome == "done" and len(performed(late, "action.speech")) == 1
    finally:
        late.close()


def test_an_unreachable_broker_fails_the_suggestion_with_the_reason(stage):
    broker, furhat, collector, robot = stage
    broker.stop()
    driver = robot(config=msgspec.structs.replace(FAST, give_up_s=0.3))
    driver.perform(suggestion(EXACT))
    assert driver.wait_idle(5)
    assert collector.acted[0].outcome == "failed" and "unreachable" in collector.acted[0].error


def test_the_brokers_word_is_information_events_go_after_the_wait(stage):
    broker, furhat, collector, robot = stage
    furhat.close()
    assert broker.wait_for(lambda b: len(b.clients) == 0)
    config = msgspec.structs.replace(FAST, iristk_subscriber_wait_s=0.1, ack_timeout_s=0.3)
    driver = robot(config=config)
    driver.perform(suggestion(EXACT))
    assert broker.wait_for(lambda b: [e.name for e in b.events] == ["action.speech"])
    assert driver.wait_idle(5)
    assert collector.acted[0].outcome == "unacknowledged" and collector.acted[0].commands


def test_a_broker_filter_that_proved_wrong_holds_nothing_again(stage):
    broker, furhat, collector, robot = stage
    furhat.close()
    assert broker.wait_for(lambda b: len(b.clients) == 0)
    config = msgspec.structs.replace(FAST, iristk_subscriber_wait_s=0.2, ack_timeout_s=0.3)
    driver = robot(config=config)
    gaze = Wire(b"", "", (), "action.gaze")
    assert broker.wait_for(lambda b: ("pairplay", "monitor.**") in b.subscribes)
    assert driver.transport.ready(gaze)  # the broker says nobody listens: it would be held
    driver.perform(suggestion(EXACT, seq=1))
    assert driver.wait_idle(5)  # held for the wait, then sent anyway
    assert driver.transport.ready(gaze) == ""  # that filter is not trusted again


def test_a_distrusted_filter_is_believed_again_once_the_broker_changes_it(stage):
    broker, furhat, collector, robot = stage
    furhat.close()
    assert broker.wait_for(lambda b: len(b.clients) == 0)
    driver = robot(config=msgspec.structs.replace(FAST, iristk_subscriber_wait_s=0.1, ack_timeout_s=0.3))
    gaze = Wire(b"", "", (), "action.gaze")
    driver.perform(suggestion(EXACT, seq=1))
    assert driver.wait_idle(5)
    assert driver.transport.ready(gaze) == ""  # "" (nobody) proved wrong once
    late = IrisTKFurhat(broker.port).start()  # the robot joins: the broker's filter changes ...
    try:
        assert until(lambda: driver.transport.broker_filter == "action.**")
        late.close()  # ... and it leaves again: "nobody" is believed again
        assert broker.wait_for(lambda b: len(b.clients) == 1)
        assert until(lambda: driver.transport.broker_filter == "")
        assert driver.transport.ready(gaze)
    finally:
        late.close()


def test_an_acknowledgement_still_awaited_when_the_session_ends_is_recorded_in_flight(stage):
    """Issue 10 item 6: the bridge closing (end of session, a signal) with a reply still due says so."""
    broker, furhat, collector, robot = stage
    furhat.close()  # nobody will acknowledge
    assert broker.wait_for(lambda b: len(b.clients) == 0)
    driver = robot(config=msgspec.structs.replace(FAST, iristk_subscriber_wait_s=0.1, ack_timeout_s=30.0))
    driver.perform(suggestion(EXACT))
    assert broker.wait_for(lambda b: [e.name for e in b.events] == ["action.speech"])
    driver.close()
    acted = collector.acted[0]
    assert acted.outcome == "in-flight" and acted.commands and "acknowledgement was awaited" in acted.error
