"""The bus contract: every event round-trips, carries its tag, and validates
against its committed, flattened JSON Schema."""

import json

import jsonschema
import msgspec
import pytest

from pairplay.schemas import keys
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import (
    EVENT_BY_TAG, EVENT_TYPES, CardPicked, SessionStarted, decode_event, encode_event,
)
from pairplay.schemas.jsonschema import JSON_DIR, flat_schema, schema_text
from pairplay.schemas.session import SessionConfig


def test_every_tag_is_the_class_name():
    for t in EVENT_TYPES:
        assert t.__struct_config__.tag == t.__name__
    assert len(EVENT_BY_TAG) == len(EVENT_TYPES)


def test_stamped_event_round_trips_with_its_envelope():
    e = stamped(CardPicked(round=2, turn=3, card=17), session="s1", source="participant", seq=9, time_ns=123)
    payload = encode_event(e)
    assert json.loads(payload)["type"] == "CardPicked"
    assert decode_event(payload) == e


def test_unknown_fields_are_ignored_so_old_readers_read_new_recordings():
    payload = b'{"type":"CardPicked","round":0,"turn":0,"card":1,"added_later":true}'
    assert decode_event(payload).card == 1


@pytest.mark.parametrize("payload", [b"{", b'{"type":"Nope"}', b'{"type":"CardPicked","round":"x"}', b"[]"])
def test_bad_payloads_raise_with_a_reason(payload):
    with pytest.raises((msgspec.DecodeError, msgspec.ValidationError)) as err:
        decode_event(payload)
    assert str(err.value)


def test_committed_schemas_match_the_code_and_have_no_ref():
    for t in EVENT_TYPES:
        path = JSON_DIR / f"{t.__name__}.json"
        assert path.read_text() == schema_text(t), f"regenerate: python -m pairplay.schemas.jsonschema ({path.name})"
        assert "$ref" not in path.read_text()


def test_events_validate_against_their_schema():
    cfg = SessionConfig(session="s1", participant="sim:Deaf", persona="Deaf", seed=1, rounds=3)
    for e in (SessionStarted(config=cfg), CardPicked(round=0, turn=0, card=5)):
        jsonschema.validate(json.loads(encode_event(e)), flat_schema(type(e)))


def test_keys_are_built_and_parsed_and_bad_chunks_refused():
    k = keys.event_key("s1", "game", "RoundStarted")
    assert k == "pairplay/s1/game/RoundStarted"
    assert keys.parse_event_key(k) == ("s1", "game", "RoundStarted")
    for bad in ("a/b", "a*", "", "a b"):
        with pytest.raises(ValueError):
            keys.event_key(bad, "game", "X")
    with pytest.raises(ValueError):
        keys.parse_event_key("pairplay/s1/_query/recorder/log")


def test_session_config_validation_gives_reasons():
    with pytest.raises(ValueError, match="policy_actions"):
        SessionConfig(session="s", participant="sim:x", persona="x", seed=0, rounds=1, algorithm="fixed").validate()
    with pytest.raises(ValueError, match="rounds"):
        SessionConfig(session="s", participant="human:1", seed=0, rounds=0).validate()
