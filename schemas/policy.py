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
from pairplay.numbers import counted, shown

FORMAT = "pairplay.policy"
VERSION = 1
N_STATES, N_ACTIONS = 24, 88  # pinned here so the contract does not import core
# the states' names, in the order of a policy's rows (core/geometry.py STATE_NAMES, pinned: tests/test_policy_bounds.py)
STATE_NAMES = ("TOP_LEFT_L0", "TOP_LEFT_L1", "TOP_LEFT_L2", "TOP_L0", "TOP_L1", "TOP_RIGHT_L0", "TOP_RIGHT_L1",
               "TOP_RIGHT_L2", "LEFT_L0", "LEFT_L1", "LEFT_L2", "MATCH_L0", "RIGHT_L0", "RIGHT_L1", "RIGHT_L2",
               "BOTTOM_LEFT_L0", "BOTTOM_LEFT_L1", "BOTTOM_LEFT_L2", "BOTTOM_L0", "BOTTOM_L1", "BOTTOM_RIGHT_L0",
               "BOTTOM_RIGHT_L1", "BOTTOM_RIGHT_L2", "NOT_ONE_CARD")
# what a policy file's `algorithm` may say: a session's learners (schemas/session.py ALGORITHMS, which imports this
# module: written out here), a merge, the oracle's; any other value was read and used as a policy (a new user's
# trial: `session --algorithm fixed --policy` of a file saying "algorithm": "banana")
ALGORITHMS = ("q-learning", "lspi", "pi-reuse", "fixed", "combined", "oracle")
# the algorithms whose greedy actions are their Q-table's argmax (rebuild and study write them so: `_check_greedy`)
GREEDY_OF_Q = ("q-learning", "lspi", "pi-reuse", "fixed")
# |Q| at most this: a Q-value estimates the expected reward of one suggestion, whose rewards are a few
# units (core/reward.py: -3..+2); a file with 1e308 was merged and profiled as if it meant something.
Q_LIMIT = 1e6
# a count (rounds, a state's visits) at most this: exact in every JSON reader, as the bus's seqs, and a sum of
# a study's files stays inside numpy's int64 (visits of 10**30 raised OverflowError in profile and combine)
COUNT_LIMIT = 2**53


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
        # rows are read by position: a file naming its states in another order was read as if its row 0 were
        # TOP_LEFT_L0 though it said NOT_ONE_CARD (trial28 F7). Refused, not mapped by name: pairplay writes
        # them in this order only, so another order is a file someone changed, whose rows may not follow it
        wrong = next((i for i, (name, want) in enumerate(zip(self.states, STATE_NAMES)) if name != want), None)
        if wrong is not None:
            raise PolicyFileError(f"states[{wrong}]: must be {STATE_NAMES[wrong]!r} (a policy names the {N_STATES} "
                                  f"states in pairplay's order, one row each), got {self.states[wrong]!r}")
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
        self._check_greedy()

    def _check_greedy(self) -> None:
        """A learner's greedy actions are its Q-table's: greedy[s] is among the actions of the highest q[s][a]
        (any of a tie: the writer breaks ties by a seeded draw, core/learning.py `greedy`). Compared exactly: the
        file's floats are written in shortest round-trip form (module rule), so they read back as the very
        doubles the writer took the maximum of. `combine` and `profile` read `greedy`, pi-reuse reads `q`: a file
        whose two disagree (a hand edit, a damaged copy) was combined and profiled as one policy and played as
        another, exit 0 (trial29 F5). A merged policy's greedy is its rules' (algorithm 4), not its Q-table's, and
        an oracle's is its user model's: not compared (`GREEDY_OF_Q`)."""
        if self.algorithm not in GREEDY_OF_Q:
            return
        for s, (a, row) in enumerate(zip(self.greedy, self.q)):
            best = max(row)
            if row[a] != best:
                tied = [i for i, v in enumerate(row) if v == best]
                named = ", ".join(map(str, tied[:3])) + (f" and {len(tied) - 3} more" if len(tied) > 3 else "")
                raise PolicyFileError(f"greedy[{s}] ({STATE_NAMES[s]}): action {a} is not a best action of its "
                                      f"Q-table's row q[{s}] (q {row[a]!r}; the best, {best!r}: action"
                                      f"{'s' if len(tied) > 1 else ''} {named}): a {self.algorithm} policy's greedy "
                                      "actions are its Q-table's (the file was changed?)")

    def _check_numbers(self) -> None:
        """Every number within its range, the participant named: counts are counts (0..COUNT_LIMIT), seed and
        game as a session takes them, Q-values a reward's size (Q_LIMIT), error shares 0..1. A file with
        `"rounds": -3`, negative visits, `"participant": ""` or Q of 1e308 was combined and profiled; one with
        visits of 10**30 was a traceback in profile and combine (OverflowError in numpy's int64)."""
        from .session import GAME_INDEX_RANGE, SEED_RANGE  # (session.py imports this module)

        if not self.participant.strip():
            raise PolicyFileError("participant: empty; a policy names the persona or participant it was learned with")
        _within("version", self.version, 1, VERSION)
        _within("rounds", self.rounds, 0, COUNT_LIMIT)
        for key, (low, high) in (("seed", SEED_RANGE), ("game", GAME_INDEX_RANGE)):
            if getattr(self, key) is not None:
                _within(key, getattr(self, key), low, high)
        for s, v in enumerate(self.visits):
            _within(f"visits[{s}]", v, 0, COUNT_LIMIT, " (updates of the state)")
        for s, row in enumerate(self.q):
            for a, v in enumerate(row):
                if not -Q_LIMIT <= v <= Q_LIMIT:  # also refuses nan
                    raise PolicyFileError(f"q: must be -{Q_LIMIT:g}..{Q_LIMIT:g} (a reward's size), got {v} "
                                          f"at state {s}, action {a}")
        if self.info is not None:
            for key in ("speech", "head"):
                if not 0 <= getattr(self.info, key) <= 1:
                    raise PolicyFileError(f"info.{key}: an error share is 0..1, got {getattr(self.info, key)}")
            _within("info.compared_states", self.info.compared_states, 0, N_STATES)


def _within(key: str, value: int, low: int, high: int, what: str = "") -> None:
    """PolicyFileError "key: must be low..high, got value" unless it lies there (a huge value said by its size)."""
    if not low <= value <= high:
        raise PolicyFileError(f"{key}: must be {low}..{high}{what}, got {shown(value)}")


FILE = JsonFileKind(PolicyFile, PolicyFileError, "policy file",
                    from_recording="`pairplay rebuild` makes the policy files of recordings")  # schemas/jsonfile.py
# decode (data, source), write (path, value, force=False), read (path): the codec, by the names callers know
encode_policy, decode_policy, write_policy, read_policy = FILE.encode, FILE.decode, FILE.write, FILE.read
