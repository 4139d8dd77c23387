"""The reward of a suggestion (thesis 4.3, 6.1.3, 7.1.2; SPEC "Reward").

Rule: +1 for a match, -1 for a miss, plus 1/|candidate set| when the suggestion
was considered and consistent (bonus "consistent", SPEC's reading); -3 (alone)
for an inconsistent suggestion; no
reward and no update when the suggestion was ignored (by focus, or because the
match was picked from memory). The human study has no candidate set: +-1, and
-3 when the participant presses the "wrong suggestion" button; a turn whose two
picks are less than 1.5 s apart counts as ignored.
"""

from __future__ import annotations

import numpy as np

INCONSISTENT = -3.0
WRONG_SUGGESTION = -3.0
IGNORE_BELOW_S = 1.5  # thesis 7.1.2: picks closer than this ignored the suggestion
# When the 1/|candidate set| bonus is paid (thesis 6.1.3: "to incentivize the use
# of specific suggestions"). "consistent": on every considered, consistent
# suggestion (SPEC). "match": only when the pick matched, so a precise suggestion
# of the wrong card earns -1, not -1 + 1/1 = 0 (the other reading; see README,
# "Where Q-learning stays above the oracle").
BONUS_RULES = ("consistent", "match")


def simulated_reward(matched: np.ndarray, considered: np.ndarray, consistent: np.ndarray,
                     candidate_size: np.ndarray, bonus: str = "consistent") -> tuple[np.ndarray, np.ndarray]:
    """(reward, learn) per game; `learn` is False where the turn gives no update."""
    size = np.maximum(np.asarray(candidate_size), 1)
    if bonus == "consistent":
        base = np.where(matched, 1.0, -1.0) + 1.0 / size
    elif bonus == "match":
        base = np.where(matched, 1.0 + 1.0 / size, -1.0)
    else:
        raise ValueError(f"reward bonus rule {bonus!r} is not one of {BONUS_RULES}")
    reward = np.where(consistent, base, INCONSISTENT)
    return np.where(considered, reward, 0.0), np.asarray(considered, dtype=bool)


def human_reward(matched: bool, pick_gap_s: float, ignore_below_s: float = IGNORE_BELOW_S) -> tuple[float, bool]:
    """(reward, learn) of a human-study turn: +-1, ignored when picked too fast."""
    if pick_gap_s < ignore_below_s:
        return 0.0, False
    return (1.0 if matched else -1.0), True
