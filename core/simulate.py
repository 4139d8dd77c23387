"""The virtual study's game loop (thesis 6.1-6.2), many games stepped together.

Rule: every game plays `rounds` rounds; a round is every turn until the board is
clear, each round on a new deal. A turn: the user's first pick; the card the
user observes (its intended card, thesis 6.1.3, or the first pick as in the human
study); the state (4.1); the learner's suggestion; the user's second pick; the
reward (4.3, 6.1.3) and the Q update (5.2); the user's memory. Games are
independent: the compiled kernel (core/kernels.py `play`) plays each game whole,
a batch's games in contiguous pieces on the machine's cores (core/threads.py;
each game's state and streams are its own, so the bytes are those of one
thread, and a recorded trace is gathered piece by piece in game order), and a batch may mix learners (Q-learning, pi-reuse, fixed
policies), schedules and lengths. Each role (deal, agent, user, snapshot) draws
from its own per-game stream, so a game run here equals the same game run alone
over the bus, and a batch's results do not depend on what else is in it. A
recorded trace is given in lockstep order (turn number, then game), the order
of the numpy simulator this replaced, so sums over it add up the same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona

from . import kernels, threads
from .geometry import N_CARDS, N_STATES
from .actions import N_ACTIONS
from .games import check_observed_source
from .learning import MODES, policy_table, schedule_tables
from .lspi import play_lspi
from .reward import BONUS_CODES, simulated_reward
from .rng import ROLES, stream_keys
from .user import frames_of, persona_arrays, reading_codes

RECORDS = {None: kernels.RECORD_NONE, "all": kernels.RECORD_ALL, "considerable": kernels.RECORD_CONSIDERABLE}
PROGRESS_SLICES = 20  # a batch with a progress callback is played in this many slices of rounds
PIECE_GAMES = 8  # the fewest games in a piece a thread plays (core/threads.py); smaller batches play inline
PIECES_PER_WORKER = 6  # pieces of unequal cost (personas, lengths) balance over the threads
TRACE_ROWS = 16  # a recorded trace's first rows per game and round; the kernel grows it when full


# What a batch of games holds in memory, for refusing one that cannot fit before any work (the study's,
# a sweep cell's, the counterfactual's arms): measured peaks (`/usr/bin/time -v`, pairplay 0.9) rounded up.
GAME_BYTES = 32_000  # per game: its Q-table and update counts (24 x 88), its memory stamps, its streams
LSPI_GAME_BYTES = 2_600_000  # per LSPI game: its 88 inverse matrices over the default 60 features (core/lspi.py)
GAME_ROUND_BYTES = 40  # per game and round: picks, inconsistent suggestions, greedy snapshots, their sums
FIXED_GAME_ROUND_BYTES = 16  # the same for a fixed policy's game (an evaluation): no snapshots
TRACE_GAME_ROUND_BYTES = 2_000  # the same with record="all": every turn's row, its buffer and its columns
ROUND_BYTES = 100  # per round of the longest game: schedule tables, curves


MEMORY_LIMIT = 2 * 10**9  # bytes a study, sweep cell or counterfactual may plan to hold: generous for real use


def gigabytes(n: int) -> str:
    """Bytes as the refusals say them: '93.1 GB'."""
    return f"{n / 1e9:.1f} GB"


def batch_bytes(games: int, rounds: int, lspi: bool = False, fixed: bool = False, trace: bool = False) -> int:
    """About how many bytes run_games holds for `games` games of `rounds` rounds (an upper estimate)."""
    per_round = TRACE_GAME_ROUND_BYTES if trace else FIXED_GAME_ROUND_BYTES if fixed else GAME_ROUND_BYTES
    return games * (LSPI_GAME_BYTES if lspi else GAME_BYTES) + games * rounds * per_round + rounds * ROUND_BYTES


def _pieces(n: int) -> list[np.ndarray]:
    """The batch's games in contiguous pieces, in order (one piece below 2 * PIECE_GAMES games)."""
    count = max(1, min(n // PIECE_GAMES, PIECES_PER_WORKER * threads.WORKERS if threads.WORKERS > 1 else 1))
    return np.array_split(np.arange(n, dtype=np.int64), count)


class SimResult(NamedTuple):
    q: np.ndarray  # (B, 24, 88) final Q-tables
    counts: np.ndarray  # (B, 24, 88) Q updates per state and action
    picks: np.ndarray  # (B, rounds) picks per round (0 past a game's own rounds)
    inconsistent: np.ndarray  # (B, rounds) inconsistent suggestions per round
    turns: int  # lockstep steps: the most turns any game took
    snapshots: np.ndarray | None  # (B, rounds // k, 24) greedy policy after every k rounds
    trace: Trace | None = None  # `record`: one entry per turn, lockstep order (step, then game); see run_games


def _per_game(value, n: int, what: str) -> list:
    if isinstance(value, (str, int, np.integer, LearnerConfig)):
        return [value] * n
    value = list(value)
    if len(value) != n:
        raise ValueError(f"one {what} per game")
    return value


def run_games(personas: Sequence[Persona], seeds: Sequence[int], rounds: int | Sequence[int],
              config: LearnerConfig | Sequence[LearnerConfig] = LearnerConfig(), mode: str | Sequence[str] = "q",
              bias: np.ndarray | None = None, policy: np.ndarray | None = None,
              observed_source: str = "intended", progress=None,
              snapshot_every: int | None = None, reward_bonus: str = DEFAULT_REWARD_BONUS,
              record: str | None = None, lspi: LSPIConfig | None = None, frames=0) -> SimResult:
    """Play one game per (persona, seed) pair; see the module rule.

    `rounds`, `config` and `mode` ("q", "reuse" on `bias`, "fixed" by `policy`)
    are one for all games or one per game, so independent experiments share a
    batch. `progress(done_rounds)` is called with the rounds completed so far
    (summed over games) after every slice of rounds. With `snapshot_every=k`
    the greedy policy of every learner is kept after rounds k, 2k, ... (ties
    broken by the game's "snapshot" stream), to measure how fast a policy
    becomes good. `reward_bonus` chooses when the 1/|candidate set| bonus is
    paid (core/reward.py). `record="all"` keeps every turn in `trace` (name ->
    array: kernels.TRACE_FIELDS, then "candidates" and "reward"), "considerable"
    only the turns whose match the user did not remember (the oracle's situations).
    `mode="lspi"` (for every game) learns by online LSPI configured by `lspi`:
    its own lockstep runner (core/lspi.py `play_lspi`; one `rounds` and
    `config` for all games, no `record`), on the same per-game streams.
    `frames`: the frame each game's user reads suggestions in, relative to how
    the robot renders them (core/frames.py; 0, the thesis's user, by default),
    one for all games or one per game.
    """
    check_observed_source(observed_source)
    if record not in RECORDS:
        raise ValueError(f"record must be one of {list(RECORDS)}")
    n = len(personas)
    if len(seeds) != n:
        raise ValueError("one seed per game")
    if mode == "lspi":
        if record is not None:
            raise ValueError("an LSPI batch records no trace")
        if np.any(frames_of(frames, n)):
            raise ValueError("an LSPI batch plays users in the robot's frame only (frames=0)")
        return SimResult(*play_lspi(personas, seeds, rounds, config, lspi or LSPIConfig(), observed_source,
                                    progress, snapshot_every, reward_bonus))
    modes = _per_game(mode, n, "mode")
    unknown = set(modes) - set(MODES)
    if unknown:
        raise ValueError(f"unknown learner mode {sorted(unknown)[0]!r}")
    if "reuse" in modes and bias is None:
        raise ValueError("pi-reuse needs a bias policy")
    if "fixed" in modes and policy is None:
        raise ValueError("a fixed learner needs a policy")
    game_rounds = np.array(_per_game(rounds, n, "rounds count"), dtype=np.int64)
    if n and game_rounds.min() < 0:
        raise ValueError("rounds must be >= 0")
    horizon = int(game_rounds.max()) if n else 0
    configs = _per_game(config, n, "learner config")
    distinct = list(dict.fromkeys(configs))
    cfg = np.array([distinct.index(c) for c in configs], dtype=np.int64)
    tabs = [schedule_tables(c, horizon) for c in distinct]
    eps_tab, alpha_tab, psi0_tab = (np.ascontiguousarray(np.stack([t[i] for t in tabs]) if tabs else
                                                         np.zeros((1, 1))) for i in range(3))
    psi_decay = np.array([c.psi_decay for c in distinct] or [1.0], dtype=np.float64)
    table = np.zeros((n, N_STATES), dtype=np.int64)
    mode_code = np.array([MODES[m] for m in modes], dtype=np.int8)
    for name, source in (("reuse", bias), ("fixed", policy)):
        rows = mode_code == MODES[name]
        if rows.any():
            table[rows] = policy_table(source, n)[rows]
    p_consider, q_hear, capacity, sees = persona_arrays(personas)
    reading = reading_codes(personas)
    frame = frames_of(frames, n)

    # a fixed policy draws nothing: its games need only the deal and user streams
    keys = stream_keys(seeds, ("deal", "user") if set(modes) == {"fixed"} else ROLES)
    pos = np.zeros_like(keys)
    q = np.zeros((n, N_STATES, N_ACTIONS))
    counts = np.zeros((n, N_STATES, N_ACTIONS), dtype=np.int32)
    picks = np.zeros((n, horizon), dtype=np.int32)
    inconsistent = np.zeros((n, horizon), dtype=np.int32)
    steps = np.zeros(n, dtype=np.int64)
    round_index = np.zeros(n, dtype=np.int64)
    memory = np.zeros(n, dtype=np.int64)
    stamp = np.full((n, N_CARDS), kernels.NEVER, dtype=np.int64)
    clock = np.zeros(n, dtype=np.int64)
    every = int(snapshot_every or 0)
    snapshots = np.zeros((n, horizon // every if every else 0, N_STATES), dtype=np.int64)
    pieces = _pieces(n)
    width = len(kernels.TRACE_FIELDS) + 1
    recorded: list[np.ndarray] = []  # the trace's rows: slice by slice, piece by piece (the order of one call)
    slice_rounds = max(1, -(-horizon // PROGRESS_SLICES)) if progress is not None else max(horizon, 1)
    previous = 0
    for until in range(slice_rounds, horizon + slice_rounds, slice_rounds):
        played: list = [None] * len(pieces)

        def work(i: int, until=until, span=min(until, horizon) - previous) -> None:
            games = pieces[i]
            buffer = np.empty((games.size * span * TRACE_ROWS if record else 0, width), dtype=np.int32)
            played[i] = kernels.play(
                kernels.TABLES, games, until, game_rounds, keys, pos, mode_code, cfg, table, p_consider, q_hear,
                capacity, sees, reading, frame, eps_tab, alpha_tab, psi0_tab, psi_decay, BONUS_CODES[reward_bonus],
                observed_source == "first-pick", q, counts, picks, inconsistent, steps, round_index, memory, stamp,
                clock, every, snapshots, RECORDS[record], buffer, 0)
        threads.each(work, len(pieces))
        if record:
            recorded += [rows[:k] for rows, k in played]
        previous = until
        if progress is not None:
            progress(int(round_index.sum()))
    trace = None
    if record:
        trace = Trace(_gathered(recorded, width), reward_bonus)
    return SimResult(q, counts, picks, inconsistent, int(steps.max()) if n else 0,
                     snapshots if every else None, trace)


def _gathered(blocks: list[np.ndarray], width: int) -> np.ndarray:
    """The blocks' rows in order, in one array; each block is dropped once copied (`blocks` ends empty),
    so the recorded turns are in memory about once, not twice."""
    rows = np.empty((sum(len(b) for b in blocks), width), dtype=np.int32)
    at = 0
    blocks.reverse()
    while blocks:
        block = blocks.pop()
        rows[at:at + len(block)] = block
        at += len(block)
        del block
    return rows


class Trace(Mapping):
    """The recorded turns of `run_games(record=...)`: name -> column, in lockstep order (step, then game).

    Names: kernels.TRACE_FIELDS, then "candidates" and "reward". A column is
    gathered (and the rewards computed) on first use; `rows` (one int32 row
    per turn, in the order the kernel played them) and `order` (the lockstep
    order of those rows) serve a caller that reads a few fields of every row
    (core/oracle.py) without copying the table.
    """

    NAMES = (*kernels.TRACE_FIELDS, "candidates", "reward")

    def __init__(self, rows: np.ndarray, reward_bonus: str):
        self.rows = rows
        self.order = np.lexsort((rows[:, kernels.T_GAME], rows[:, kernels.T_STEP]))
        self._bonus = reward_bonus
        self._columns: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._columns:
            if name == "reward":
                size = np.bitwise_count(self["candidates"])
                holds = (self["candidates"] >> self["match"]) & 1 == 1
                self._columns[name], _ = simulated_reward(self["second"] == self["match"], self["considered"] == 1,
                                                          self["consistent"] == 1, size, holds, self._bonus)
            elif name == "candidates":
                self._columns[name] = self.rows[self.order, kernels.T_CANDIDATES]
            elif name in kernels.TRACE_FIELDS:
                self._columns[name] = self.rows[self.order, kernels.TRACE_FIELDS.index(name)]
            else:
                raise KeyError(name)
        return self._columns[name]

    def __iter__(self):
        return iter(self.NAMES)

    def __len__(self) -> int:
        return len(self.NAMES)
