"""The policy file: one learned (or combined) policy, documented and versioned.

Rule: a policy file is JSON (UTF-8, keys in a fixed order, floats in shortest
round-trip form, so the same seed gives the same bytes) holding the Q-table
(24 states x 88 actions), the greedy action of every state, the persona or
participant it was learned with, the learner config, the seed and game, the
updates per state, and for merged policies the rule that decided each state.
What Q means depends on `algorithm`: "q-learning" (and "pi-reuse") files hold the
running average of eq. 5.2; "lspi" files hold phi(s, a)^T theta of online LSPI
(core/lspi.py), say so in `q_meaning` and carry the LSPI settings in `lspi`. Both
estimate the expected reward of a considered suggestion (gamma 0), on one scale.
`format` and `version` say what the file is, `algorithm` what made it (one of
ALGORITHMS); a reader refuses anything else, and a key no Struct of the file
declares (schemas/jsonfile.py), with a clear error (PolicyFileError),
never a half-read policy.

Version 1 fields are below; later versions add fields with defaults at the end.
"""

from __future__ import annotations

import msgspec

from pairplay.errors import InputError

from .config import REWARD_BONUS_RULES, UNSTATED_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona
from .jsonfile import JsonFileKind
from pairplay.numbers import counted

FORMAT = "pairplay.policy"
VERSION = 1
N_STATES, N_ACTIONS = 24, 88  # pinned here so the contract does not import core
# what a policy file's `algorithm` may say: a session's learners (schemas/session.py ALGORITHMS, which imports this
# module: written out here), a merge, the oracle's; any other value was read and used as a policy (a new user's
# trial: `session --algorithm fixed --policy` of a file saying "algorithm": "banana")
ALGORITHMS = ("q-learning", "lspi", "pi-reuse", "fixed", "combined", "oracle")
# |Q| at most this: a Q-value estimates the expected reward of one suggestion, whose rewards are a few
# units (core/reward.py: -3..+2); a file with 1e308 was merged and profiled as if it meant something.
Q_LIMIT = 1e6


class PolicyFileError(InputError):
    """A policy file that cannot be used; the message says why."""


class UserInfo(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """User information of algorithm 3 (thesis figure 5.1): error shares 0..1."""

    speech: float
    head: float
    facial: bool
    gaze: bool
    compared_states: int = 0


class PolicyFile(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    format: str = FORMAT
    version: int = VERSION
    algorithm: str  # one of ALGORITHMS
    participant: str  # persona key, or a study participant's id
    persona: Persona | None = None
    # the seed the game was played with: a session's --seed (`rebuild`), or the per-game seed `pairplay study`
    # derived from its --seed and `game` (a new user's trial read the two as one meaning)
    seed: int | None = None
    game: int | None = None
    rounds: int = 0
    config: LearnerConfig | None = None
    states: list[str]
    greedy: list[int]
    q: list[list[float]]
    visits: list[int]
    info: UserInfo | None = None
    merged_from: list[str] = []
    rules: list[str] = []  # per state: which rule of algorithm 4 decided it
    software: str = ""
    # When the learning reward paid its 1/|C| bonus (core/reward.py); files that do
    # not state it were written by pairplay 0.1.0, under SPEC's rule.
    reward_bonus: str = UNSTATED_REWARD_BONUS
    # Why the session this policy was rebuilt from is not complete ("" = it completed every round):
    # interrupted, aborted, failed, cut short, damaged or recovered (replay/rebuild.py).
    partial: str = ""
    # Written only by learners other than Q-learning (UNSET fields are left out of the
    # file, so Q-learning files keep their bytes): what the Q-table is, and LSPI's settings.
    q_meaning: str | msgspec.UnsetType = msgspec.UNSET
    lspi: LSPIConfig | msgspec.UnsetType = msgspec.UNSET

    def __post_init__(self) -> None:
        if self.format != FORMAT:
            raise PolicyFileError(f"not a pairplay policy file (format {self.format!r})")
        if self.version > VERSION:
            raise PolicyFileError(f"policy file version {self.version} is newer than this pairplay "
                                  f"(reads up to {VERSION}); upgrade pairplay")
        if self.algorithm not in ALGORITHMS:
            raise PolicyFileError(f"algorithm {self.algorithm!r} is not one of {', '.join(ALGORITHMS)}")
        if len(self.states) != N_STATES or len(self.greedy) != N_STATES or len(self.visits) != N_STATES:
            raise PolicyFileError(f"a policy has {N_STATES} states; this file has "
                                  f"{counted(len(self.states), 'name')}, {counted(len(self.greedy), 'action')}, {len(self.visits)} visit counts")
        if len(self.q) != N_STATES or any(len(row) != N_ACTIONS for row in self.q):
            raise PolicyFileError(f"the Q-table must be {N_STATES} x {N_ACTIONS}")
        bad = [a for a in self.greedy if not 0 <= a < N_ACTIONS]
        if bad:
            raise PolicyFileError(f"greedy actions outside 0..{N_ACTIONS - 1}: {bad}")
        if self.reward_bonus not in REWARD_BONUS_RULES:
            raise PolicyFileError(f"reward_bonus {self.reward_bonus!r} is not one of {REWARD_BONUS_RULES}")
        if self.rules and len(self.rules) != N_STATES:
            raise PolicyFileError(f"a merged policy names one rule per state ({N_STATES})")
        self._check_numbers()

    def _check_numbers(self) -> None:
        """Counts are counts, the participant is named, Q-values are rewards' size (Q_LIMIT): a file with
        `"rounds": -3`, negative visits, `"participant": ""` or Q of 1e308 was combined and profiled."""
        if not self.participant.strip():
            raise PolicyFileError("participant: empty; a policy names the persona or participant it was learned with")
        if self.rounds < 0:
            raise PolicyFileError(f"rounds: must be at least 0, got {self.rounds}")
        for key in ("seed", "game"):
            if getattr(self, key) is not None and getattr(self, key) < 0:
                raise PolicyFileError(f"{key}: must be at least 0, got {getattr(self, key)}")
        bad = [(s, v) for s, v in enumerate(self.visits) if v < 0]
        if bad:
            raise PolicyFileError(f"visits: must be at least 0, got {bad[0][1]} for state {bad[0][0]}")
        for s, row in enumerate(self.q):
            for a, v in enumerate(row):
                if not -Q_LIMIT <= v <= Q_LIMIT:  # also refuses nan
                    raise PolicyFileError(f"q: must be -{Q_LIMIT:g}..{Q_LIMIT:g} (a reward's size), got {v} "
                                          f"at state {s}, action {a}")
        if self.info is not None:
            for key in ("speech", "head"):
                if not 0 <= getattr(self.info, key) <= 1:
                    raise PolicyFileError(f"info.{key}: an error share is 0..1, got {getattr(self.info, key)}")


FILE = JsonFileKind(PolicyFile, PolicyFileError, "policy file",
                    from_recording="`pairplay rebuild` makes the policy files of recordings")  # schemas/jsonfile.py
# decode (data, source), write (path, value, force=False), read (path): the codec, by the names callers know
encode_policy, decode_policy, write_policy, read_policy = FILE.encode, FILE.decode, FILE.write, FILE.read
