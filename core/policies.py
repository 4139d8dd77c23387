"""Between Q-tables (arrays) and policy files (schemas/policy.py).

Rule: a learned policy file is built from a Q-table and its update counts; its
greedy actions come from the same seeded tie-break the study uses, so the file
is a pure function of the learning. Reading back gives the arrays.
"""

from __future__ import annotations

import numpy as np

from pairplay.schemas.config import LearnerConfig, Persona
from pairplay.schemas.policy import PolicyFile, UserInfo

from .geometry import STATE_NAMES


def to_policy_file(q: np.ndarray, counts: np.ndarray, greedy: np.ndarray, *, algorithm: str,
                   participant: str, persona: Persona | None = None, seed: int | None = None,
                   game: int | None = None, rounds: int = 0, config: LearnerConfig | None = None,
                   info: UserInfo | None = None, merged_from: list[str] | None = None,
                   rules: list[str] | None = None, software: str = "") -> PolicyFile:
    return PolicyFile(
        algorithm=algorithm, participant=participant, persona=persona, seed=seed, game=game,
        rounds=rounds, config=config, states=list(STATE_NAMES),
        greedy=[int(a) for a in greedy], q=[[float(v) for v in row] for row in q],
        visits=[int(v) for v in np.asarray(counts).reshape(len(STATE_NAMES), -1).sum(-1)],
        info=info, merged_from=list(merged_from or []), rules=list(rules or []), software=software)


def greedy_of(policy: PolicyFile) -> np.ndarray:
    return np.asarray(policy.greedy, dtype=np.int64)


def q_of(policy: PolicyFile) -> np.ndarray:
    return np.asarray(policy.q, dtype=np.float64)
