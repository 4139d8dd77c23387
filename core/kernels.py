"""The compiled inner loops of core/: draws, deal, user, learner, reward, game and oracle (numba).

Rule: one code path. Each rule is one scalar function of one game (`_user_*`,
`_suggest`, `_learn`, `_reward`, `_deal`, `draw`); the batch kernels below call
them in a loop over games, whether the batch holds one game (a live service:
core/user.py, core/learning.py, core/rng.py, core/board.py call these with a
batch of one) or thousands (core/simulate.py's `play`, which runs a whole game
per call without returning to Python). Draws are the same counts per event as
the numpy streams of core/rng.py took (DRAWS_PER_TURN user draws per turn,
DRAWS_PER_SUGGESTION agent draws per suggestion, 18 deal draws per round, 24
snapshot draws per snapshot), and every float is computed with the same
operations in the same order as the numpy code it replaced, so results are
bit for bit those of the numpy lockstep simulator (tests/test_study_digests.py).

Why one file: numba's on-disk cache (`cache=True`) is keyed on the source file
of each kernel, not on the functions it calls; with every kernel here a change
to any rule invalidates them all. Lookup tables (appendix B, the state
geometry) are arguments (`TABLES`), never globals, for the same reason: numba
freezes globals into the cached code.

Why `_nrt=False` on the scalar rules and `_play_round`: numba counts references
to arrays atomically, and a call that passes arrays (the 11 of `Tables`) or a
row view (`q[g, s]`) increfs and decrefs each one; in the step loop that was
60% of the time (perf). Functions that never allocate compile without it; so
rows are indexed in place (`_greedy(q, g, s, u)`), never viewed, in the loops.

Pure: no I/O, no clock; randomness is the SplitMix64 streams (keys, positions)
passed in. The cache lives in __pycache__ beside this file, or, where that is
not writable, in numba's user-wide cache dir (NUMBA_CACHE_DIR overrides both).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from .actions import ACTION_HEARING, ACTION_VISUAL, HEARING_SMILE, N_ACTIONS, VISUAL_GAZE
from .geometry import ALL_CARDS, CELL_MASK, CELL_OF, LEVEL_OF_COUNT, N_CARDS, N_STATES, STATE_INDEX
from .frames import FRAME_HEAR, FRAME_VIS
from .interpretation import COMPOUND, HEAR_SET, READ_COMPOUND, READ_TOGETHER, VIS_SET

# Stream roles, in the column order of a batch's `keys` and `pos` (core/rng.py ROLES).
DEAL, AGENT, USER, SNAPSHOT = 0, 1, 2, 3
DRAWS_PER_TURN = 5  # user: first pick, intended card, focus, hearing, choice in the candidate set
DRAWS_PER_SUGGESTION = 4  # agent: psi, epsilon, random action, tie
MODE_Q, MODE_REUSE, MODE_FIXED = 0, 1, 2
HOW_GREEDY, HOW_EXPLORE, HOW_BIAS, HOW_FIXED = 0, 1, 2, 3
BONUS_CORRECT, BONUS_CONSISTENT, BONUS_MATCH = 0, 1, 2  # core/reward.py's rules
INCONSISTENT = -3.0
NEVER = np.iinfo(np.int64).max  # memory stamp of a card not remembered
# Per-turn record columns (`play(..., record=...)`): int32, one row per recorded turn.
TRACE_FIELDS = ("game", "step", "round", "first", "observed", "match", "covered", "nis", "from_memory",
                "state", "action", "second", "considered", "consistent")
_T = {name: i for i, name in enumerate(TRACE_FIELDS)}
T_GAME, T_STEP, T_ROUND, T_FIRST, T_OBSERVED, T_MATCH, T_COVERED, T_NIS, T_FROM_MEMORY, T_STATE, T_ACTION, \
    T_SECOND, T_CONSIDERED, T_CONSISTENT = (_T[n] for n in TRACE_FIELDS)
T_CANDIDATES = len(TRACE_FIELDS)  # and one more column: the candidate set
RECORD_NONE, RECORD_ALL, RECORD_CONSIDERABLE = 0, 1, 2  # considerable: the match was not remembered

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11, _ONE = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11), np.uint64(1)
_TO_UNIT = 2.0 ** -53


class Tables(NamedTuple):
    """The lookup tables every kernel reads, passed as an argument (see the module rule)."""

    hear_set: np.ndarray  # (18, 18, 8) int64: appendix B, hearing parts
    vis_set: np.ndarray  # (18, 18, 11) int64: appendix B, visual parts
    action_hearing: np.ndarray  # (88,) int64
    action_visual: np.ndarray  # (88,) int64
    cell_of: np.ndarray  # (18, 18) int64
    cell_mask: np.ndarray  # (18, 9) int64
    state_index: np.ndarray  # (9, 3) int64
    level_of_count: np.ndarray  # (19,) int64
    compound: np.ndarray  # (8, 11) int64: a "compound" reader's diagonal part of a pair, or -1
    frame_hear: np.ndarray  # (4, 18, 18, 8) int64: hear_set as a user in each frame reads it (core/frames.py)
    frame_vis: np.ndarray  # (4, 18, 18, 11) int64


TABLES = Tables(*(np.ascontiguousarray(t, dtype=np.int64) for t in (
    HEAR_SET, VIS_SET, ACTION_HEARING, ACTION_VISUAL, CELL_OF, CELL_MASK, STATE_INDEX, LEVEL_OF_COUNT, COMPOUND,
    FRAME_HEAR, FRAME_VIS)))


def as_batch(x, n: int, dtype) -> np.ndarray:
    """`x` as a C-contiguous (n,) array of `dtype` for a batch kernel (a scalar or (1,) is broadcast).

    The cheap path first: a live service passes arrays that already fit, and
    numpy's conversions cost more than the kernel call itself in a batch of one
    (the test is attribute reads only: `np.asarray(x, dtype)` alone costs more).
    """
    if type(x) is np.ndarray and x.shape == (n,) and x.dtype is _DTYPES.get(dtype) and (
            n < 2 or x.strides[0] == x.itemsize):
        return x
    a = np.asarray(x, dtype=dtype)
    if a.shape == (n,) and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(np.broadcast_to(a, (n,)))


_DTYPES = {t: np.dtype(t) for t in (bool, np.bool_, np.int8, np.int32, np.int64, np.float64, np.uint64)}


# --- scalar rules -----------------------------------------------------------------------------

@njit(cache=True, inline="always")
def draw(key, index):
    """SplitMix64: uniform [0, 1) draw number `index` of the stream `key` (core/rng.py)."""
    z = key + (np.uint64(index) + _ONE) * _GAMMA
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    z = z ^ (z >> _S31)
    return np.float64(z >> _S11) * _TO_UNIT


@intrinsic
def _popcount(typingctx, x):
    """Set bits of a card mask (int64): LLVM's ctpop, one instruction where the CPU has it."""
    if not isinstance(x, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        return builder.ctpop(context.cast(builder, args[0], x, types.int64))
    return types.int64(x), codegen


@intrinsic
def _bit_index(typingctx, single):
    """Index of the lowest set bit of `single` (int64, not 0): LLVM's cttz."""
    if not isinstance(single, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        value = context.cast(builder, args[0], single, types.int64)
        return builder.cttz(value, ir.Constant(ir.IntType(1), 1))
    return types.int64(single), codegen


@njit(cache=True, _nrt=False)
def _pick(mask, u):
    """The floor(u*n)-th set bit (ascending) of a card mask; -1 for an empty mask."""
    n = _popcount(mask)
    if n == 0:
        return -1
    k = min(np.int64(u * n), n - 1)
    for _ in range(k):  # strip the k lowest set bits
        mask &= mask - 1
    return _bit_index(mask & -mask)


@njit(cache=True, _nrt=False)
def _deal(u, partner, order):
    """A deal from 18 draws (core/board.py): stable argsort; places 2k, 2k+1 of it are a pair.

    Writes `partner` (18,) and the order (18,) of the places into `order`."""
    for i in range(N_CARDS):
        order[i] = i
    for i in range(1, N_CARDS):  # insertion sort: stable, 18 items
        j = i
        while j > 0 and u[order[j - 1]] > u[order[j]]:
            order[j - 1], order[j] = order[j], order[j - 1]
            j -= 1
    for k in range(0, N_CARDS, 2):
        partner[order[k]] = order[k + 1]
        partner[order[k + 1]] = order[k]


@njit(cache=True, _nrt=False)
def _state(t, observed, match, covered):
    """Thesis 4.1 (core/geometry.py state_of): the cell of the match and its covered count's level."""
    cell = t.cell_of[observed, match]
    n = _popcount(t.cell_mask[observed, cell] & covered)
    return t.state_index[cell, t.level_of_count[n]]


@njit(cache=True, _nrt=False)
def _user_nis(memory, covered):
    """No-information set: covered cards not remembered (never empty while a card is covered)."""
    nis = covered & ~memory
    return nis if nis != 0 else covered


@njit(cache=True, _nrt=False)
def _user_first_pick(memory, partner, covered, u):
    """A card of a wholly remembered pair, else a covered card not remembered (core/user.py)."""
    known = 0
    rest = memory
    while rest:  # the remembered cards whose partner is remembered too
        bit = rest & -rest
        rest ^= bit
        if (memory >> partner[_bit_index(bit)]) & 1:
            known |= bit
    return _pick(known if known != 0 else covered & ~memory, u)


@njit(cache=True, _nrt=False)
def _user_respond(t, action, observed, match, intended, from_memory, nis, u_focus, u_hear, u_choice,
                  p_consider, q_hear, sees_smile, sees_head, sees_gaze, reading, frame):
    """(second, considered, consistent, candidates) after a suggestion (core/user.py); `reading`: the
    persona's whole readings (core/interpretation.py READINGS, 0 = the thesis's user); read in `frame`
    (core/frames.py; frame 0's tables are appendix B's)."""
    considered = (not from_memory) and u_focus < p_consider
    heard = u_hear < q_hear
    h, v = t.action_hearing[action], t.action_visual[action]
    hear_seen = sees_smile if h == HEARING_SMILE else (h > HEARING_SMILE and heard)
    vis_seen = sees_gaze if v == VISUAL_GAZE else (v > VISUAL_GAZE and sees_head)
    if reading & READ_TOGETHER:  # speech and head only as one gesture: alone, neither is perceived
        spoken, turned = h > HEARING_SMILE, v > VISUAL_GAZE
        hear_seen = hear_seen and (turned or not spoken)
        vis_seen = vis_seen and (spoken or not turned)
    cand = nis
    if reading & READ_COMPOUND and hear_seen and vis_seen and t.compound[h, v] >= 0:
        cand &= t.frame_vis[frame, observed, match, t.compound[h, v]]  # the pair means the diagonal between them
    else:
        if hear_seen:
            cand &= t.frame_hear[frame, observed, match, h]
        if vis_seen:
            cand &= t.frame_vis[frame, observed, match, v]
    consistent = cand != 0
    chosen = _pick(cand if consistent else nis, u_choice)
    second = match if from_memory else (chosen if considered else intended)
    return second, considered, consistent, (cand if consistent else 0)


@njit(cache=True, _nrt=False)
def _user_end_turn(g, first, second, matched, memory, stamp, clock, capacity):
    """Memory after a turn: a miss adds both cards (oldest leave), a match removes them."""
    if matched:
        stamp[g, first] = NEVER
        stamp[g, second] = NEVER
        memory[g] &= ~((1 << first) | (1 << second))
        return
    evict = _popcount(memory[g]) + 2 - capacity[g]
    for nth in range(1, 3):
        if evict >= nth:  # the oldest remembered card leaves (stamps are distinct; others are NEVER)
            oldest, rest = -1, memory[g]
            while rest:
                card = _bit_index(rest & -rest)
                rest &= rest - 1
                if oldest < 0 or stamp[g, card] < stamp[g, oldest]:
                    oldest = card
            stamp[g, oldest] = NEVER
            memory[g] &= ~(1 << oldest)
    stamp[g, first] = clock[g]
    stamp[g, second] = clock[g] + 1
    memory[g] |= (1 << first) | (1 << second)
    clock[g] += 2


@njit(cache=True, _nrt=False)
def _greedy(q, g, s, u_tie):
    """argmax of the Q row q[g, s], ties broken by the draw: the floor(u*n)-th tied action (core/learning.py).

    The row is indexed in place (a view of it would cost two atomic reference
    counts per call). The max runs in four independent lanes: a max is exact,
    so any order gives the same value, and four chains hide the compare's
    latency that one 88-long chain would pay in full.
    """
    size = q.shape[2]
    m0 = q[g, s, 0]
    m1, m2, m3 = m0, m0, m0
    a = 0
    while a + 4 <= size:
        x0, x1, x2, x3 = q[g, s, a], q[g, s, a + 1], q[g, s, a + 2], q[g, s, a + 3]
        m0 = x0 if x0 > m0 else m0
        m1 = x1 if x1 > m1 else m1
        m2 = x2 if x2 > m2 else m2
        m3 = x3 if x3 > m3 else m3
        a += 4
    while a < size:
        x0 = q[g, s, a]
        m0 = x0 if x0 > m0 else m0
        a += 1
    m0 = m1 if m1 > m0 else m0
    m2 = m3 if m3 > m2 else m2
    best = m2 if m2 > m0 else m0
    n = 0
    for a in range(size):
        n += q[g, s, a] == best
    k = 0 if n == 1 else min(np.int64(u_tie * n), n - 1)
    for a in range(size):
        if q[g, s, a] == best:
            if k == 0:
                return a
            k -= 1
    return 0


@njit(cache=True, _nrt=False)
def _suggest(q, g, s, u_psi, u_eps, u_action, u_tie, epsilon, mode, psi, bias_action):
    """(action, how) of one suggestion in state s of game g (algorithms 1 and 5); psi's decay is the caller's."""
    if mode == MODE_FIXED:
        return bias_action, HOW_FIXED
    if u_eps < epsilon:
        action, how = min(np.int64(u_action * N_ACTIONS), N_ACTIONS - 1), HOW_EXPLORE
    else:
        action, how = _greedy(q, g, s, u_tie), HOW_GREEDY
    if mode == MODE_REUSE and u_psi < psi:
        action, how = bias_action, HOW_BIAS
    return action, how


@njit(cache=True, _nrt=False)
def _learn(q, counts, g, state, action, reward, alpha):
    """Eq. 5.2, Q + alpha * (r - Q) (core/learning.py q_update), and one more update counted."""
    old = q[g, state, action]
    q[g, state, action] = old + alpha * (reward - old)
    counts[g, state, action] += 1


@njit(cache=True, _nrt=False)
def _reward(hit, considered, consistent, size, holds_match, bonus):
    """(reward, learn) of a simulated turn (core/reward.py simulated_reward)."""
    if not considered:
        return 0.0, False
    if not consistent:
        return INCONSISTENT, True
    size = max(size, 1)
    paid = True if bonus == BONUS_CONSISTENT else (hit if bonus == BONUS_MATCH else holds_match)
    return (1.0 if hit else -1.0) + (1.0 / size if paid else 0.0), True


# --- batch kernels (a batch of one is a live service) ------------------------------------------

@njit(cache=True)
def draw_block(keys, pos, k, games, out):
    """The next `k` draws of each game in `games`: out[i, j] = draw pos[g] + j of keys[g]; pos += k."""
    for i in range(games.size):
        g = games[i]
        for j in range(k):
            out[i, j] = draw(keys[g], pos[g] + np.uint64(j))
        pos[g] += np.uint64(k)


@njit(cache=True)
def pick_batch(masks, u, out):
    for i in range(masks.size):
        out[i] = _pick(masks[i], u[i])


@njit(cache=True)
def deal_batch(u, faces, partner):
    """Faces (B, 18) and partners (B, 18) of a deal per row of 18 draws."""
    order = np.empty(N_CARDS, dtype=np.int64)
    for g in range(u.shape[0]):
        _deal(u[g], partner[g], order)
        for k in range(N_CARDS):
            faces[g, order[k]] = k // 2


@njit(cache=True)
def states_batch(t, observed, match, covered, out):
    for i in range(observed.size):
        out[i] = _state(t, observed[i], match[i], covered[i])


@njit(cache=True)
def users_nis(memory, covered, out):
    for g in range(covered.size):
        out[g] = _user_nis(memory[g], covered[g])


@njit(cache=True)
def users_first_pick(memory, partner, covered, u, out):
    for g in range(covered.size):
        out[g] = _user_first_pick(memory[g], partner[g], covered[g], u[g, 0])


@njit(cache=True)
def users_intend(memory, first, match, covered, u, intended, from_memory):
    for g in range(first.size):
        remembered = (memory[g] >> match[g]) & 1 == 1
        unaided = _pick(_user_nis(memory[g], covered[g]), u[g, 1])
        intended[g] = match[g] if remembered else unaided
        from_memory[g] = remembered


@njit(cache=True)
def users_respond(t, memory, actions, observed, match, intended, from_memory, covered, u, p_consider, q_hear,
                  sees_smile, sees_head, sees_gaze, reading, frames, second, considered, consistent, candidates):
    for g in range(actions.size):
        second[g], considered[g], consistent[g], candidates[g] = _user_respond(
            t, actions[g], observed[g], match[g], intended[g], from_memory[g], _user_nis(memory[g], covered[g]),
            u[g, 2], u[g, 3], u[g, 4], p_consider[g], q_hear[g], sees_smile[g], sees_head[g], sees_gaze[g],
            reading[g], frames[g])


@njit(cache=True)
def users_end_turn(first, second, matched, memory, stamp, clock, capacity):
    for g in range(first.size):
        _user_end_turn(g, first[g], second[g], matched[g], memory, stamp, clock, capacity)


@njit(cache=True)
def learners_suggest(q, states, keys, pos, epsilon, mode, psi, psi_decay, table, actions, how):
    """One suggestion per game from the next DRAWS_PER_SUGGESTION draws of its agent stream (keys, pos:
    core/rng.py UniformStream; pos += 4, whatever the mode); psi *= psi_decay after each pi-reuse
    suggestion (algorithm 5, line 9). One call draws and chooses: a live learner (a batch of one) pays
    one kernel dispatch per suggestion."""
    for g in range(states.size):
        s = states[g]
        k, p = keys[g], pos[g]
        actions[g], how[g] = _suggest(q, g, s, draw(k, p), draw(k, p + np.uint64(1)), draw(k, p + np.uint64(2)),
                                      draw(k, p + np.uint64(3)), epsilon[g], mode, psi[g], table[g, s])
        pos[g] = p + np.uint64(DRAWS_PER_SUGGESTION)
        if mode == MODE_REUSE:
            psi[g] = psi[g] * psi_decay


@njit(cache=True)
def learners_learn(q, counts, states, actions, rewards, mask, alpha):
    for g in range(states.size):
        if mask[g]:
            _learn(q, counts, g, states[g], actions[g], rewards[g], alpha[g])


@njit(cache=True)
def greedy_batch(q, u, out):
    """Greedy action of every row q[i, 0] of q (n, 1, A) with tie draws u (n,)."""
    for i in range(q.shape[0]):
        out[i] = _greedy(q, i, 0, u[i])


@njit(cache=True)
def reward_one(hit, considered, consistent, size, holds_match, bonus):
    """`_reward` of one turn: (reward, learn); a live learner's batch of one without array boxing."""
    return _reward(hit, considered, consistent, size, holds_match, bonus)


@njit(cache=True)
def rewards_batch(hit, considered, consistent, size, holds_match, bonus, reward, learn):
    for g in range(hit.size):
        reward[g], learn[g] = _reward(hit[g], considered[g], consistent[g], size[g], holds_match[g], bonus)


@njit(cache=True)
def _grown(trace, rows):
    """`trace` in a twice bigger array, its first `rows` rows copied.

    An element loop, not `bigger[:rows] = trace[:rows]`: numba's array-to-slice
    assignment compiles a formatted shape-mismatch error (string joins) that
    tripled the first run's compile time of `play`."""
    bigger = np.empty((2 * trace.shape[0] + 1024, trace.shape[1]), dtype=trace.dtype)
    for i in range(rows):
        for j in range(trace.shape[1]):
            bigger[i, j] = trace[i, j]
    return bigger


# --- a whole game per call ----------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _play_round(t, g, r, keys, pos, m, table, p_consider, q_hear, capacity, sees, reading, frame, epsilon, alpha,
                psi_decay, bonus, first_pick_observed, partner, q, counts, steps, memory, stamp, clock, turn, psi,
                record, trace, n_trace):
    """The turns of game g's round r from where `turn` ([matched, picks, inconsistent]) and psi[0] left
    them, until the board is clear or, when recording, `trace` is full; returns the rows recorded.

    Compiled without reference counting (nothing here allocates), so a turn costs no atomic
    operation: `play` grows a full trace and calls again, which resumes the round where it stopped.
    """
    matched, picks, inconsistent, p = turn[0], turn[1], turn[2], psi[0]
    while matched != ALL_CARDS:
        if record != RECORD_NONE and n_trace == trace.shape[0]:
            break
        steps[g] += 1
        ku, pu = keys[g, USER], pos[g, USER]
        pos[g, USER] += np.uint64(DRAWS_PER_TURN)
        covered = ALL_CARDS & ~matched
        first = _user_first_pick(memory[g], partner, covered, draw(ku, pu))
        covered &= ~(1 << first)
        match = partner[first]
        from_memory = (memory[g] >> match) & 1 == 1
        nis = _user_nis(memory[g], covered)
        intended = match if from_memory else _pick(nis, draw(ku, pu + np.uint64(1)))
        observed = first if first_pick_observed else intended
        state = _state(t, observed, match, covered)
        if m == MODE_FIXED:
            action = table[g, state]
        else:
            ka, pa = keys[g, AGENT], pos[g, AGENT]
            pos[g, AGENT] += np.uint64(DRAWS_PER_SUGGESTION)
            action, _ = _suggest(q, g, state, draw(ka, pa), draw(ka, pa + np.uint64(1)),
                                 draw(ka, pa + np.uint64(2)), draw(ka, pa + np.uint64(3)),
                                 epsilon, m, p, table[g, state])
            if m == MODE_REUSE:
                p = p * psi_decay
        second, considered, consistent, cand = _user_respond(
            t, action, observed, match, intended, from_memory, nis, draw(ku, pu + np.uint64(2)),
            draw(ku, pu + np.uint64(3)), draw(ku, pu + np.uint64(4)), p_consider[g], q_hear[g],
            sees[g, 0], sees[g, 1], sees[g, 2], reading[g], frame)
        hit = second == match
        _user_end_turn(g, first, second, hit, memory, stamp, clock, capacity)
        reward, learn = _reward(hit, considered, consistent, _popcount(cand), (cand >> match) & 1 == 1, bonus)
        if learn and m != MODE_FIXED:
            _learn(q, counts, g, state, action, reward, alpha)
        if record == RECORD_ALL or (record == RECORD_CONSIDERABLE and not from_memory):
            k = n_trace
            trace[k, T_GAME], trace[k, T_STEP], trace[k, T_ROUND] = g, steps[g] - 1, r
            trace[k, T_FIRST], trace[k, T_OBSERVED], trace[k, T_MATCH] = first, observed, match
            trace[k, T_COVERED], trace[k, T_NIS], trace[k, T_FROM_MEMORY] = covered, nis, from_memory
            trace[k, T_STATE], trace[k, T_ACTION], trace[k, T_SECOND] = state, action, second
            trace[k, T_CONSIDERED], trace[k, T_CONSISTENT], trace[k, T_CANDIDATES] = considered, consistent, cand
            n_trace += 1
        if hit:
            matched |= (1 << first) | (1 << second)
        picks += 2
        if considered and not consistent:
            inconsistent += 1
    turn[0], turn[1], turn[2], psi[0] = matched, picks, inconsistent, p
    return n_trace


@njit(cache=True, nogil=True)
def play(t, games, until, rounds, keys, pos, mode, cfg, table, p_consider, q_hear, capacity, sees, reading, frames,
         eps_tab, alpha_tab, psi0_tab, psi_decay, bonus, first_pick_observed,
         q, counts, picks_log, inconsistent_log, steps, round_index, memory, stamp, clock,
         snapshot_every, snapshots, record, trace, n_trace):
    """Play each game of `games` from its `round_index` up to round min(until, rounds[g]) (core/simulate.py).

    State (q, counts, logs, steps, round_index, memory, stamp, clock, pos) is
    updated in place, so a caller may play a batch in slices of rounds. With
    `record`, one int32 row per turn (TRACE_FIELDS) is appended to `trace`
    from row `n_trace`, the array doubled when full; returns (trace, rows).
    The turns are `_play_round`'s; this loop deals, keeps the logs and snapshots.
    """
    partner = np.empty(N_CARDS, dtype=np.int64)
    order = np.empty(N_CARDS, dtype=np.int64)
    u_deal = np.empty(N_CARDS)
    u_snap = np.empty(N_STATES)
    turn = np.zeros(3, dtype=np.int64)
    psi = np.zeros(1)
    for i in range(games.size):
        g = games[i]
        c = cfg[g]
        m = mode[g]
        stop = min(until, rounds[g])
        while round_index[g] < stop:
            r = round_index[g]
            for j in range(N_CARDS):
                u_deal[j] = draw(keys[g, DEAL], pos[g, DEAL] + np.uint64(j))
            pos[g, DEAL] += np.uint64(N_CARDS)
            _deal(u_deal, partner, order)
            memory[g] = 0
            for j in range(N_CARDS):
                stamp[g, j] = NEVER
            turn[0], turn[1], turn[2], psi[0] = 0, 0, 0, psi0_tab[c, r]
            while True:
                n_trace = _play_round(t, g, r, keys, pos, m, table, p_consider, q_hear, capacity, sees, reading,
                                      frames[g], eps_tab[c, r], alpha_tab[c, r], psi_decay[c], bonus,
                                      first_pick_observed, partner, q, counts, steps, memory, stamp, clock, turn,
                                      psi, record, trace, n_trace)
                if turn[0] == ALL_CARDS:
                    break
                trace = _grown(trace, n_trace)  # full: twice the rows, and the round goes on
            picks_log[g, r] = turn[1]
            inconsistent_log[g, r] = turn[2]
            r += 1
            round_index[g] = r
            if snapshot_every > 0 and r % snapshot_every == 0 and r <= snapshots.shape[1] * snapshot_every:
                for s in range(N_STATES):
                    u_snap[s] = draw(keys[g, SNAPSHOT], pos[g, SNAPSHOT] + np.uint64(s))
                pos[g, SNAPSHOT] += np.uint64(N_STATES)
                for s in range(N_STATES):
                    snapshots[g, r // snapshot_every - 1, s] = _greedy(q, g, s, u_snap[s])
    return trace, n_trace


# --- the oracle's expectation (core/oracle.py) --------------------------------------------------

@njit(cache=True)
def _value_table(bonus):
    """Expected reward of a uniform pick in a candidate set, by its size (0-18) and whether it holds
    the match (core/oracle.py): (19, 2). A table, so the 88 actions of a situation cost a popcount each."""
    out = np.empty((N_CARDS + 1, 2))
    for size in range(N_CARDS + 1):
        for hit in range(2):
            if size == 0:
                out[size, hit] = INCONSISTENT
                continue
            p_hit = hit / size
            if bonus == BONUS_CORRECT:
                paid = np.float64(hit)
            elif bonus == BONUS_CONSISTENT:
                paid = 1.0
            else:
                paid = p_hit
            out[size, hit] = 2.0 * p_hit - 1.0 + paid / size
    return out


@njit(cache=True, _nrt=False)
def _expected(t, observed, match, nis, q_hear, sees_smile, sees_head, sees_gaze, value, out, row, base, unheard):
    """E[reward | considered] of each of the 88 actions in one situation, into out[row] (out: (n, 88)).

    The visual part decides the unheard candidate set, so its 11 values are
    computed once (into the scratch arrays `base`, `unheard`: (11,)) and shared
    by the 8 hearing parts (same operations per action); `value` is `_value_table`'s.
    """
    for v in range(base.size):
        vis_seen = sees_gaze if v == VISUAL_GAZE else (v > VISUAL_GAZE and sees_head)
        base[v] = nis & (t.vis_set[observed, match, v] if vis_seen else -1)
        unheard[v] = value[_popcount(base[v]), (base[v] >> match) & 1]
    for a in range(N_ACTIONS):
        h, v = t.action_hearing[a], t.action_visual[a]
        if h == HEARING_SMILE:
            p_heard = 1.0 if sees_smile else 0.0
        elif h > HEARING_SMILE:
            p_heard = q_hear
        else:
            p_heard = 0.0
        if p_heard == 0.0:  # 0 * heard + 1 * unheard, exactly, for finite values
            out[row, a] = unheard[v]
            continue
        cand = base[v] & t.hear_set[observed, match, h]
        heard = value[_popcount(cand), (cand >> match) & 1]
        out[row, a] = p_heard * heard + (1 - p_heard) * unheard[v]


@njit(cache=True)
def expected_batch(t, observed, match, nis, q_hear, sees_smile, sees_head, sees_gaze, bonus, out):
    """`_expected` for n situations of one persona: out (n, 88)."""
    base = np.empty(t.vis_set.shape[2], dtype=np.int64)
    unheard = np.empty(t.vis_set.shape[2])
    value = _value_table(bonus)
    for i in range(observed.size):
        _expected(t, observed[i], match[i], nis[i], q_hear, sees_smile, sees_head, sees_gaze, value, out, i,
                  base, unheard)


@njit(cache=True, nogil=True)
def expected_sums(t, owner, rows, order, q_hear, sees, bonus, sums, counts):
    """Add the 88 expected rewards of each recorded situation to sums[owner[game], state], in `order`.

    `rows` are recorded turns (TRACE_FIELDS columns, core/simulate.py Trace.rows), `order` the
    lockstep order they are summed in (np.add.at's order before; floats add up the same way)."""
    values = np.empty((1, N_ACTIONS))
    base = np.empty(t.vis_set.shape[2], dtype=np.int64)
    unheard = np.empty(t.vis_set.shape[2])
    value = _value_table(bonus)
    for i in range(order.size):
        r = order[i]  # rows are indexed in place: a view per row costs two atomic reference counts
        o = owner[rows[r, T_GAME]]
        state = np.int64(rows[r, T_STATE])
        _expected(t, np.int64(rows[r, T_OBSERVED]), np.int64(rows[r, T_MATCH]), np.int64(rows[r, T_NIS]), q_hear[o],
                  sees[o, 0], sees[o, 1], sees[o, 2], value, values, 0, base, unheard)
        for a in range(N_ACTIONS):
            sums[o, state, a] += values[0, a]
        counts[o, state] += 1


def warm_up() -> tuple[float, int, int]:
    """Compile (first run) or load from the cache every kernel: (seconds, compiled, loaded from cache)."""
    from .rng import UniformStream  # noqa: F401  (imports the wrappers; they call the kernels below)
    t0 = time.perf_counter()
    _exercise()
    kernels = [f for f in globals().values() if hasattr(f, "stats") and hasattr(f, "py_func")]
    misses = sum(sum(f.stats.cache_misses.values()) for f in kernels)
    hits = sum(sum(f.stats.cache_hits.values()) for f in kernels)
    return time.perf_counter() - t0, misses, hits


def _exercise() -> None:
    """Call every batch kernel once with the argument types core/ uses."""
    from pairplay.schemas.config import LearnerConfig
    from .personas import PERSONAS
    from .simulate import run_games
    from .oracle import oracle_policies
    p = list(PERSONAS.values())[:2]
    run_games(p, [1, 2], 1, LearnerConfig(), snapshot_every=1)
    oracle_policies(p[:1], 1, 0, rounds=1, iterations=1)
