"""Configuration of learners and studies: the knobs a study designer may turn.

Rule: defaults are the thesis's values (section 6.2 for the virtual study,
section 7.2 for the human study); every choice SPEC.md or this project made
where the thesis is silent is a field here, so the other reading is one flag
away. Config files are strict: unknown fields are an error.
"""

from __future__ import annotations

import msgspec

from pairplay.numbers import shown

# When the simulated reward pays its 1/|candidate set| bonus (thesis 6.1.3; core/reward.py):
# "correct": on a considered suggestion whose candidate set holds the matching card
#   (pairplay's default; SPEC's reading pays a certain miss, see README "The reward bonus");
# "consistent": on every considered, consistent suggestion (SPEC.md's literal reading);
# "match": only when the pick matched.
REWARD_BONUS_RULES = ("correct", "consistent", "match")
DEFAULT_REWARD_BONUS = "correct"
# A recording or policy file that does not state its rule predates the choice
# (pairplay 0.1.0): it was made with SPEC's reading.
UNSTATED_REWARD_BONUS = "consistent"


# Every LearnerConfig field's range, the one check of a schedule wherever it comes from (a session's
# config, a study file's [[phase]] learner overrides, a policy file's config, the CLI's presets):
# `alpha_start = nan` in a study file passed `protocol check`, then the learner refused the session and
# the game waited for ever; `epsilon_start = 5.0` learned with nonsense. Probabilities and rates are
# 0..1 (a step is how much one falls each `every` rounds); `every` counts rounds; None: no reuse limit.
ROUNDS_MAX = 10**9  # a round count in a schedule (more than any study plays; numpy's int64 takes it)
LEARNER_RANGES: dict[str, tuple[float, float]] = {
    "epsilon_start": (0, 1), "epsilon_step": (0, 1), "epsilon_every": (1, ROUNDS_MAX), "epsilon_min": (0, 1),
    "alpha_start": (0, 1), "alpha_step": (0, 1), "alpha_every": (1, ROUNDS_MAX), "alpha_min": (0, 1),
    "psi_start": (0, 1), "psi_decay": (0, 1), "psi_round_decay": (0, 1), "reuse_rounds": (0, ROUNDS_MAX),
}


class LearnerConfig(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Online Q-learning (thesis 5.1, algorithm 1) with optional pi-reuse (5.3).

    epsilon(round) = max(epsilon_min, epsilon_start - epsilon_step * (round // epsilon_every))
    alpha(round)   = max(alpha_min,   alpha_start   - alpha_step   * (round // alpha_every))
    The virtual study: epsilon 0.9 minus 0.1 every 50 rounds, floor 0.1; alpha 0.5
    minus 0.05 every 50 rounds. The thesis gives alpha no floor; it reaches 0.05 at
    round 450 of 500, and alpha_min keeps it there for longer games (0 would stop
    learning).
    pi-reuse (algorithm 5): with probability psi the bias policy's action, else
    epsilon-greedy on the new Q; psi starts each round (episode) at
    psi_start * psi_round_decay**round and is multiplied by psi_decay (v) after
    every suggestion; from round `reuse_rounds` on (if set) psi is 0, so the last
    rounds use the new policy alone.
    """

    epsilon_start: float = 0.9
    epsilon_step: float = 0.1
    epsilon_every: int = 50
    epsilon_min: float = 0.1
    alpha_start: float = 0.5
    alpha_step: float = 0.05
    alpha_every: int = 50
    alpha_min: float = 0.05
    psi_start: float = 1.0
    psi_decay: float = 0.95
    psi_round_decay: float = 1.0
    reuse_rounds: int | None = None

    def __post_init__(self) -> None:
        for key, (low, high) in LEARNER_RANGES.items():
            value = getattr(self, key)
            if value is not None and not low <= value <= high:  # also refuses nan
                raise ValueError(f"{key} must be {low}..{high}, got {shown(value)}")

    def never_reuses(self) -> str:
        """Why pi-reuse on this schedule would never take the bias policy's action, "" if it does: such a
        session or phase is Q-learning called pi-reuse (a protocol phase of 1 round under human-phase2,
        whose last round is on the new policy alone, was accepted and never reused)."""
        if self.reuse_rounds is not None and self.reuse_rounds < 1:
            return f"its schedule plays every round on the new policy alone (reuse_rounds {self.reuse_rounds})"
        if self.psi_start <= 0:
            return "its psi starts at 0"
        return ""

    @classmethod
    def human_phase1(cls, rounds: int = 5) -> "LearnerConfig":
        """Thesis 7.2: epsilon 0.9 falling by a fifth of 0.9 each round (5 rounds)."""
        return cls(epsilon_start=0.9, epsilon_step=0.9 / rounds, epsilon_every=1, epsilon_min=0.0,
                   alpha_start=0.5, alpha_step=0.0, alpha_every=1, alpha_min=0.5)

    @classmethod
    def human_phase2(cls, rounds: int = 5) -> "LearnerConfig":
        """Thesis 7.2: pi-reuse on the bias policy, the last round on the new policy alone."""
        return cls(epsilon_start=0.9, epsilon_step=0.9 / rounds, epsilon_every=1, epsilon_min=0.0,
                   alpha_start=0.5, alpha_step=0.0, alpha_every=1, alpha_min=0.5,
                   psi_start=1.0, psi_decay=0.95, psi_round_decay=1.0 - 1.0 / rounds,
                   reuse_rounds=rounds - 1)


class LSPIConfig(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Online LSPI (thesis 5.1.2, algorithm 2) with tile-coded state x action features (core/lspi.py).

    ridge: delta of algorithm 2 line 3 (Gamma_0 = delta I): the ridge penalty that
      keeps every block of A invertible before its states are seen.
    improve_every: K_theta, samples between two policy improvements (line 11).
    gamma: the discount of line 12. After a suggestion the next state is always the
      user's, where the agent does not act (thesis eq. 5.1), so phi(s', pi(s')) = 0,
      Lambda stays 0 and gamma does not change the solution here (SPEC "Learning").
    tilings, tile_width: the coarse tile coding of a state's (row sign, column sign,
      level) grid point: `tilings` grids of tiles `tile_width` grid steps wide, each
      displaced as Sutton and Barto (2018, 9.5.4) describe.
    exact: add one tiling of one tile per state, so every state can take its own value.
    The exploration schedule (epsilon) is the Q-learner's, from LearnerConfig.
    """

    ridge: float = 1.0
    improve_every: int = 10
    gamma: float = 0.0
    tilings: int = 4
    tile_width: float = 2.0
    exact: bool = True

    def __post_init__(self) -> None:
        if not self.ridge > 0:
            raise ValueError(f"lspi ridge must be > 0, got {shown(self.ridge)}")
        if self.improve_every < 1:
            raise ValueError(f"lspi improve_every must be >= 1, got {self.improve_every}")
        if not 0 <= self.gamma < 1:
            raise ValueError(f"lspi gamma must be in [0, 1), got {shown(self.gamma)}")
        if self.tilings < 0 or (self.tilings and not self.tile_width >= 1):
            raise ValueError("lspi needs tilings >= 0 and tile_width >= 1 (grid steps)")
        if not self.tilings and not self.exact:
            raise ValueError("lspi needs some features: tilings > 0 or exact")


def lspi_unused(algorithm: str, given: list[str], algorithm_option: str = "--algorithm") -> str:
    """Why the LSPI settings `given` (as the user spelled them: `--lspi-ridge`, a sweep's `lspi_ridge`) cannot
    go with `algorithm`, or "" if they can: a learner that is not LSPI would ignore them without a word
    (`study --lspi-ridge 2` ran Q-learning, exit 0). One rule for session, study and sweep."""
    if algorithm == "lspi" or not given:
        return ""
    return f"{'/'.join(given)} need{'s' if len(given) == 1 else ''} {algorithm_option} lspi, not {algorithm}"


class Persona(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A simulated user of appendix A: features on the thesis's 1..6 scale."""

    key: str
    name: str
    focus: int
    memory: int
    hearing: int
    sight: int
    inferred: tuple[str, ...] = ()  # features not stated in the thesis's text
    basis: str = ""  # the text the values come from

    def __post_init__(self) -> None:
        for feature in ("focus", "memory", "hearing", "sight"):
            value = getattr(self, feature)
            if not 1 <= value <= 6:
                raise ValueError(f"persona {self.key}: {feature} must be 1..6, got {value}")
