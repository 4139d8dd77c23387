"""The reward of a suggestion (thesis 4.3, 6.1.3, 7.1.2; SPEC "Reward").

Rule: +1 for a match, -1 for a miss, plus a bonus of 1/|candidate set| for a
considered suggestion (thesis 6.1.3: "to incentivize the use of specific
suggestions"); -3 (alone) for an inconsistent suggestion; no reward and no
update when the suggestion was ignored (by focus, or because the match was
picked from memory). The human study has no candidate set: +-1, and -3 when
the participant presses the "wrong suggestion" button; a turn whose two picks
are less than 1.5 s apart counts as ignored.

When the bonus is paid (schemas.config.REWARD_BONUS_RULES):
- "correct" (default): when the candidate set holds the matching card. A
  suggestion that points away from the match is not a specific suggestion of
  it: it earns the plain -1 of the miss it causes.
- "consistent" (SPEC.md's literal reading): on every consistent suggestion. A
  smile at the card the user already looks at, when it is not the match, then
  pays -1 + 1/1 = 0, more than any honest hint over three or more cards; the
  reward-optimal policy misleads on purpose and the learner locks onto such
  certain misses (README, "The reward bonus").
- "match": only when the pick matched, so honest misses earn no bonus either.
"correct" and "consistent" differ only on suggestions that point away from the
match.
"""

from __future__ import annotations

import math

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, REWARD_BONUS_RULES

from . import kernels

INCONSISTENT = -3.0
WRONG_SUGGESTION = -3.0
IGNORE_BELOW_S = 1.5  # thesis 7.1.2: picks closer than this ignored the suggestion
BONUS_RULES = REWARD_BONUS_RULES
BONUS_CODES = {"correct": kernels.BONUS_CORRECT, "consistent": kernels.BONUS_CONSISTENT, "match": kernels.BONUS_MATCH}
assert set(BONUS_CODES) == set(BONUS_RULES)
assert kernels.INCONSISTENT == INCONSISTENT
# How each rule reads in a report.
BONUS_RULE_TEXT = {
    "correct": "paid when the candidate set holds the matching card",
    "consistent": "paid on every consistent suggestion (SPEC's literal reading)",
    "match": "paid on a match only",
}


def check_bonus_rule(bonus: str) -> str:
    if bonus not in BONUS_RULES:
        raise ValueError(f"reward bonus rule {bonus!r} is not one of {BONUS_RULES}")
    return bonus


def simulated_reward(matched: np.ndarray, considered: np.ndarray, consistent: np.ndarray,
                     candidate_size: np.ndarray, holds_match: np.ndarray,
                     bonus: str = DEFAULT_REWARD_BONUS) -> tuple[np.ndarray, np.ndarray]:
    """(reward, learn) per game; `learn` is False where the turn gives no update.

    `holds_match`: the candidate set contains the matching card (core/kernels.py `_reward`).
    """
    check_bonus_rule(bonus)
    inputs = (matched, considered, consistent, candidate_size, holds_match)
    shape = np.shape(matched)
    if any(np.shape(x) != shape for x in inputs):
        shape = np.broadcast_shapes(*(np.shape(x) for x in inputs))
    n = math.prod(shape)
    hit, cons, consist, size, holds = (
        kernels.as_batch(x if len(shape) == 1 else np.reshape(np.broadcast_to(x, shape), -1), n, dt)
        for x, dt in zip(inputs, (bool, bool, bool, np.int64, bool)))
    reward, learn = np.empty(hit.size), np.empty(hit.size, dtype=bool)
    kernels.rewards_batch(hit, cons, consist, size, holds, BONUS_CODES[bonus], reward, learn)
    return reward.reshape(shape), learn.reshape(shape)


def simulated_reward_one(matched: bool, considered: bool, consistent: bool, candidate_size: int,
                         holds_match: bool, bonus: str = DEFAULT_REWARD_BONUS) -> tuple[float, bool]:
    """`simulated_reward` of one turn as (reward, learn) Python scalars: the same compiled rule
    (core/kernels.py `_reward`) without a batch's arrays, for a live learner (services/learner.py)."""
    return kernels.reward_one(bool(matched), bool(considered), bool(consistent), int(candidate_size),
                              bool(holds_match), BONUS_CODES[check_bonus_rule(bonus)])


def human_reward(matched: bool, pick_gap_s: float = float("inf"), ignore_below_s: float = IGNORE_BELOW_S,
                 ignored: bool | None = None) -> tuple[float, bool]:
    """(reward, learn) of a human-study turn: +-1, ignored when picked too fast.

    `ignored`, when given, is the game's decision (it timed the picks on the
    session's clock) and takes the place of comparing `pick_gap_s`."""
    if ignored if ignored is not None else pick_gap_s < ignore_below_s:
        return 0.0, False
    return (1.0 if matched else -1.0), True
