"""A recording from a newer pairplay, with event types this version does not know (issue 10, item 9):
verify counts and names them, and its verdict is about the events this version derives."""

import json

import msgspec
from mcap.writer import CompressionType, Writer

from pairplay.replay.reader import read_log
from pairplay.replay.rebuild import rebuild_recording
from pairplay.schemas import events as ev
from pairplay.schemas.events import encode_event
from pairplay.schemas.jsonschema import schema_text
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.verify import verify_recording

from loopback_session import loopback_events

NEWER = [("game", "RoundPaused", {"round": 0, "why": "break"}), ("robot", "RobotBlinked", {"eyes": 2}),
         ("robot", "RobotBlinked", {"eyes": 1}), ("learner", "PolicySnapshot", {"q": [[0.5]]})]


def write_newer(path, alter=None):
    """A session recorded by a 'newer' pairplay: every known event plus events of types unknown here."""
    config = SessionConfig(session="newer", participant="sim:blind", persona="blind", seed=2, rounds=2)
    events = loopback_events(config)
    if alter is not None:
        events = alter(events)
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="pairplay", library="pairplay 9.9")
        channels = {}

        def put(key, tag, schema, payload, t):
            if key not in channels:
                channels[key] = w.register_channel(key, "json", w.register_schema(tag, "jsonschema", schema))
            w.add_message(channels[key], t, payload, t)

        extra = iter(NEWER)
        for i, e in enumerate(events):
            tag = type(e).__name__
            put(event_key(e.session, e.source, tag), tag, schema_text(type(e)).encode(), encode_event(e), i)
            if i % 60 == 30:
                new = next(extra, None)
                if new is not None:
                    source, tag, fields = new
                    payload = json.dumps({"type": tag, **fields, "session": "newer", "source": source,
                                          "seq": 10_000 + i, "time_ns": i}).encode()
                    put(event_key("newer", source, tag), tag, b'{"type":"object"}', payload, i)
        w.finish()


def test_unknown_types_are_counted_and_named_and_the_verdict_is_about_known_ones(tmp_path, pairplay_cli):
    path = tmp_path / "newer.mcap"
    write_newer(path)
    log = read_log(path)
    assert not log.bad and log.unknown_types() == {"RoundPaused": 1, "RobotBlinked": 2, "PolicySnapshot": 1}
    v = verify_recording(path)
    assert v.ok and v.unknown == {"RoundPaused": 1, "RobotBlinked": 2, "PolicySnapshot": 1}
    assert rebuild_recording(path).fold.ended is not None
    r = pairplay_cli("replay", path, "--verify")
    assert r.returncode == 0 and "verify: PASS" in r.stdout, r.stdout + r.stderr
    assert "4 events of types this version does not know, not compared: PolicySnapshot (1), RobotBlinked (2), " \
           "RoundPaused (1)" in r.stdout


def test_a_derived_event_altered_beside_unknown_types_still_fails(tmp_path):
    def alter(events):
        i = next(i for i, e in enumerate(events) if isinstance(e, ev.QUpdated))
        events[i] = msgspec.structs.replace(events[i], q_after=events[i].q_after + 1.0)
        return events

    path = tmp_path / "newer-altered.mcap"
    write_newer(path, alter)
    v = verify_recording(path)
    assert not v.ok and v.unknown
    assert any(m.startswith("QUpdated seq") for c in v.checks for m in c.mismatches)


def test_only_a_well_formed_event_of_an_unknown_type_counts_as_unknown():
    from pairplay.replay.reader import unknown_tag

    assert unknown_tag(b'{"type":"RobotBlinked","session":"s","source":"robot","seq":1,"time_ns":5}') == "RobotBlinked"
    assert unknown_tag(b'{"type":"CardPicked","round":"x"}') is None  # a known type that does not decode: bad
    assert unknown_tag(b'[1, 2]') is None and unknown_tag(b'{"type": 3}') is None and unknown_tag(b"{not json") is None
    assert unknown_tag(b'{"no_type": 1}') is None and unknown_tag(b'{"type":""}') is None
