"""Fitting the simulated user of thesis 6.1.3 to a participant's recorded picks (maximum likelihood).

Rule: the fitted user is a persona of appendix A, i.e. the four features of
the simulated user (core/user.py) on the thesis's 1..6 scale, plus a lapse
rate that exists only in the fit. The likelihood of a recording is the
product, over its turns, of the probabilities the simulated user gives the
picks that were made:
- the first pick: uniform over the cards of the pairs it remembers whole, if
  any, else over the covered cards it does not remember;
- the observed card, when the recording's observed card is the user's intended
  card (the simulation's "intended" source): the remembered match, else uniform
  over the no-information set (NIS);
- the second pick: the remembered match if known; otherwise, with
  p = (focus - 1) * 0.2, the suggestion is considered: speech heard with
  q = (hearing - 1) * 0.2, smile, head and gaze seen as table 6.1 says for the
  sight level, and the pick is uniform over the candidate set (NIS when it is
  empty); otherwise the unaided card: the intended (= observed) card, or for
  a first-pick or gaze source a uniform card of the NIS.
Memory is not a hidden state: given the capacity m = memory + 1 it is a
deterministic function of the picks already made (core/kernels.py's
`users_end_turn`, replayed on the recorded picks), so the likelihood is exact.
Each pick is, with the lapse probability, a uniform covered card instead: a
person who does something the model calls impossible (picks a remembered card
first, ignores a known match) lowers the fit instead of zeroing it. The
simulator has no lapse: it is reported as a measure of how far the participant
is from the model.

The grid is every persona (6 x 6 x 6 x 6) x LAPSES, evaluated exactly; the
estimate is its maximum (exact ties go to the lower level: the smallest memory,
the lowest sight of a group of table 6.1). Uncertainty is the profile
likelihood: a level is in a feature's 95% set when 2 (max log L - max log L
with that level) <= 3.84 (the likelihood-ratio test, 1 degree of freedom).
p and q are also profiled on a 0.01 grid, the other features at their
estimate, for a finer interval than the 0.2 steps of the scale.
What one session cannot identify, the 95% sets show as wide: hearing when no
considered suggestion spoke, sight beyond the groups of table 6.1 (5 and 6,
3 and 4 perceive the same), memory above the most cards the session ever
asked the user to hold. Assumed, not fitted: appendix B's reading of each
part, the canonical frame of reference, uniform choice in a set, a user who
neither learns nor tires during the session (one set of features for all
turns).

Pure: numpy in, numpy out; no randomness.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pairplay.arguments import at, given, instance_argument
from pairplay.errors import InputError

from . import kernels
from .actions import ACTION_HEARING, ACTION_VISUAL, HEARING_SMILE, VISUAL_GAZE
from .geometry import ALL_CARDS, N_CARDS
from .user import UNKNOWN_PARTNER
from .interpretation import HEAR_SET, VIS_SET, consider_probability, hear_probability, memory_capacity, sees

LEVELS = np.arange(1, 7)  # the thesis's 1..6 scale
LAPSES = np.array([0.0, 0.01, 0.03, 0.1, 0.3, 0.6, 1.0])
FINE = np.round(np.linspace(0.0, 1.0, 101), 2)  # p and q profiled every 0.01
LR_95 = 3.841458820694124  # chi-square, 1 degree of freedom, 0.95
FEATURES = ("focus", "hearing", "sight", "memory")
SOURCES = ("intended", "first-pick", "gaze")
_CARDS = np.arange(N_CARDS, dtype=np.int64)


class Observations(NamedTuple):
    """One row per resolved turn, in play order (all arrays (T,) int64 unless said)."""

    game: np.ndarray  # which session / game the turn belongs to (memory starts empty in each round of each game)
    round: np.ndarray
    first: np.ndarray  # the two cards picked
    second: np.ndarray
    match: np.ndarray  # the first card's partner
    covered: np.ndarray  # mask of the cards covered before the first pick
    observed: np.ndarray  # the card the last suggestion was relative to (-1: no suggestion this turn)
    action: np.ndarray  # that suggestion's action code 0..87 (-1: none)
    partner: np.ndarray  # (T, 18) the deal's partner of every card (UNKNOWN_PARTNER: never seen)
    considered: np.ndarray  # recorded perception, 1/0 (a simulated participant's SuggestionPerceived); -1 unknown
    from_memory: np.ndarray  # recorded: the match was remembered (1/0); -1 unknown


class Fit(NamedTuple):
    levels: dict  # feature -> the estimate (1..6)
    lapse: float
    loglik: float  # at the estimate
    picks: int  # picks the likelihood covers
    grid: np.ndarray  # (memory, sight, hearing, focus, lapse) log-likelihood, every level 1..6
    profile: dict  # feature -> (6,) max log L with that level
    set95: dict  # feature -> levels in the 95% likelihood-ratio set
    fine: dict  # "p_consider" / "q_hear" -> (estimate, low, high) on the 0.01 grid
    evidence: dict  # counts: turns, suggestions, considerable ones and which parts they showed
    counted: tuple[int, int] | None  # recorded (considered, considerable) of a simulated participant


def _bits(x):
    return np.bitwise_count(np.asarray(x, dtype=np.int64)).astype(np.int64)


def _has(mask, card):
    return (np.asarray(mask, dtype=np.int64) >> np.asarray(card, dtype=np.int64)) & 1 == 1


def _share(mask, card):
    """P(a uniform card of `mask` is `card`): [card in mask] / |mask| (0 for an empty mask)."""
    n = _bits(mask)
    return np.where(_has(mask, card) & (n > 0), 1.0 / np.maximum(n, 1), 0.0)


def memory_before(obs: Observations, capacities: np.ndarray) -> np.ndarray:
    """(T, M) the memory (card mask) of the simulated user before each turn, one column per capacity.

    The simulated user's own rule (core/kernels.py `users_end_turn`) replayed on the recorded picks;
    memory is emptied at each new round of each game (a new deal).
    """
    caps = np.ascontiguousarray(capacities, dtype=np.int64)
    m = caps.size
    memory = np.zeros(m, dtype=np.int64)
    stamp = np.full((m, N_CARDS), kernels.NEVER, dtype=np.int64)
    clock = np.zeros(m, dtype=np.int64)
    out = np.empty((len(obs.first), m), dtype=np.int64)
    matched = obs.second == obs.match
    prev = None
    for t in range(len(obs.first)):
        key = (int(obs.game[t]), int(obs.round[t]))
        if key != prev:
            memory[:] = 0
            stamp[:] = kernels.NEVER
            prev = key
        out[t] = memory
        kernels.users_end_turn(np.full(m, obs.first[t]), np.full(m, obs.second[t]), np.full(m, bool(matched[t])),
                               memory, stamp, clock, caps)
    return out


def _known_pairs(mem: np.ndarray, partner: np.ndarray) -> np.ndarray:
    """(T, M) the remembered cards whose partner is remembered too."""
    inmem = (mem[..., None] >> np.arange(N_CARDS + 1)) & 1  # (T, M, 19): bit 18 (UNKNOWN_PARTNER) is never set
    idx = np.broadcast_to(partner[:, None, :], inmem.shape[:2] + (N_CARDS,))
    both = inmem[..., :N_CARDS] & np.take_along_axis(inmem, idx, axis=2)
    return (both << _CARDS).sum(-1)


class _Terms(NamedTuple):
    first: np.ndarray  # (T, M) model probability of the first pick
    observed: np.ndarray  # (T, M) of the observed card (1 where it is not a pick of the user)
    observed_legal: np.ndarray  # (T,) cards the lapse could give there (0: no term)
    from_memory: np.ndarray  # (T, M) bool
    unaided: np.ndarray  # (T, M) of the second pick without the suggestion
    read: np.ndarray  # (2, 2, T, M) of the second pick read with hearing part perceived x visual part perceived
    speech: np.ndarray  # (T,) the hearing part is speech (heard with q)
    smile: np.ndarray  # (T,) the hearing part is a smile
    gaze: np.ndarray  # (T,) the visual part is a gaze
    head: np.ndarray  # (T,) the visual part is a head movement
    shown: np.ndarray  # (T,) a suggestion was shown
    legal_first: np.ndarray  # (T,) covered cards at the first pick
    legal_second: np.ndarray  # (T,) at the second


def _terms(obs: Observations, source: str, mem: np.ndarray) -> _Terms:
    T = len(obs.first)
    first, second, match = (np.asarray(a, dtype=np.int64)[:, None] for a in (obs.first, obs.second, obs.match))
    cov = np.asarray(obs.covered, dtype=np.int64)[:, None]
    known = _known_pairs(mem, np.asarray(obs.partner, dtype=np.int64))
    p_first = _share(np.where(known != 0, known, cov & ~mem), first)
    cov2 = cov & ~(np.int64(1) << first)
    fm = _has(mem, match)
    nis = cov2 & ~mem
    nis = np.where(nis == 0, cov2, nis)
    shown = np.asarray(obs.action) >= 0
    observed = np.where(np.asarray(obs.observed) >= 0, obs.observed, obs.first).astype(np.int64)[:, None]
    intended = source == "intended"
    if intended:
        p_obs = np.where(fm, (observed == match).astype(float), _share(nis, observed))
        p_obs = np.where(shown[:, None], p_obs, 1.0)
        obs_legal = np.where(shown, _bits(cov2[:, 0]), 0)
    else:
        p_obs, obs_legal = np.ones_like(p_first), np.zeros(T, dtype=np.int64)
    # unaided: the card looked at (intended, gaze) when one was recorded, else a uniform card of the NIS
    looked = shown[:, None] & (source in ("intended", "gaze"))
    unaided = np.where(looked, (observed == second).astype(float), _share(nis, second))
    unaided = np.where(fm, (second == match).astype(float), unaided)
    action = np.where(shown, obs.action, 0)
    h, v = ACTION_HEARING[action].astype(np.int64), ACTION_VISUAL[action].astype(np.int64)
    hear = HEAR_SET[observed[:, 0], match[:, 0], h][:, None]
    vis = VIS_SET[observed[:, 0], match[:, 0], v][:, None]
    read = np.empty((2, 2) + mem.shape)
    for hp in (0, 1):
        for vp in (0, 1):
            cand = nis & (hear if hp else ALL_CARDS) & (vis if vp else ALL_CARDS)
            read[hp, vp] = _share(np.where(cand == 0, nis, cand), second)
    return _Terms(p_first, p_obs, obs_legal, fm, unaided, read, h > HEARING_SMILE, h == HEARING_SMILE,
                  v == VISUAL_GAZE, v > VISUAL_GAZE, shown, _bits(cov[:, 0]), _bits(cov2[:, 0]))


def sight_groups() -> list[tuple[int, ...]]:
    """Sight levels that perceive the same channels (table 6.1), lowest first: [(1,), (2,), (3, 4), (5, 6)]."""
    groups: dict[tuple, list[int]] = {}
    for level in LEVELS:
        groups.setdefault(tuple(sees(int(level))), []).append(int(level))
    return [tuple(g) for g in groups.values()]


def _second_given(terms: _Terms, k_sees: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(Q, T, M) P(second pick | considered) for each q, one sight level (sees: hearing, smile, head, gaze)."""
    vp = np.where(terms.gaze, k_sees[3], terms.head & k_sees[2]).astype(int)  # (T,)
    hp_smile = (terms.smile & k_sees[1]).astype(int)
    rows = np.arange(len(vp))
    heard, unheard = terms.read[1, vp, rows], terms.read[0, vp, rows]  # (T, M)
    fixed = terms.read[hp_smile, vp, rows]
    q = np.asarray(q, dtype=float)[:, None, None]
    return np.where(terms.speech[None, :, None], q * heard + (1 - q) * unheard, fixed[None])


def _log(x):
    with np.errstate(divide="ignore"):
        return np.log(x)


def _second_loglik(terms: _Terms, p: np.ndarray, read: np.ndarray, lapse: np.ndarray) -> np.ndarray:
    """(E, P, Q, M) summed log-likelihood of the second picks; read is (Q, T, M)."""
    p = np.asarray(p, dtype=float)[:, None, None, None]  # (P, 1, 1, 1)
    shown = terms.shown[:, None]
    model = np.where(terms.from_memory, terms.unaided, (1 - p) * terms.unaided + p * np.where(shown, read, 0.0))
    model = np.where(shown | terms.from_memory, model, terms.unaided)  # (P, Q, T, M)
    out = np.empty((len(lapse),) + model.shape[:2] + (model.shape[-1],))
    uniform = (1.0 / terms.legal_second)[:, None]
    for e, eps in enumerate(lapse):
        out[e] = _log((1 - eps) * model + eps * uniform).sum(axis=2)
    return out


def _pick_loglik(terms: _Terms, lapse: np.ndarray) -> np.ndarray:
    """(E, M) summed log-likelihood of the first picks and the intended (observed) cards."""
    out = np.empty((len(lapse), terms.first.shape[1]))
    has_obs = terms.observed_legal > 0
    u_obs = np.where(has_obs, 1.0 / np.maximum(terms.observed_legal, 1), 0.0)[:, None]
    for e, eps in enumerate(lapse):
        first = _log((1 - eps) * terms.first + eps / terms.legal_first[:, None]).sum(0)
        obs = np.where(has_obs[:, None], _log((1 - eps) * terms.observed + eps * u_obs), 0.0).sum(0)
        out[e] = first + obs
    return out


def loglik_grid(obs: Observations, source: str, lapses: np.ndarray = LAPSES) -> np.ndarray:
    """(6 memory, 6 sight, 6 hearing, 6 focus, E lapse) log-likelihood of the recorded picks (see the rule)."""
    if source not in SOURCES:
        raise ValueError(f"observed source must be one of {SOURCES}")
    lapses = np.asarray(lapses, dtype=float)
    mem = memory_before(obs, np.array([memory_capacity(int(m)) for m in LEVELS]))
    terms = _terms(obs, source, mem)
    p = np.array([consider_probability(int(f)) for f in LEVELS])
    q = np.array([hear_probability(int(h)) for h in LEVELS])
    picks = _pick_loglik(terms, lapses)  # (E, M)
    grid = np.empty((len(LEVELS),) * 4 + (len(lapses),))
    for group in sight_groups():
        second = _second_loglik(terms, p, _second_given(terms, sees(group[0]), q), lapses)  # (E, P, Q, M)
        total = second + picks[:, None, None, :]
        for level in group:
            grid[:, level - 1] = np.transpose(total, (3, 2, 1, 0))
    return grid


def _lr_set(profile: np.ndarray) -> list[int]:
    return [int(LEVELS[i]) for i in np.flatnonzero(2 * (profile.max() - profile) <= LR_95)]


def _fine_interval(values: np.ndarray, ll: np.ndarray) -> tuple[float, float, float]:
    best = int(np.argmax(ll))
    inside = values[2 * (ll[best] - ll) <= LR_95]
    return float(values[best]), float(inside.min()), float(inside.max())


def fit_user(obs: Observations, source: str, lapses: np.ndarray = LAPSES) -> Fit:
    """Maximum-likelihood persona (and lapse) of the recorded turns `obs`; see the module rule.

    `source` is the recording's observed-card source ("intended", "first-pick", "gaze").
    Raises InputError (a ValueError) for a recording without a single turn or an unknown `source`,
    ArgumentError (pairplay/arguments.py) for `obs` that is no Observations.
    """
    instance_argument(obs, Observations, "fit_user", "obs", "Observations (a read recording's `turns.observations`, "
                      "pairplay.read_turns)")
    if source not in SOURCES:
        raise InputError(f"source must be one of {', '.join(SOURCES)} (a read recording's "
                         f"`turns.config.observed_source`), got {given(source)}", at("fit_user", "source"))
    if len(obs.first) == 0:
        raise InputError("no turn to fit: the recording holds no resolved turn", at("fit_user", "obs"))
    lapses = np.asarray(lapses, dtype=float)
    grid = loglik_grid(obs, source, lapses)
    idx = np.unravel_index(int(np.argmax(grid)), grid.shape)  # C order: ties to the lower levels
    m, s, h, f, e = idx
    levels = {"memory": int(LEVELS[m]), "sight": int(LEVELS[s]), "hearing": int(LEVELS[h]), "focus": int(LEVELS[f])}
    axes = {"memory": 0, "sight": 1, "hearing": 2, "focus": 3}
    profile = {name: grid.max(axis=tuple(a for a in range(5) if a != ax)) for name, ax in axes.items()}
    set95 = {name: _lr_set(prof) for name, prof in profile.items()}
    # p and q on the fine grid, memory, sight and lapse at the estimate
    mem = memory_before(obs, np.array([memory_capacity(levels["memory"])]))
    terms = _terms(obs, source, mem)
    one = lapses[e:e + 1]
    picks = _pick_loglik(terms, one)[0, 0]
    by_q = _second_given(terms, sees(levels["sight"]), FINE)
    fine_ll = np.stack([_second_loglik(terms, FINE[i:i + 1], by_q, one)[0, 0, :, 0] for i in range(len(FINE))]) + picks
    # fine_ll: (P, Q)
    fine = {"p_consider": _fine_interval(FINE, fine_ll.max(axis=1)),
            "q_hear": _fine_interval(FINE, fine_ll.max(axis=0))}
    considerable = terms.shown & ~terms.from_memory[:, 0]
    evidence = {"turns": int(len(obs.first)), "suggestions": int(terms.shown.sum()),
                "considerable": int(considerable.sum()),
                "speech": int((considerable & terms.speech).sum()), "smile": int((considerable & terms.smile).sum()),
                "head": int((considerable & terms.head).sum()), "gaze": int((considerable & terms.gaze).sum())}
    rec = np.asarray(obs.considered)
    rec_fm = np.asarray(obs.from_memory)
    known = (rec >= 0) & (rec_fm == 0) & terms.shown
    counted = (int((rec[known] == 1).sum()), int(known.sum())) if known.any() else None
    n_picks = int(len(obs.first) * 2 + (terms.observed_legal > 0).sum())
    return Fit(levels, float(lapses[e]), float(grid[idx]), n_picks, grid, profile, set95, fine, evidence, counted)


def pooled(parts: list[Observations]) -> Observations:
    """Several sessions' observations as one, each its own game (memory starts empty in each)."""
    games = [np.full(len(o.first), i, dtype=np.int64) for i, o in enumerate(parts)]
    fields = {name: np.concatenate([getattr(o, name) for o in parts]) for name in Observations._fields}
    fields["game"] = np.concatenate(games)
    return Observations(**fields)


def partners_from_matches(game: np.ndarray, round_: np.ndarray, first: np.ndarray, match: np.ndarray) -> np.ndarray:
    """(T, 18) partner table of each turn's deal, from the (first, match) pairs of its round.

    A complete round reveals every pair; a card of a pair never picked in the round gets
    UNKNOWN_PARTNER (core/user.py: it cannot be in a remembered pair, the user never saw it)."""
    out = np.full((len(first), N_CARDS), UNKNOWN_PARTNER, dtype=np.int64)
    keys = np.stack([game, round_], axis=1)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.reshape(-1)
    for g in np.unique(group):
        rows = np.flatnonzero(group == g)
        table = np.full(N_CARDS, UNKNOWN_PARTNER, dtype=np.int64)
        table[first[rows]] = match[rows]
        table[match[rows]] = first[rows]
        out[rows] = table
    return out


def observations_from_trace(trace: dict) -> Observations:
    """Observations of simulated games (core/simulate.py run_games(record="all")), each game's turns in order."""
    order = np.lexsort((trace["step"], trace["game"]))
    t = {k: np.asarray(v)[order].astype(np.int64) for k, v in trace.items()}
    covered = t["covered"] | (np.int64(1) << t["first"])
    partner = partners_from_matches(t["game"], t["round"], t["first"], t["match"])
    return Observations(t["game"], t["round"], t["first"], t["second"], t["match"], covered, t["observed"],
                        t["action"], partner, t["considered"], t["from_memory"])
