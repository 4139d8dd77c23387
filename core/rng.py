"""Per-game, per-role streams of uniform numbers (the only randomness in core/).

Rule: every game owns independent streams, one per role that decides something
at random: "deal" (the game: 18 draws per round, the shuffle), "agent" (the
learner: DRAWS_PER_SUGGESTION per suggestion), "user" (the simulated
participant: DRAWS_PER_TURN per turn) and "snapshot" (ties of greedy policies
read off a learner during a study, outside the game). A role draws the same
count for every event whatever branch it then takes, so a game's outcome
depends only on its seed: alone on the bus (a batch of one, each role in its own
process) or stepped together with thousands of games in the in-process study,
it is the same game.

Generator: SplitMix64 (Steele, Lea and Flood, OOPSLA 2014), the generator that
seeds Java's SplittableRandom and xoshiro: draw n of a stream is
mix(key + (n + 1) * 0x9E3779B97F4A7C15), a pure function of the stream's key
and the draw's index. So a batch of streams is a few uint64 array operations
per draw (no per-game Python loop, no buffers), and skipping ahead is adding
to a counter (a restarted service catches up with its log in O(1)). Keys come
from numpy's SeedSequence hashing of (game seed, role), 64 bits each. The
draws themselves are core/kernels.py's `draw`, the one the compiled simulator
uses inline.

Game seeds (`game_seed`, derivation STREAMS_VERSION = 2): every seed 0..2**64-1
and every label (a persona key, a participant id) gives its own streams. The
study's own labels (the persona keys of appendix A, bare or as "reuse:",
"combine:", "oracle:" + key) with seeds below 2**32 keep derivation 1 (numpy's
SeedSequence of the seed, the label's CRC-32 and the game index), so the study's
results stay what they were; those labels are a fixed table whose CRC-32s
differ (tested). Everything else, where derivation 1 aliased (it cut seeds to
32 bits: 5 and 4294967301, -1 and 4294967295 were one game; two participant ids
with one CRC-32 shared their streams), goes through BLAKE2b of the seed, the
label and the game index. Derivation 1 stays available, exactly, for the
recordings made with it (SessionConfig.streams).

A game's seed is an integer in SEED_RANGE, checked where it becomes a stream
(`check_seed`: stream_key, stream_keys, game_seed), never cut to 64 bits or
truncated to an integer: 2**64 was seed 0's game, -1 seed 2**64-1's, 1.7 seed 1's.
"""

from __future__ import annotations

import hashlib
import zlib
from functools import lru_cache
from typing import Sequence

import numpy as np

from pairplay.arguments import is_integer
from pairplay.schemas.session import GAME_INDEX_RANGE, SEED_RANGE  # noqa: F401  (SEED_RANGE: this module's)

from . import kernels

ROLES = ("deal", "agent", "user", "snapshot")
_ROLE_KEY = {role: i for i, role in enumerate(ROLES)}
assert (kernels.DEAL, kernels.AGENT, kernels.USER, kernels.SNAPSHOT) == tuple(_ROLE_KEY[r] for r in ROLES)


STREAMS_VERSION = 2  # the derivation new sessions record (SessionConfig.streams)
_STUDY_ROLES = ("reuse:", "combine:", "oracle:")


def _study_label(label: str) -> bool:
    from .personas import PERSONAS  # the fixed table of appendix A

    for role in _STUDY_ROLES:
        if label.startswith(role):
            label = label[len(role):]
            break
    return label in PERSONAS


def check_seed(seed, what: str = "seed", bounds: tuple[int, int] = SEED_RANGE) -> int:
    """`seed` as an int: an integer (Python's or numpy's, not a bool) within `bounds` (SEED_RANGE).
    TypeError for anything else that is not an integer, ValueError (naming the range) outside it."""
    if not is_integer(seed):
        raise TypeError(f"{what} must be an integer {bounds[0]}..{bounds[1]}, got {seed!r}")
    seed = int(seed)
    if not bounds[0] <= seed <= bounds[1]:
        raise ValueError(f"{what} {seed} is outside {bounds[0]}..{bounds[1]}")
    return seed


def game_seed(seed: int, persona: str, game: int, version: int = STREAMS_VERSION) -> int:
    """A 64-bit seed for game `game` (>= 0) of `persona` (a persona key or a participant id) under
    study seed `seed` (0..2**64-1), by stream derivation `version` (see the module rule).
    Raises ValueError for a seed or game index out of range, TypeError for one that is not an integer
    (version 1 takes what it always took)."""
    if version == 1:
        return _derivation_1(int(seed), persona, int(game))
    if version != 2:
        raise ValueError(f"unknown stream derivation {version} (this pairplay knows 1 and {STREAMS_VERSION})")
    seed, game = check_seed(seed), check_seed(game, "game index", GAME_INDEX_RANGE)
    if seed < 2**32 and _study_label(persona):
        return _derivation_1(seed, persona, game)
    digest = hashlib.blake2b(f"{seed}\x00{game}".encode(), digest_size=8, key=b"pairplay streams 2",
                             person=b"game seed", salt=hashlib.blake2b(persona.encode("utf-8"),
                                                                        digest_size=16).digest())
    return int.from_bytes(digest.digest(), "little")


@lru_cache(maxsize=1 << 16)  # SeedSequence costs ~20 us; a study asks for the same evaluation games many times
def _derivation_1(seed: int, persona: str, game: int) -> int:
    """pairplay <= 0.2's game seed (the seed cut to 32 bits, the label's CRC-32): the study's streams."""
    key = zlib.crc32(persona.encode("utf-8"))
    state = np.random.SeedSequence([seed & 0xFFFFFFFF, key, game]).generate_state(2, np.uint32)
    return int(state[0]) << 32 | int(state[1])


def stream_key(seed: int, role: str) -> int:
    """The 64-bit SplitMix64 key of one game's stream for one role."""
    if role not in _ROLE_KEY:
        raise ValueError(f"unknown role {role!r}; roles are {ROLES}")
    return _stream_key(check_seed(seed), _ROLE_KEY[role])


@lru_cache(maxsize=1 << 16)
def _stream_key(s: int, role: int) -> int:
    # SeedSequence hashing costs ~20 us; a study asks for the same evaluation games many times.
    return int(np.random.SeedSequence([s >> 32, s & 0xFFFFFFFF, role]).generate_state(1, np.uint64)[0])


def stream_keys(seeds: Sequence[int], roles: Sequence[str] = ROLES) -> np.ndarray:
    """(n, 4) uint64: the keys of `roles` (default all) of every game, columns in ROLES order, 0 elsewhere."""
    for role in roles:
        if role not in _ROLE_KEY:
            raise ValueError(f"unknown role {role!r}; roles are {ROLES}")
    wanted = tuple(role in roles for role in ROLES)
    keys = np.array([_key_row(check_seed(s), wanted) for s in seeds], dtype=np.uint64)
    return keys.reshape(len(seeds), len(ROLES))


@lru_cache(maxsize=1 << 16)
def _key_row(s: int, wanted: tuple[bool, ...]) -> tuple[int, ...]:
    # one cached row per game: a batch of 2,048 games looked up 8,192 keys one by one (~5% of its run)
    return tuple(_stream_key(s, i) if w else 0 for i, w in enumerate(wanted))


class UniformStream:
    """Uniform [0, 1) draws for a batch of games, one SplitMix64 stream per game and role."""

    def __init__(self, seeds: Sequence[int], role: str):
        self.role = role
        self._key = np.array([stream_key(s, role) for s in seeds], dtype=np.uint64)
        self._pos = np.zeros(len(self._key), dtype=np.uint64)
        self._all = np.arange(len(self._key))

    @property
    def n_games(self) -> int:
        return len(self._key)

    @property
    def keys(self) -> np.ndarray:
        """(n,) uint64: each game's key, for a kernel that draws from this stream in place."""
        return self._key

    @property
    def positions(self) -> np.ndarray:
        """(n,) uint64: each game's next draw index; a kernel that draws in place advances it."""
        return self._pos

    @property
    def drawn(self) -> np.ndarray:
        """Draws consumed so far, per game."""
        return self._pos.astype(np.int64)

    def take(self, k: int, games: np.ndarray | None = None) -> np.ndarray:
        """The next `k` draws of each game (or of `games`, an index array): shape (n, k)."""
        idx = self._all if games is None else np.asarray(games, dtype=np.int64)
        out = np.empty((idx.size, k))
        kernels.draw_block(self._key, self._pos, k, idx, out)
        return out

    def skip(self, n_draws: int, games: np.ndarray | None = None) -> None:
        """Fast-forward by `n_draws` (a restarted service catches up with its log)."""
        if games is None:
            self._pos += np.uint64(n_draws)
        else:
            self._pos[np.asarray(games)] += np.uint64(n_draws)


def pick_from_mask(masks: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Uniformly pick one set bit of each mask with draw `u`: the floor(u*n)-th bit.

    Masks (18-bit card sets) must be non-empty (an empty one gives -1). Returns
    card indices (int64). Every random choice of a card is made this way, with
    exactly one draw.
    """
    masks, u = np.broadcast_arrays(np.asarray(masks, dtype=np.int64), np.asarray(u, dtype=np.float64))
    out = np.empty(masks.shape, dtype=np.int64)
    kernels.pick_batch(np.ascontiguousarray(masks).reshape(-1), np.ascontiguousarray(u).reshape(-1), out.reshape(-1))
    return out
