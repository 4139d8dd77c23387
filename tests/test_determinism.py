"""Same seed, same bytes; another seed, other results; a game is the same alone or batched."""

import hashlib

import numpy as np
import pytest

from pairplay.core.personas import PERSONAS
from pairplay.core.rng import UniformStream, game_seed, pick_from_mask
from pairplay.core.simulate import run_games
from pairplay.cli.main import main


def test_streams_are_independent_per_role_and_skip_is_take():
    a = UniformStream([5, 6], "user")
    b = UniformStream([5, 6], "user")
    c = UniformStream([5, 6], "agent")
    first = a.take(7)
    assert (first == b.take(7)).all() and not np.allclose(first, c.take(7))
    b.skip(10_000)
    for _ in range(10):
        a.take(1000)  # a has drawn 10,007 too
    with pytest.raises(ValueError, match="role"):
        UniformStream([1], "dealer")
    assert (a.take(3) == b.take(3)).all() and (a.drawn == 10_010).all() and (b.drawn == 10_010).all()


def test_streams_give_each_game_its_own_numbers_whatever_the_batch():
    alone = UniformStream([42], "deal")
    batch = UniformStream([7, 42, 9], "deal")
    batch.take(18, np.array([0, 2]))  # other games draw more often
    batch.take(18, np.array([0]))
    assert (alone.take(18)[0] == batch.take(18, np.array([1]))[0]).all()


def test_pick_from_mask_chooses_the_kth_card():
    masks = np.array([0b1011, 0b1011, 0b1011, 1 << 17])
    assert pick_from_mask(masks, np.array([0.0, 0.4, 0.99, 0.5])).tolist() == [0, 1, 3, 17]


def test_game_seeds_differ_by_seed_persona_and_game():
    seeds = {game_seed(s, p, g) for s in (0, 1) for p in ("deaf", "blind") for g in range(3)}
    assert len(seeds) == 12 and game_seed(0, "deaf", 1) == game_seed(0, "deaf", 1)


def test_a_game_alone_equals_the_same_game_in_a_batch():
    deaf, vincent = PERSONAS["deaf"], PERSONAS["vincent"]
    s = [game_seed(3, "deaf", 0), game_seed(3, "vincent", 0), game_seed(3, "deaf", 1)]
    batch = run_games([deaf, vincent, deaf], s, 30)
    alone = run_games([vincent], s[1:2], 30)
    assert (batch.q[1] == alone.q[0]).all() and (batch.picks[1] == alone.picks[0]).all()


def _study_digest(out, seed):
    assert main(["study", "--quiet", "--seed", str(seed), "--personas", "deaf,vincent", "--games", "2",
                 "--rounds", "40", "--train-only", "--out", str(out)]) == 0
    files = sorted((out / "policies").rglob("*.json"))
    assert len(files) == 4
    return {f.relative_to(out).as_posix(): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}


def test_same_seed_gives_byte_identical_policy_files_and_another_seed_does_not(tmp_path):
    first = _study_digest(tmp_path / "a", 7)
    again = _study_digest(tmp_path / "b", 7)
    other = _study_digest(tmp_path / "c", 8)
    assert first == again
    assert all(first[k] != other[k] for k in first)
