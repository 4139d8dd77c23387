"""Every accepted seed gives its own streams, or is refused with the accepted range; participant ids enter
the streams through a collision-resistant digest (issue 10, item 8). The study's own streams are unchanged,
and recordings made with the old derivation still verify under it."""

import zlib
from pathlib import Path

import pytest

from pairplay.core.personas import PERSONAS
from pairplay.core.rng import STREAMS_VERSION, game_seed
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.verify import verify_recording

from loopback_session import loopback_events

SAMPLES = Path(__file__).resolve().parent.parent / "recordings" / "samples"


def first_deal(config):
    return next(e.faces for e in loopback_events(config) if isinstance(e, ev.RoundStarted))


@pytest.mark.parametrize("a,b", [(5, 4294967301), (0, 2**32), (4294967295, 2**64 - 1), (7, 7 + 2**40)])
def test_seeds_that_derivation_1_aliased_give_their_own_games(a, b):
    assert game_seed(a, "deaf", 0, version=1) == game_seed(b, "deaf", 0, version=1)  # the fault, kept for old files
    assert game_seed(a, "deaf", 0) != game_seed(b, "deaf", 0)
    human = [SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=s, rounds=1,
                           streams=STREAMS_VERSION) for s in (a, b)]
    assert first_deal(human[0]) != first_deal(human[1])


@pytest.mark.parametrize("seed", [-1, -(2**40), 2**64, 2**70])
def test_seeds_outside_the_range_are_refused_with_the_range(seed, tmp_path, pairplay_cli):
    with pytest.raises(ValueError, match="18446744073709551615"):
        game_seed(seed, "deaf", 0)
    with pytest.raises(ValueError, match="0..18446744073709551615"):
        SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=seed, rounds=1, streams=2).validate()
    for verb in (["session", "--participant", "sim:deaf", "--rounds", "1"], ["study", "--quiet"]):
        r = pairplay_cli(*verb, "--seed", seed, "--out", tmp_path)
        assert r.returncode != 0 and "0..18446744073709551615" in r.stdout + r.stderr
        assert "Traceback" not in r.stderr and not list(tmp_path.glob("*.mcap"))


def test_the_old_derivation_refuses_what_it_would_alias():
    with pytest.raises(ValueError, match="0..4294967295"):
        SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=2**32 + 5, rounds=1).validate()


def test_participant_ids_with_one_crc32_get_their_own_streams():
    a, b = "plumless", "buckeroo"
    assert zlib.crc32(a.encode()) == zlib.crc32(b.encode())
    assert game_seed(3, a, 0, version=1) == game_seed(3, b, 0, version=1)  # derivation 1 shared them
    assert game_seed(3, a, 0) != game_seed(3, b, 0)
    deals = [first_deal(SessionConfig(session="h", participant=f"human:{p}", seed=3, rounds=1, streams=2,
                                      observed_source="first-pick", ignore_rule="time")) for p in (a, b)]
    assert deals[0] != deals[1]


def test_the_study_keeps_its_streams():
    """The study's labels are a fixed table with distinct CRC-32s, and keep derivation 1 (results pinned)."""
    labels = [role + key for key in PERSONAS for role in ("", "reuse:", "combine:", "oracle:")]
    assert len({zlib.crc32(x.encode()) for x in labels}) == len(labels)
    for label in labels:
        for seed in (0, 1, 4, 2**32 - 1):
            for game in (0, 9, 1000):
                assert game_seed(seed, label, game) == game_seed(seed, label, game, version=1)


def test_recordings_made_with_derivation_1_verify_under_it():
    from pairplay.replay.reader import read_log

    for name in ("sim-ashley.mcap", "human-board.mcap"):
        [started] = read_log(SAMPLES / name).of("SessionStarted")
        assert started.config.streams == 1  # recorded before the field existed: derivation 1
        assert verify_recording(SAMPLES / name).ok
    # the human sample's streams differ between the derivations: the recorded version decides
    assert game_seed(3, "p01", 0, 1) != game_seed(3, "p01", 0, 2)


@pytest.mark.parametrize("seed", [-1, 2**64, 2**64 + 1, 2**70, 1.7, 2.0, True])
def test_a_games_streams_refuse_a_seed_they_would_alias(seed):
    """A game's streams (core.rng) took any number and cut it to 64 bits: 2**64 played seed 0's game, -1 seed
    2**64-1's, 1.7 seed 1's; the study, the sessions and pairplay.gym all key their games through them."""
    from pairplay.core.rng import UniformStream, stream_key, stream_keys
    from pairplay.core.simulate import run_games

    error = TypeError if isinstance(seed, (bool, float)) else ValueError
    for make in (lambda: stream_key(seed, "deal"), lambda: stream_keys([3, seed]),
                 lambda: UniformStream([seed], "user"), lambda: game_seed(seed, "deaf", 0),
                 lambda: run_games([PERSONAS["deaf"]], [seed], 1)):
        with pytest.raises(error, match="seed"):
            make()
    with pytest.raises(TypeError, match="game index"):
        game_seed(3, "deaf", 1.5)
    assert stream_key(2**64 - 1, "deal") != stream_key(0, "deal") and stream_keys([2**64 - 1]).shape == (1, 4)
