"""A whole session over a real Zenoh bus, recorded to MCAP: the recording is the
truth the learner's table is rebuilt from, bit for bit, and equal to the study."""

import json

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from pairplay.core.personas import persona
from pairplay.core.simulate import run_games
from pairplay.core.study import train
from pairplay.replay.fold import stream_seed
from pairplay.replay.reader import EventDecoderFactory, read_log
from pairplay.replay.rebuild import rebuild_recording, write_outputs
from pairplay.schemas.policy import read_policy
from pairplay.schemas.config import DEFAULT_REWARD_BONUS
from pairplay.schemas.session import SessionConfig
from pairplay.services.replayer import republish
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

from busutil import collect, connector, listener, wait_until

CONFIG = SessionConfig(session="bus1", participant="sim:tatiana", persona="tatiana", seed=11, rounds=8,
                       software_version="test", reward_bonus=DEFAULT_REWARD_BONUS)


def test_a_bus_session_rebuilds_to_the_live_learner_and_the_study(tmp_path):
    nodes = {}
    path = run_session(CONFIG, tmp_path / "bus1.mcap", nodes_out=nodes)
    live_q = nodes["learner"].logic.learner.q[0]
    rebuilt = rebuild_recording(path)
    assert not rebuilt.truncated and rebuilt.fold.q_mismatches == 0
    assert np.array_equal(rebuilt.fold.q, live_q)  # bit for bit
    study = run_games([persona("tatiana")], [stream_seed(CONFIG)], CONFIG.rounds, reward_bonus=CONFIG.reward_bonus)
    assert np.array_equal(study.q[0], live_q)  # one code path: the bus plays the study's game
    assert [2 * t for t in rebuilt.fold.turns_per_round()] == list(study.picks[0])
    trained = train([persona("tatiana")], games=1, rounds=CONFIG.rounds, seed=CONFIG.seed)
    assert rebuilt.policy.greedy == list(trained.greedy[0])  # the same policy file as the study's
    assert rebuilt.fold.ended is not None and not rebuilt.fold.rejections
    policy_path, curve_path = write_outputs(rebuilt, tmp_path / "out")
    assert read_policy(policy_path).q == [list(map(float, row)) for row in live_q]
    assert curve_path.read_text().count("\n") == CONFIG.rounds + 1
    assert verify_recording(path).ok


def test_the_recording_reads_with_mcap_readers_validates_and_carries_metadata(tmp_path):
    path = run_session(CONFIG, tmp_path / "bus1.mcap")
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[EventDecoderFactory()])
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        n = 0
        validators = {}
        for schema, channel, message, event in reader.iter_decoded_messages():
            assert channel.topic == f"pairplay/bus1/{event.source}/{type(event).__name__}"
            v = validators.get(schema.id) or validators.setdefault(
                schema.id, jsonschema.Draft202012Validator(json.loads(schema.data)))
            v.validate(json.loads(message.data))
            n += 1
    assert n == len(read_log(path).events) > 500
    session = meta["pairplay.session"]
    assert session["seed"] == "11" and session["software_version"] == "test"
    assert json.loads(session["config"])["persona"] == "tatiana"
    assert meta["pairplay.recorder"]["software_version"]


def test_replay_republishes_every_event_in_order(tmp_path):
    from pairplay.services.replayer import end_last
    path = run_session(CONFIG, tmp_path / "bus1.mcap")
    events = read_log(path).events
    with listener() as a, connector(a) as b:
        got = collect(b, "pairplay/again/**")
        first = events[0].key.replace("/bus1/", "/again/")
        assert wait_until(lambda: a.matching(first))  # the subscription arrived
        assert republish(a, events, speed=0.0, as_session="again") == len(events)
        assert wait_until(lambda: got.qsize() == len(events))
    keys = [got.get()[0] for _ in range(len(events))]
    # in file order, the session's end last (services/replayer.py end_last: the learner's last reward was filed after it)
    assert keys == [r.key.replace("/bus1/", "/again/") for r in end_last(events)]


@pytest.mark.parametrize("rule", ["consistent", "match"])
def test_the_other_reward_readings_travel_over_the_bus_too(tmp_path, rule):
    import msgspec
    config = msgspec.structs.replace(CONFIG, session=f"bus-{rule}", persona="deaf", participant="sim:deaf",
                                     reward_bonus=rule)
    nodes = {}
    path = run_session(config, tmp_path / "bus2.mcap", nodes_out=nodes)
    study = run_games([persona("deaf")], [stream_seed(config)], config.rounds, reward_bonus=rule)
    assert np.array_equal(study.q[0], nodes["learner"].logic.learner.q[0])
    other = run_games([persona("deaf")], [stream_seed(config)], config.rounds, reward_bonus=DEFAULT_REWARD_BONUS)
    assert not np.array_equal(other.q[0], study.q[0])
    rebuilt = rebuild_recording(path)
    assert rebuilt.policy.reward_bonus == rule and np.array_equal(rebuilt.fold.q, study.q[0])
