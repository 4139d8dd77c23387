"""schemas/checked.py: `check_event` takes exactly what `decode_event` takes (issue 16, the recorder's
decode), on every event type of the sample recordings and on hostile mutations of each of their fields."""

import json
from pathlib import Path

import msgspec
import pytest
from hypothesis import given, settings, strategies as st
from mcap.reader import make_reader

from pairplay.schemas.checked import CHECKED_BY_TAG, CheckedTimeObject, check_event
from pairplay.schemas.envelope import MAX_NS, Nanos
from pairplay.schemas.events import EVENT_BY_TAG, EVENT_TYPES, decode_event

SAMPLES = Path(__file__).resolve().parent.parent / "recordings" / "samples"
ENVELOPE = ("session", "source", "seq")


def _sample_payloads() -> dict[str, list[bytes]]:
    """Up to 3 payloads of every event type in the sample recordings (both JSON time formats)."""
    out: dict[str, list[bytes]] = {}
    for path in sorted(SAMPLES.glob("*.mcap")):
        with open(path, "rb") as f:
            for _schema, _channel, message in make_reader(f).iter_messages():
                tag = json.loads(message.data)["type"]
                if len(out.setdefault(tag, [])) < 3:
                    out[tag].append(message.data)
    return out


PAYLOADS = _sample_payloads()
CORPUS = [p for ps in PAYLOADS.values() for p in ps]
# values a hostile publisher may put in any field: wrong types, out of every range, times in every form
HOSTILE = [None, True, -1, 0, 1, 17, 18, 87, 88, 2**31, 2**53, 2**53 + 1, 2**63 - 1, 2**63, 2**64, -2**63 - 1,
           10**30, 1.5, -0.0, 1e300, "", "x", [], [1], {}, {"sec": 1, "nsec": 2}, {"sec": -1, "nsec": 0},
           {"sec": 1, "nsec": 10**9}, {"sec": 1, "nsec": -1}, {"sec": 1.0, "nsec": 2}, {"sec": 1},
           {"sec": 1, "nsec": 2, "x": 3}, {"sec": MAX_NS // 10**9, "nsec": MAX_NS % 10**9},
           {"sec": MAX_NS // 10**9, "nsec": MAX_NS % 10**9 + 1}, {"sec": 2**64, "nsec": 0}, {"sec": True, "nsec": 0},
           MAX_NS, MAX_NS + 1, list(range(18)), [0] * 18, [9] * 18, ["a"] * 18]


def _outcome(fn, payload: bytes):
    try:
        return fn(payload), None
    except (msgspec.DecodeError, msgspec.ValidationError) as err:
        return None, str(err)


def _agree(payload: bytes) -> None:
    event, error = _outcome(decode_event, payload)
    twin, twin_error = _outcome(check_event, payload)
    assert twin_error == error, payload  # same verdict, and the refusal worded by the event's decoder
    if event is not None:
        assert type(twin).__name__ == type(event).__name__
        assert [getattr(twin, f) for f in ENVELOPE] == [getattr(event, f) for f in ENVELOPE]


def test_every_event_type_has_a_twin_with_its_fields_and_no_python_hook():
    assert set(CHECKED_BY_TAG) == set(EVENT_BY_TAG) == set(PAYLOADS)  # the samples hold every type
    for t in EVENT_TYPES:
        twin = CHECKED_BY_TAG[t.__struct_config__.tag]
        ours, theirs = msgspec.structs.fields(twin), msgspec.structs.fields(t)
        assert [(f.name, f.default, f.default_factory) for f in ours] == \
               [(f.name, f.default, f.default_factory) for f in theirs]
        assert all((a.type == b.type) != (b.type is Nanos) for a, b in zip(ours, theirs))
        assert twin.__struct_config__.tag_field == t.__struct_config__.tag_field


def test_the_samples_are_taken_alike():
    for payload in CORPUS:
        _agree(payload)


@pytest.mark.parametrize("tag", sorted(PAYLOADS))
def test_every_field_of_every_type_with_hostile_values_is_judged_alike(tag):
    for payload in PAYLOADS[tag]:
        obj = json.loads(payload)
        for field in list(obj) + ["type"]:
            for value in HOSTILE:
                mutated = dict(obj, **{field: value})
                _agree(json.dumps(mutated).encode())
            _agree(json.dumps({k: v for k, v in obj.items() if k != field}).encode())  # missing


def test_a_time_at_the_edge_of_the_range_is_left_to_the_event_decoder():
    """sec == MAX_NS // 10**9 is out of the twin's range but in the event's (up to MAX_NS): the
    event's decoder then decides, so nothing valid is refused."""
    obj = json.loads(PAYLOADS["CardPicked"][-1])
    last = dict(obj, time_ns={"sec": MAX_NS // 10**9, "nsec": MAX_NS % 10**9})
    assert decode_event(json.dumps(last).encode()).time_ns == MAX_NS
    assert check_event(json.dumps(last).encode()).time_ns == MAX_NS
    with pytest.raises(msgspec.ValidationError):
        msgspec.json.decode(b'{"sec": 9223372036, "nsec": 0}', type=CheckedTimeObject)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(CORPUS), st.binary(max_size=8), st.integers(0, 400))
def test_damaged_bytes_are_judged_alike(payload, junk, at):
    at = min(at, len(payload))
    _agree(payload[:at] + junk + payload[at:])
    _agree(payload[:at] + payload[at + len(junk):])
