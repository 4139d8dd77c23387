"""Online LSPI with tile-coded state x action features (thesis 3.1.3, 5.1.2, algorithm 2).

Rule: Q(s, a) = phi(s, a)^T theta (eq. 3.3) with phi(s, a) = the tile features of
state s placed in action a's block (one block of F features per action, zero
elsewhere: "state x action" as the thesis builds it, n = 88 F). Algorithm 2 keeps
Gamma = delta I + sum phi phi^T, Lambda = sum phi phi'^T and z = sum phi r, and every
K samples solves (Gamma - gamma Lambda) theta = z and acts greedily on the new theta.
After a suggestion the next state is the user's, where the agent never acts (thesis
eq. 5.1), so phi' = 0, Lambda = 0 whatever gamma is, and line 12 is the ridge
regression Gamma theta = z. Because phi(s, a) lives in block a, Gamma is block
diagonal: 88 blocks of F x F. We keep each block's inverse B_a = Gamma_a^-1 by
Sherman-Morrison restricted to the sample's block (B_a phi is the sum of the T
columns of B_a at the active features, O(F T); the rank-one update O(F^2)), and a
policy improvement sets theta_a = B_a z_a only for the blocks that got samples
since the last one (B_a z_a itself is kept current by the recursive-least-squares
form of the same rank-one step, w += B_new phi (r - phi^T w), O(F) a sample). Exploration is the Q-learner's epsilon-greedy with its schedule
and its seeded tie-break (core/learning.py), so the two learners differ only in how
they estimate Q. Every operation is elementwise or a reduction along a contiguous
last axis, so a game's weights are the same bits alone (a session) or batched (the
study), and a fold over the recorded samples rebuilds them exactly.

Features (Sutton and Barto 2018, 9.5.4, "tile coding"): a spatial state is the grid
point (row sign + 1, column sign + 1, level) of its cell (core/geometry.py); each of
`tilings` grids of tiles `tile_width` grid steps wide is displaced by
t * (1, 3, 5) * width / tilings, Sutton's asymmetric offsets; `exact` adds a grid
of one tile per state. "Not one card turned" has a tile of its own in every tiling.
Only tiles some state lands in become features (what an index-hash table does).
No maintained package fits: tiles3 is one public file not on PyPI, mushroom-rl's
Tiles needs torch and the whole library, and neither is block-aware.

Why the thesis's LSPI never converged (6.4), measured here (`pairplay bench --only lspi`,
tests/test_lspi.py, README "Online LSPI"):
1. Cost, first of all. It solved line 12 densely with n = 32 x 88 = 2816 unknowns;
   with K_theta = 0 that is one dense solve per sample: 0.2-0.3 s of wall time each
   (LIBRARY-NOTES; 0.77 s of CPU over two BLAS threads in the bench row), and even a dense Sherman-Morrison update of that
   size costs tens of ms. 80 games x 500 rounds x ~15 samples at 0.25 s is about
   40 hours of solving: "days". Here a sample costs ~20 us of CPU (bench row, 80
   games at once, K = 10), 10^3-10^4 x less, because gamma = 0 makes A block
   diagonal and only the sampled block is touched.
2. Representation, second. 32 tilings of a 4 x 4 grid over (cell code, level),
   written into 32 indices per action the way tiles3 does when its index table is
   that small (`thesis_features`), leave the 24 states rank `THESIS_RANK` (11):
   most states cannot get their own greedy action. Run through this learner (5
   games x 300 rounds per persona with focus >= 5), those features still reach
   1.00-1.09x the oracle, because one action ("try row x column y") is near-best in
   most states for a hearing user; its second try, 3 features per action (n = 264),
   gives Deaf and Frances 1.11-1.12x. Our features (rank 24) give 0.98-1.05x.
"""

from __future__ import annotations

import zlib
from typing import NamedTuple

import numpy as np

from pairplay.schemas.config import LearnerConfig, LSPIConfig

from .actions import N_ACTIONS
from .games import MemoryGames
from .geometry import CELLS, N_STATES, NOT_ONE_CARD_STATE, SPATIAL_STATES
from .learning import Learner, greedy
from .rng import UniformStream


class Features(NamedTuple):
    """Tile features of every state: `active[s]` are the T indices (0..size-1) of its tiles."""

    active: np.ndarray  # (N_STATES, T) int64; a repeated index counts twice (phi entry 2)
    size: int  # F, features per action block


def state_points() -> np.ndarray:
    """(23, 3) grid point (row sign + 1, column sign + 1, level) of every spatial state."""
    return np.array([(CELLS[c][1] + 1, CELLS[c][2] + 1, lv) for c, lv in SPATIAL_STATES], dtype=np.float64)


def tile_features(tilings: int = 4, tile_width: float = 2.0, exact: bool = True) -> Features:
    """Grid tile coding of the states (module rule); tiles no state uses are dropped."""
    points = state_points()
    dims = points.shape[1]
    keys: list[list[tuple]] = [[] for _ in range(N_STATES)]
    grids = [(float(tile_width), t * np.arange(1, 2 * dims, 2) * tile_width / tilings) for t in range(tilings)]
    if exact:
        grids.append((1.0, np.zeros(dims)))
    for g, (width, offset) in enumerate(grids):
        coords = np.floor((points + offset) / width).astype(np.int64)
        for s in range(len(points)):
            keys[s].append((g, *coords[s].tolist()))
        keys[NOT_ONE_CARD_STATE].append((g, "not one card"))
    index: dict[tuple, int] = {}
    active = np.array([[index.setdefault(k, len(index)) for k in row] for row in keys], dtype=np.int64)
    return Features(active, len(index))


def thesis_features(tilings: int = 32, grid: int = 4, size: int = 32) -> Features:
    """The thesis's features (5.1.2): `tilings` grids of grid x grid tiles over (cell/8, level/2)
    in [0, 1]^2, written into `size` indices the way tiles3's index table does (new tiles
    take the next free index; once it is full, tiles share indices by a hash)."""
    points = np.array([(c / 8, lv / 2) for c, lv in SPATIAL_STATES] + [(1.0, 1.0)])
    width = 1.0 / grid
    index: dict[tuple, int] = {}
    rows = []
    for p in points:
        row = []
        for t in range(tilings):
            key = (t, *np.floor((p + t * np.array([1, 3]) * width / tilings) / width).astype(int).tolist())
            if key not in index:
                index[key] = len(index) if len(index) < size else zlib.crc32(repr(key).encode()) % size
            row.append(index[key])
        rows.append(row)
    return Features(np.array(rows, dtype=np.int64), size)


def feature_matrix(features: Features) -> np.ndarray:
    """(N_STATES, F) phi of every state within one action block."""
    phi = np.zeros((N_STATES, features.size))
    np.add.at(phi, (np.arange(N_STATES)[:, None], features.active), 1.0)
    return phi


def features_of(config: LSPIConfig) -> Features:
    return tile_features(config.tilings, config.tile_width, config.exact)


THESIS_RANK = int(np.linalg.matrix_rank(feature_matrix(thesis_features())))


def _sum_columns(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """sum_t x[m, ..., idx[m, t]] in tiling order (a fixed order: same bits in any batch)."""
    rows = np.arange(x.shape[0])
    total = x[rows, ..., idx[:, 0]]
    for t in range(1, idx.shape[1]):
        total = total + x[rows, ..., idx[:, t]]
    return total


class LSPILearner(Learner):
    """A batch of online LSPI learners (algorithm 2), one per game, with the Learner's interface.

    `q` (B, 24, 88) is the value table of the current weights, refreshed at every
    policy improvement (so the behaviour policy pi_l stays fixed for K samples);
    `inverse` (B, 88, F, F) holds each block's Gamma_a^-1, `w` (B, 88, F) the solution
    B_a z_a of the samples so far (z, line 10, lives only in it), `theta` (B, 88, F) the weights
    of the policy in force (w at the last improvement), `samples` (B,) the samples learned.
    """

    def __init__(self, n_games: int, stream: UniformStream, config: LearnerConfig = LearnerConfig(),
                 lspi: LSPIConfig = LSPIConfig(), features: Features | None = None):
        super().__init__(n_games, stream, config, "q")  # acts as the Q-learner does (epsilon-greedy on q)
        self._rows = np.arange(n_games)
        self.lspi = lspi
        self.features = features or features_of(lspi)
        f = self.features.size
        self.inverse = np.zeros((n_games, N_ACTIONS, f, f))
        self.inverse[..., np.arange(f), np.arange(f)] = 1.0 / lspi.ridge  # Gamma_0 = delta I (line 3)
        self.theta = np.zeros((n_games, N_ACTIONS, f))
        self.w = np.zeros((n_games, N_ACTIONS, f))  # B z, kept current sample by sample
        self.samples = np.zeros(n_games, dtype=np.int64)
        self.improvements = np.zeros(n_games, dtype=np.int64)
        self._dirty = np.zeros((n_games, N_ACTIONS), dtype=bool)

    def learn(self, states: np.ndarray, actions: np.ndarray, rewards: np.ndarray, mask: np.ndarray,
              round_index: np.ndarray | None = None) -> np.ndarray:
        """Lines 8-15 for the games in `mask`; returns the games that improved their policy."""
        mask = np.asarray(mask, dtype=bool)
        if not mask.any():
            return np.zeros(0, dtype=np.int64)
        g, s, a = self._rows[mask], np.asarray(states)[mask], np.asarray(actions)[mask]
        r = np.asarray(rewards, dtype=np.float64)[mask]
        idx = self.features.active[s]  # (m, T)
        block = self.inverse[g, a]  # (m, F, F), a copy
        u = _sum_columns(block, idx)  # B phi (B is symmetric: also phi^T B)
        denom = 1.0 + _sum_columns(u[:, None, :], idx)[:, 0]  # 1 + phi^T B phi
        gain = u / denom[:, None]  # the new B phi (Sherman-Morrison)
        block -= gain[:, :, None] * u[:, None, :]
        self.inverse[g, a] = block
        # The running solution w_a = B_a z_a, kept by the same rank-one step (recursive least
        # squares: w += B_new phi (r - phi^T w)), so an improvement only copies it (lines 12-13).
        w = self.w[g, a]
        w += gain * (r - _sum_columns(w[:, None, :], idx)[:, 0])[:, None]
        self.w[g, a] = w
        self._dirty[g, a] = True
        self.counts[g, s, a] += 1
        self.samples[g] += 1
        due = g[self.samples[g] % self.lspi.improve_every == 0]
        if due.size:
            self.improve(due)
        return due

    def improve(self, games: np.ndarray) -> None:
        """Lines 12-14 for `games`: theta_a = B_a z_a for the blocks sampled since the last improvement."""
        rows, a = np.nonzero(self._dirty[games])
        g = np.asarray(games)[rows]
        theta = self.w[g, a]  # (m, F): B_a z_a, kept current by learn()
        self.theta[g, a] = theta
        active = self.features.active
        q = theta[:, active[:, 0]]
        for t in range(1, active.shape[1]):
            q = q + theta[:, active[:, t]]
        self.q[g, :, a] = q
        self._dirty[g, a] = False
        self.improvements[games] += 1


def weights_digest(theta: np.ndarray) -> str:
    """A short fingerprint of one learner's weights (hex), recorded so a rebuild can prove it matched."""
    import hashlib
    return hashlib.sha256(np.ascontiguousarray(theta, dtype=np.float64).tobytes()).hexdigest()[:16]


def dense_sherman_morrison(inverse: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(A + u v^T)^-1 from A^-1 (n x n): the update the thesis's dense LSPI pays per sample (reference)."""
    au = inverse @ u
    va = v @ inverse
    return inverse - np.outer(au, va) / (1.0 + v @ au)


def play_lspi(personas, seeds, rounds: int, config: LearnerConfig, lspi: LSPIConfig, observed_source: str,
              progress, snapshot_every: int | None, reward_bonus: str) -> tuple:
    """run_games(mode="lspi"): every game learns by LSPILearner, all stepped in lockstep.

    The games are core/games.py's (the study's per-game "deal" and "user"
    streams), the learner draws from the "agent" stream as the Q-learner does
    and greedy snapshots from "snapshot", so a game here is the same game as a
    session's learner service plays. A game that finished its rounds keeps
    stepping with its results frozen and learns nothing. Returns core/simulate.py
    SimResult's fields: (q, counts, picks, inconsistent, turns, snapshots).
    Errors: ValueError for a rounds count that is not one int >= 0.
    """
    n = len(personas)
    if len(seeds) != n:
        raise ValueError("one seed per game")
    if not isinstance(rounds, (int, np.integer)) or rounds < 0:
        raise ValueError("an LSPI batch plays one rounds count >= 0 for all its games")
    games = MemoryGames(personas, seeds, observed_source, reward_bonus)
    learner = LSPILearner(n, UniformStream(seeds, "agent"), config, lspi)
    rows = np.arange(n)
    picks = np.zeros((n, rounds), dtype=np.int32)
    inconsistent = np.zeros((n, rounds), dtype=np.int32)
    open_inconsistent = np.zeros(n, dtype=np.int32)
    done = games.round_index >= rounds
    learner.start_round(games.round_index)
    every = int(snapshot_every or 0)
    snapshots = np.zeros((n, rounds // every if every else 0, N_STATES), dtype=np.int64)
    snap_stream = UniformStream(seeds, "snapshot") if every else None
    steps = 0
    while not done.all():
        steps += 1
        states = games.observe()
        actions, _ = learner.suggest(states, games.round_index)
        out = games.act(actions)
        learner.learn(states, actions, out.rewards, out.learned & ~done)
        open_inconsistent += out.considered & ~out.consistent
        if not out.round_over.any():
            continue
        g = rows[out.round_over & ~done]
        r = games.round_index[g]  # rounds now complete
        picks[g, r - 1] = out.picks[g]
        inconsistent[g, r - 1] = open_inconsistent[g]
        done |= games.round_index >= rounds
        if every:
            due = g[(r % every == 0) & (r <= snapshots.shape[1] * every)]
            if due.size:
                snapshots[due, games.round_index[due] // every - 1] = greedy(learner.q[due],
                                                                              snap_stream.take(N_STATES, due))
        over = rows[out.round_over]
        open_inconsistent[over] = 0
        games.new_round(over)
        learner.start_round(games.round_index, over)
        if progress is not None:
            progress(int(np.minimum(games.round_index, rounds).sum()))
    return learner.q, learner.counts, picks, inconsistent, steps, snapshots if every else None
