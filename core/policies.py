"""Between Q-tables (arrays) and policy files (schemas/policy.py).

Rule: a learned policy file is built from a Q-table and its update counts; its
greedy actions come from the same seeded tie-break the study uses, so the file
is a pure function of the learning. Reading back gives the arrays.
"""

from __future__ import annotations

import os

import numpy as np

import msgspec

from pairplay.arguments import at, given, instance_argument, integer_argument, list_argument
from pairplay.errors import ArgumentError, InputError, OptionError
from pairplay.nearest import hinted
from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona
from pairplay.schemas.policy import PolicyFile, UserInfo

from .combine import Combined, Profile, User, represent
from .geometry import STATE_NAMES


def to_policy_file(q: np.ndarray, counts: np.ndarray, greedy: np.ndarray, *, algorithm: str,
                   participant: str, persona: Persona | None = None, seed: int | None = None,
                   game: int | None = None, rounds: int = 0, config: LearnerConfig | None = None,
                   info: UserInfo | None = None, merged_from: list[str] | None = None,
                   rules: list[str] | None = None, software: str = "",
                   reward_bonus: str = DEFAULT_REWARD_BONUS, partial: str = "",
                   lspi: LSPIConfig | None = None) -> PolicyFile:
    """`lspi` (the learner's settings) marks an LSPI policy: the file says what its Q is."""
    return PolicyFile(
        algorithm=algorithm, participant=participant, persona=persona, seed=seed, game=game,
        rounds=rounds, config=config, states=list(STATE_NAMES),
        greedy=[int(a) for a in greedy], q=[[float(v) for v in row] for row in q],
        visits=[int(v) for v in np.asarray(counts).reshape(len(STATE_NAMES), -1).sum(-1)],
        info=info, merged_from=list(merged_from or []), rules=list(rules or []), software=software,
        reward_bonus=reward_bonus, partial=partial, lspi=msgspec.UNSET if lspi is None else lspi,
        q_meaning=msgspec.UNSET if lspi is None else LSPI_Q_MEANING)


LSPI_Q_MEANING = ("Q(s, a) = phi(s, a)^T theta, online LSPI (thesis algorithm 2, core/lspi.py): the ridge-"
                  "regularised least-squares fit of the reward of suggestion a in state s when considered "
                  "(gamma 0), on tile features of the state in action a's block; the scale of Q-learning's Q")


def greedy_of(policy: PolicyFile) -> np.ndarray:
    return np.asarray(policy.greedy, dtype=np.int64)


def q_of(policy: PolicyFile) -> np.ndarray:
    return np.asarray(policy.q, dtype=np.float64)


def by_participant(policies: list[PolicyFile], exclude=()) -> dict[str, list[PolicyFile]]:
    """Policy files grouped by their participant, in the order first seen."""
    groups: dict[str, list[PolicyFile]] = {}
    for p in policies:
        if p.participant not in exclude:
            groups.setdefault(p.participant, []).append(p)
    return groups


def users_from_policies(policies: list[PolicyFile], seed: int, exclude=()) -> tuple[list[User], dict[str, Profile]]:
    """Group policy files by participant; each group becomes one combination input. InputError for no
    policy, or every one excluded; ArgumentError (pairplay/arguments.py) for an item that is no read
    policy (a path: read it first) or a seed that is no integer 0..2**64-1."""
    fn = "users_from_policies"
    for place, p in enumerate(list_argument(policies, object, fn, "policies", "a PolicyFile")):
        if not isinstance(p, PolicyFile):
            hint = ": a path, read it first: pairplay.read_policy(path)" if isinstance(p, (str, os.PathLike)) else ""
            raise ArgumentError(f"policies[{place}] must be a PolicyFile (pairplay.read_policy), got {given(p)}{hint}",
                                at(fn, "policies"))
    seed = integer_argument(seed, fn, "seed", low=0)
    exclude = list_argument(exclude, str, fn, "exclude", "a participant's id", empty_ok=True)
    if not by_participant(policies, exclude):
        raise InputError(f"every policy's participant is excluded ({', '.join(sorted(set(exclude)))}): nothing to "
                         "combine", at(fn, "exclude"))
    users, profiles = [], {}
    for name, own in by_participant(policies, exclude).items():
        user, profile = represent(name, np.stack([greedy_of(p) for p in own]), np.stack([q_of(p) for p in own]), seed)
        users.append(user)
        profiles[name] = profile
    return users, profiles


def _some(names: list[str], shown: int = 3) -> str:
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


def common_reward_bonus(policies: list[PolicyFile], names: list[str] | None = None) -> str:
    """The reward rule all the policies were learned under; InputError naming the files of each rule if they differ.

    Algorithm 4 settles "Error" states by summing the users' Q-values, which are
    comparable only under one reward. `names[i]` is where policies[i] came from.
    """
    names = names or [p.participant for p in policies]
    by_rule: dict[str, list[str]] = {}
    for p, name in zip(policies, names):
        by_rule.setdefault(p.reward_bonus, []).append(name)
    if len(by_rule) != 1:
        rules = sorted(by_rule)
        raise InputError(f"the policies were learned under different reward rules ({', '.join(rules)}): "
                         "their Q-values cannot be compared; "
                         + "; ".join(f"{rule}: {_some(by_rule[rule])}" for rule in rules))
    return next(iter(by_rule))


def check_distinct(policies: list[PolicyFile], names: list[str]) -> None:
    """InputError naming both files if two policies are the same learning (equal Q-table, update
    counts and greedy actions): given twice, one would weigh double in a profile and a merge."""
    seen: dict[bytes, str] = {}
    for p, name in zip(policies, names):
        key = q_of(p).tobytes() + np.asarray(p.visits, dtype=np.int64).tobytes() + greedy_of(p).tobytes()
        if key in seen:
            same = "given twice" if seen[key] == name else f"the same policy as {seen[key]}"
            raise InputError(f"{same}: each policy may count once", name)
        seen[key] = name


def check_exclude(policies: list[PolicyFile], exclude) -> None:
    """OptionError if --exclude names a participant no policy has (a typo would be ignored)."""
    known = sorted({p.participant for p in policies})
    unknown = sorted(set(exclude) - set(known))
    if unknown:
        raise OptionError(f"no policy of {', '.join(hinted(u, known) for u in unknown)}; participants: {', '.join(known)}",
                          f"--exclude {','.join(sorted(exclude))}")


def check_profiles_computable(policies: list[PolicyFile], names: list[str], merge: bool = False) -> None:
    """InputError if a participant has one policy: algorithm 3 finds incompatibilities between a
    user's policies, so one policy always gives 0% / 0%, a result it did not compute. A `merge`
    (algorithm 4, thesis 6.1.3) weighs each participant's actions by that profile: one policy would
    enter as a participant perceiving every channel ("hearing=equal; visual=equal" in every state)."""
    alone = [(p.participant, name) for (p, name) in zip(policies, names)
             if sum(q.participant == p.participant for q in policies) == 1]
    if alone:
        what = ("a merge (algorithm 4) weighs each participant by its profile (algorithm 3), which compares"
                if merge else "a profile (algorithm 3) compares")
        raise InputError(f"{what} two or more policies of a participant; only one of "
                         + _some([f"{who} ({name})" for who, name in alone]))


def partial_inputs(policies: list[PolicyFile], names: list[str], exclude=()) -> str:
    """Why a file derived from these policies is partial ("" if none is): a policy flagged partial (a session
    not completed, a damaged recording: replay/rebuild.py) makes whatever is made of it partial too, so the
    flag is carried, naming the first such input and its reason (a new user's trial: `combine` of a partial
    policy wrote a merged policy that did not say so). Policies of `exclude`d participants take no part."""
    flagged = [(name, p.partial) for p, name in zip(policies, names) if p.partial and p.participant not in exclude]
    if not flagged:
        return ""
    name, why = flagged[0]
    more = f" and {len(flagged) - 1} more" if len(flagged) > 1 else ""
    return f"made of a partial policy: {name} ({why}){more}"


def combined_policy_file(merged: Combined, users: list[User], merged_from: list[str], seed: int | None,
                         software: str = "", reward_bonus: str = DEFAULT_REWARD_BONUS,
                         partial: str = "") -> PolicyFile:
    """The merged policy's file; `partial`: why it is partial (`partial_inputs` of what it was made of).
    ArgumentError (pairplay/arguments.py) for a `merged` that is no Combined, `users` no list of Users."""
    fn = "combined_policy_file"
    instance_argument(merged, Combined, fn, "merged", "a Combined (pairplay.combine)")
    users = list_argument(users, User, fn, "users", "a User (pairplay.users_from_policies)")
    merged_from = list_argument(merged_from, str, fn, "merged_from", "a participant's id or a file's name", empty_ok=True)
    seed = None if seed is None else integer_argument(seed, fn, "seed", low=0)
    return to_policy_file(merged.q, np.zeros(len(merged.policy), dtype=np.int64), merged.policy,
                          algorithm="combined", participant="+".join(sorted(u.name for u in users)),
                          seed=seed, info=merged.info, merged_from=merged_from, rules=merged.rules,
                          software=software, reward_bonus=reward_bonus, partial=partial)
