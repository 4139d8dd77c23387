"""The calibration round: a few suggestions with known answers that tell a user's frame (chapter 8, future work 2).

Rule: before the game, the robot shows a card (the observed card) and gives a
suggestion about a card whose place it knows; the user picks. Two kinds, in
turn, each naming a different card under each of the four frames
(core/frames.py), so one followed suggestion tells the frame:
  "exact": "Try at row x and column y" alone, the card in the top or bottom
           row (a frame mirrors it to four different cards);
  "head":  a diagonal head turn alone, the observed card in the middle row
           away from the edges (the four diagonal cells are disjoint).
Speech needs hearing and the head needs sight, so a deaf or a blind user is
still calibrated by the other kind. The board is fully covered but for the
observed card, and the user remembers nothing yet.

Inference (`infer`): the frame of highest posterior, uniform prior, ties to the
lower frame (the robot's own first). A user follows a suggestion of a kind
with an unknown rate w (it may not have heard, seen or cared) and otherwise
picks any covered card: P(pick | frame f, w) = w * [pick in C_f] / |C_f| +
(1 - w) / |covered|, C_f the cards the suggestion names in frame f; w is
integrated out per kind over FOLLOW_GRID (uniform), so a user who ignores one
kind is judged on the other. Pure numpy; the randomness of the design is the
generator passed in. `respond` plays the simulated user (core/kernels.py
`users_respond`, the game's own rule) through a round.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import Persona

from . import kernels
from .actions import HEARING_EXACT, HEARING_NOTHING, VISUAL_NOTHING, VISUAL_PARTS, code_of
from .frames import FRAME_HEAR, FRAME_VIS, N_FRAMES
from .geometry import ALL_CARDS, CELL_INDEX, CELL_MASK, COLS, ROWS, card_of
from .user import frames_of, persona_arrays, reading_codes

KINDS = ("exact", "head")
EXACT_ACTION = code_of(HEARING_EXACT, VISUAL_NOTHING)
# the four diagonal head turns (thesis table 4.3 codes 6-9) and the cells they name
DIAGONALS = ((6, "TOP_LEFT"), (7, "TOP_RIGHT"), (8, "BOTTOM_LEFT"), (9, "BOTTOM_RIGHT"))
HEAD_ACTIONS = np.array([code_of(HEARING_NOTHING, VISUAL_PARTS.index((h, 0))) for h, _ in DIAGONALS])
HEAD_CELLS = np.array([CELL_INDEX[c] for _, c in DIAGONALS])
# w in (0, 1): near 0 a user ignores the kind; never 1, where one random pick would rule a frame out
FOLLOW_GRID = np.linspace(0.0, 1.0, 21)[1:-1]
_EDGE_ROWS = np.array([0, ROWS - 1])


class Trials(NamedTuple):
    """A calibration round per session: every array is (sessions, n), trial by trial."""

    kind: np.ndarray  # index into KINDS
    observed: np.ndarray  # the card shown
    match: np.ndarray  # the card the suggestion is about (the known answer)
    action: np.ndarray  # the composite action given (core/actions.py code)

    @property
    def covered(self) -> np.ndarray:
        return ALL_CARDS & ~(np.int64(1) << self.observed)


def design(sessions: int, n: int, rng: np.random.Generator) -> Trials:
    """`n` trials for each of `sessions` rounds, kinds alternating from "exact" (see the module rule)."""
    if n < 1:
        raise ValueError("a calibration round needs at least one suggestion")
    shape = (sessions, n)
    kind = np.broadcast_to(np.arange(n) % len(KINDS), shape).copy()
    u = rng.random((4,) + shape)  # one set of draws per trial, used or not
    # exact: the answer in an edge row, the observed card in the middle row (never one of the answer's mirrors)
    exact_match = card_of(_EDGE_ROWS[(u[0] * 2).astype(np.int64)], (u[1] * COLS).astype(np.int64))
    exact_observed = card_of(1, (u[2] * COLS).astype(np.int64))
    # head: the observed card in the middle row, columns 1..COLS-2; a diagonal; the answer in its cell
    head_observed = card_of(1, 1 + (u[0] * (COLS - 2)).astype(np.int64))
    diagonal = (u[1] * len(DIAGONALS)).astype(np.int64)
    cells = CELL_MASK[head_observed, HEAD_CELLS[diagonal]].astype(np.int64)
    head_match = np.empty(shape, dtype=np.int64)
    kernels.pick_batch(cells.reshape(-1), np.ascontiguousarray(u[2].reshape(-1)), head_match.reshape(-1))
    exact = kind == 0
    return Trials(kind, np.where(exact, exact_observed, head_observed), np.where(exact, exact_match, head_match),
                  np.where(exact, EXACT_ACTION, HEAD_ACTIONS[diagonal]))


def named_cards(trials: Trials) -> np.ndarray:
    """(sessions, n, frames): the covered cards each trial's suggestion names to a user in each frame."""
    exact = (trials.kind == 0)[..., None]
    obs, match = trials.observed[..., None], trials.match[..., None]
    f = np.arange(N_FRAMES)
    hear = FRAME_HEAR[f, obs, match, HEARING_EXACT]
    head_part = (trials.action % len(VISUAL_PARTS))[..., None]
    vis = FRAME_VIS[f, obs, match, head_part]
    return np.where(exact, hear, vis) & trials.covered[..., None]


def _per_trial(trials: Trials, picks: np.ndarray) -> np.ndarray:
    """(kinds, follow rates, sessions, n, frames): log P(pick | frame, w) of each trial, 0 in the other kinds' rows."""
    named = named_cards(trials)
    size = np.bitwise_count(named)
    hit = (named >> np.asarray(picks)[..., None]) & 1
    p_follow = hit / np.maximum(size, 1)  # (S, n, F); 0 where the frame names no covered card
    p_random = 1.0 / np.bitwise_count(trials.covered)[..., None]
    w = FOLLOW_GRID[:, None, None, None]
    per_trial = np.log(w * p_follow + (1 - w) * p_random)  # (W, S, n, F)
    mine = trials.kind[None, None, :, :, None] == np.arange(len(KINDS))[:, None, None, None, None]
    return np.where(mine, per_trial[None], 0.0)


def _marginal(by_w: np.ndarray) -> np.ndarray:
    """Sum over kinds of log mean over w of exp(log-likelihood): (kinds, W, S, F) -> (S, F)."""
    top = by_w.max(axis=1, keepdims=True)
    return (top[:, 0] + np.log(np.exp(by_w - top).mean(axis=1))).sum(axis=0)


def log_likelihood(trials: Trials, picks: np.ndarray) -> np.ndarray:
    """(sessions, frames): log P(picks | frame), follow rates integrated out per kind (module rule)."""
    return _marginal(_per_trial(trials, picks).sum(axis=3))


def _decide(ll: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    post = np.exp(ll - ll.max(axis=1, keepdims=True))
    return np.argmax(ll, axis=1), post / post.sum(axis=1, keepdims=True)


def infer(trials: Trials, picks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frame (sessions,), posterior (sessions, frames)) from a round's picks (trials (sessions, n), picks
    (sessions, n) card indices); uniform prior, ties to the lower frame (the robot's own first)."""
    return _decide(log_likelihood(trials, picks))


def respond(personas: Sequence[Persona], frames, trials: Trials, rng: np.random.Generator) -> np.ndarray:
    """(sessions, n): the simulated users' picks in a calibration round (one persona and frame per session).

    Each trial is a turn of the game's own user rule (core/kernels.py `users_respond`)
    with an empty memory: the user considers the suggestion with its focus, hears
    and sees as its features allow, reads it in its frame, and otherwise picks a
    covered card at random. Draws: DRAWS_PER_TURN uniforms per trial from `rng`.
    """
    s, n = trials.match.shape
    p_consider, q_hear, _, seen = persona_arrays(personas)
    frame = frames_of(frames, s)
    sees = [np.ascontiguousarray(seen[:, i]) for i in range(3)]
    memory = np.zeros(s, dtype=np.int64)
    no = np.zeros(s, dtype=bool)
    picks = np.empty((s, n), dtype=np.int64)
    for t in range(n):
        u = np.ascontiguousarray(rng.random((s, kernels.DRAWS_PER_TURN)))
        covered = np.ascontiguousarray(trials.covered[:, t])
        intended = np.empty(s, dtype=np.int64)
        kernels.pick_batch(covered, np.ascontiguousarray(u[:, 1]), intended)
        second, cand = np.empty(s, dtype=np.int64), np.empty(s, dtype=np.int64)
        considered, consistent = np.empty(s, dtype=bool), np.empty(s, dtype=bool)
        kernels.users_respond(kernels.TABLES, memory, np.ascontiguousarray(trials.action[:, t]),
                              np.ascontiguousarray(trials.observed[:, t]), np.ascontiguousarray(trials.match[:, t]),
                              intended, no, covered, u, p_consider, q_hear, *sees, reading_codes(personas), frame,
                              second, considered, consistent, cand)
        picks[:, t] = second
    return picks


def accuracy(personas: Sequence[Persona], frames: Sequence[int], lengths: Sequence[int], sessions: int,
             rng: np.random.Generator) -> np.ndarray:
    """(personas, lengths): the share of `sessions` rounds of each length whose inferred frame is the true one.

    One round of max(lengths) trials per session; a shorter round is its first trials."""
    flat = [p for p in personas for _ in range(sessions)]
    truth = np.repeat(np.asarray(frames, dtype=np.int64), sessions)
    trials = design(len(flat), max(lengths), rng)
    picks = respond(flat, truth, trials, rng)
    prefix = np.cumsum(_per_trial(trials, picks), axis=3)  # a round of n trials is its first n
    out = np.empty((len(personas), len(lengths)))
    for j, n in enumerate(lengths):
        right = _decide(_marginal(prefix[:, :, :, n - 1]))[0] == truth
        out[:, j] = right.reshape(len(personas), sessions).mean(axis=1)
    return out
