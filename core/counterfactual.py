"""Counterfactual replay: other learners or policies played against a user fitted to a recording.

Rule: the fitted persona (core/userfit.py) is the existing simulated user
(core/simulate.py run_games, the compiled kernels); each arm is a learner or a
policy playing it for the recording's number of rounds, once per seed. Every
arm plays the same seeds, so seed i deals the same boards in every arm and the
arms compare pairwise (a difference per seed, then its mean). Arms:
- "same": the recorded session's own learner (its algorithm, schedule and
  bias or fixed policy, or its LSPI settings): a check of the fit, it should
  give what the recording gave, within the spread of the seeds;
- "q": Q-learning from scratch, on the recorded session's schedule;
- "final": the recorded learner's final greedy policy, played fixed;
- "oracle": the best policy for the fitted user (core/oracle.py);
- "alone": no suggestion (the user alone);
- any other name: a given policy, pi-reused ("reuse") or played fixed ("fixed").
Measures, the same for the recording and every arm: picks per round (18 is
perfect play) and the share of suggestions after which the second card matched.
An LSPI arm plays in a batch of its own (run_games plays LSPI in its own
lockstep runner, which records no trace); its share comes from its picks, which
hold it exactly: every round ends with its 9 pairs matched, each by one turn
whose second pick matched, and every turn is 2 picks, so the share is
9 rounds / (picks / 2) (the kernel arms' traces give the same, tested).

Pure: numpy in, numpy out; randomness from the seeds given.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.arguments import at, given, instance_argument, integer_argument, list_argument
from pairplay.core.reward import BONUS_RULES
from pairplay.errors import InputError
from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona
from pairplay.schemas.usermodel import CountedRate, FeatureFit, RateFit, UserModelFile

from .geometry import N_CARDS, N_STATES
from .interpretation import SIGHT_SEES, consider_probability, hear_probability, memory_capacity
from .oracle import USER_ALONE, oracle_policies
from .simulate import batch_bytes, run_games
from .userfit import FEATURES, Fit
from pairplay.numbers import counted

# Observed sources of a recording -> the simulation's (a gaze is taken as the card the user intends)
SIM_SOURCE = {"intended": "intended", "first-pick": "first-pick", "gaze": "intended"}
ASSUMPTIONS = (
    "The participant is the simulated user of thesis 6.1.3 with one set of features for the whole session "
    "(no learning, no fatigue); the features are fitted on the thesis's 1..6 scale.",
    "Suggestions are read as appendix B says (each part names a set of cards, the candidate set is their "
    "intersection with the cards not remembered), in the canonical frame of reference (columns from the left).",
    "Memory is the simulated user's: the cards of a missed turn enter it, the oldest leave when it holds "
    "memory + 1 cards, matched cards leave it, a new deal empties it; it is replayed on the recorded picks.",
    "Every choice in a set of cards is uniform.",
    "The lapse (a uniform covered card instead of the model's pick) exists only in the fit; the simulated "
    "user replays the fitted persona without it.",
    "The observed card of a gaze recording is taken as the card the participant would pick unaided.",
    "Features the session cannot tell apart (a 95% set of every level) are set to the lowest level of the set "
    "with the highest likelihood; sight is identified only up to the groups of table 6.1.",
)


class Arm(NamedTuple):
    name: str
    mode: str  # run_games mode: "q", "reuse", "fixed" or "lspi"
    config: LearnerConfig
    table: np.ndarray | None = None  # (24,) the bias (reuse) or fixed policy
    lspi: LSPIConfig | None = None  # mode "lspi": its settings (None: the defaults)


class ArmRuns(NamedTuple):
    picks: np.ndarray  # (seeds, rounds) picks per round
    hits: np.ndarray  # (seeds,) share of turns whose second pick matched (report/counterfactual.py HITS)


def fitted_persona(fit: Fit, participant: str, session: str) -> Persona:
    """The fitted user as a persona of appendix A (key "fit:<participant>")."""
    lv = fit.levels
    return Persona(key=f"fit:{participant}", name=f"fitted to {session}", focus=lv["focus"], memory=lv["memory"],
                   hearing=lv["hearing"], sight=lv["sight"], inferred=FEATURES,
                   basis="maximum likelihood over the recorded picks (core/userfit.py)")


def _means(feature: str, level: int) -> str:
    if feature == "focus":
        return f"considers a suggestion with p = {consider_probability(level):.1f}"
    if feature == "hearing":
        return f"hears speech with q = {hear_probability(level):.1f}"
    if feature == "memory":
        return f"remembers {counted(memory_capacity(level), 'card')}"
    seen = sorted(SIGHT_SEES[level])
    return "sees " + (", ".join(seen) if seen else "no visual part")


def wilson(count: int, of: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a proportion (0..1)."""
    if of == 0:
        return 0.0, 1.0
    p = count / of
    centre = (p + z * z / (2 * of)) / (1 + z * z / of)
    half = z * np.sqrt(p * (1 - p) / of + z * z / (4 * of * of)) / (1 + z * z / of)
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def to_user_model(fit: Fit, *, recording: str, session: str, participant: str, observed_source: str,
                  software: str = "", fitted_on: Sequence[str] = ()) -> UserModelFile:
    """The fit as the versioned user-model file (schemas/usermodel.py)."""
    feats = {f: FeatureFit(level=fit.levels[f], means=_means(f, fit.levels[f]), set95=fit.set95[f],
                           profile=[round(float(v), 6) for v in fit.profile[f]],
                           identified=len(fit.set95[f]) < 6) for f in FEATURES}
    rates = {k: RateFit(estimate=v[0], low95=v[1], high95=v[2]) for k, v in fit.fine.items()}
    counted = None
    if fit.counted is not None and fit.counted[1] > 0:
        k, n = fit.counted
        lo, hi = wilson(k, n)
        counted = CountedRate(count=k, of=n, rate=round(k / n, 6), low95=round(lo, 6), high95=round(hi, 6))
    return UserModelFile(recording=recording, session=session, participant=participant,
                         observed_source=observed_source, persona=fitted_persona(fit, participant, session),
                         **feats, **rates, lapse=fit.lapse, loglik=round(fit.loglik, 6), picks=fit.picks,
                         evidence=dict(fit.evidence), considered_counted=counted, assumptions=list(ASSUMPTIONS),
                         software=software, fitted_on=list(fitted_on) or [recording])


def oracle_policy(persona: Persona, seed: int, bonus: str = DEFAULT_REWARD_BONUS) -> np.ndarray:
    """(24,) the oracle's policy for one persona (core/oracle.py; 10 situation games of 100 rounds)."""
    policies, _ = oracle_policies([persona], 10, seed, 100, bonus=bonus)
    return policies[0]


def user_alone() -> np.ndarray:
    return USER_ALONE.copy()


def arms_bytes(arms: int, seeds: int, rounds: int, lspi: int = 0) -> int:
    """About the bytes run_arms holds: one batch of the arms x seeds games that records every turn, then
    the `lspi` arms' (of `arms`) one after the other, each a batch of seeds LSPI games without a trace."""
    lspi_batch = batch_bytes(seeds, rounds, lspi=True) if lspi else 0
    return batch_bytes((arms - lspi) * seeds, rounds, trace=True) + lspi_batch


def hits_of_picks(picks: np.ndarray) -> np.ndarray:
    """(seeds,) share of turns whose second pick matched, from (seeds, rounds) picks of complete rounds
    (module rule: N_CARDS / 2 such turns a round, 2 picks a turn)."""
    return N_CARDS * picks.shape[1] / np.maximum(picks.sum(axis=1), 1)


def run_arms(persona: Persona, arms: Sequence[Arm], seeds: Sequence[int], rounds: int,
             observed_source: str = "intended", reward_bonus: str = DEFAULT_REWARD_BONUS) -> dict[str, ArmRuns]:
    """Every arm against `persona`, once per seed: the learners and policies in one batch of the compiled
    simulator, each LSPI arm in a batch of its own (module rule); the result in the arms' order.
    A caller's mistake is an InputError (an ArgumentError for the wrong kind: pairplay/arguments.py)."""
    fn = "run_arms"
    instance_argument(persona, Persona, fn, "persona", "a Persona (pairplay.core.personas.persona(key))")
    arms = list_argument(arms, Arm, fn, "arms", "an Arm")
    seeds = list_argument(seeds, object, fn, "seeds", "an integer seed")
    seeds = [integer_argument(s, fn, "seeds", low=0) for s in seeds]
    rounds = integer_argument(rounds, fn, "rounds", low=1)
    if observed_source not in SIM_SOURCE:
        raise InputError(f"observed_source must be one of {', '.join(SIM_SOURCE)}, got {given(observed_source)}",
                         at(fn, "observed_source"))
    if reward_bonus not in BONUS_RULES:
        raise InputError(f"reward_bonus must be one of {', '.join(BONUS_RULES)}, got {given(reward_bonus)}",
                         at(fn, "reward_bonus"))
    runs = _run_batch(persona, [a for a in arms if a.mode != "lspi"], seeds, rounds, observed_source, reward_bonus)
    for arm in arms:
        if arm.mode == "lspi":
            result = run_games([persona] * len(seeds), list(seeds), rounds, config=arm.config, mode="lspi",
                               lspi=arm.lspi, observed_source=SIM_SOURCE[observed_source], reward_bonus=reward_bonus)
            picks = result.picks.astype(np.float64)
            runs[arm.name] = ArmRuns(picks, hits_of_picks(picks))
    return {arm.name: runs[arm.name] for arm in arms}


def _run_batch(persona: Persona, arms: Sequence[Arm], seeds: Sequence[int], rounds: int, observed_source: str,
               reward_bonus: str) -> dict[str, ArmRuns]:
    """The arms of the compiled kernel (no LSPI) in one batch, every turn recorded."""
    if not arms:
        return {}
    n_seeds = len(seeds)
    games = len(arms) * n_seeds
    tables = np.zeros((games, N_STATES), dtype=np.int64)
    for i, arm in enumerate(arms):
        if arm.mode != "q":
            tables[i * n_seeds:(i + 1) * n_seeds] = np.asarray(arm.table, dtype=np.int64)
    result = run_games([persona] * games, list(seeds) * len(arms), rounds,
                       config=[a.config for a in arms for _ in range(n_seeds)],
                       mode=[a.mode for a in arms for _ in range(n_seeds)], bias=tables, policy=tables,
                       observed_source=SIM_SOURCE[observed_source], reward_bonus=reward_bonus, record="all")
    t = result.trace
    hit = np.bincount(t["game"], weights=(t["second"] == t["match"]), minlength=games)
    turns = np.bincount(t["game"], minlength=games)
    hits = hit / np.maximum(turns, 1)
    return {arm.name: ArmRuns(result.picks[i * n_seeds:(i + 1) * n_seeds].astype(np.float64),
                              hits[i * n_seeds:(i + 1) * n_seeds])
            for i, arm in enumerate(arms)}
