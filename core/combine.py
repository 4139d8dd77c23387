"""User information, policy combination (thesis 5.2, algorithms 3 and 4).

User information (algorithm 3) compares one user's policies state by state:
- speech and head: a state counts as an incompatibility when the policies give
  different parts, except that a part which says nothing or points at the exact
  card is compatible with anything (thesis: "Maybe left" and "Try the card at
  row x and column y" are accepted). Exact-card parts: the "exact position"
  speech in every state; "It is the right card" and the nod in the MATCH state,
  where the observed card is the matching card.
- smile and gaze: True when any policy uses them in any state.
Counts become shares of the compared states: the 23 spatial states (the extra
"cards turned != 1" state never gets a suggestion in the simulation).

Combination (algorithm 4, tables 5.1 and 5.2), per state and per half of the
action (hearing = speech + facial, visual = head + gaze): the part of the user
with fewer errors in that channel (speech errors for hearing, head errors for
visual), or, when the errors are equal, the algebraic sum of the parts:
    equal parts stay; nothing + X = X;
    hearing: "exact position" + X = "exact position";
    visual: gaze + X = gaze if every user in the sum perceives gaze (its info
            says gaze), else X;
    any other pair is an Error, which the thesis leaves open: pairplay gives it
    to the part whose actions the users value most, the sum over the users of
    Q_user(s, own action with that part), exact ties to the lowest part code.
Merged information: min of the errors, AND of the booleans.

Several users: the thesis folds pairwise. pairplay combines N users at once:
the users whose error is the minimum sum their parts with the same algebra.
For two users that is algorithm 4; without Errors it equals every pairwise
fold; with Errors a pairwise fold can depend on the order (the first merge's
Q decides before the third user is seen), the N-ary form never does. Every
state records the rule that decided each half.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.arguments import at, given, list_argument
from pairplay.errors import ArgumentError, InputError
from pairplay.schemas.policy import UserInfo

from .actions import (HEAD_NOD, HEARING_EXACT, HEARING_NOTHING, HEARING_PARTS, N_VISUAL, SPEECH_EXACT,
                      SPEECH_RIGHT_CARD, VISUAL_GAZE, VISUAL_NOTHING, VISUAL_PARTS, N_ACTIONS, code_of)
from .geometry import N_STATES, SPATIAL_STATES, STATE_INDEX, CELL_INDEX

COMPARED_STATES = np.arange(len(SPATIAL_STATES))  # the 23 spatial states
MATCH_STATE = int(STATE_INDEX[CELL_INDEX["MATCH"], 0])

HEARING_SPEECH = np.array([s for s, _ in HEARING_PARTS])
_FACIAL = np.array([f for _, f in HEARING_PARTS])
VISUAL_HEAD = np.array([h for h, _ in VISUAL_PARTS])
_GAZE = np.array([g for _, g in VISUAL_PARTS])


def parts(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hearing part, visual part) of action codes."""
    a = np.asarray(actions)
    return a // N_VISUAL, a % N_VISUAL


def exempt_speech(speech: int, state: int) -> bool:
    return speech == 0 or speech == SPEECH_EXACT or (speech == SPEECH_RIGHT_CARD and state == MATCH_STATE)


def exempt_head(head: int, state: int) -> bool:
    return head == 0 or (head == HEAD_NOD and state == MATCH_STATE)


def incompatible(values: Sequence[int], state: int, exempt) -> bool:
    """True when the non-exempt values of one family differ (algorithm 3, lines 3 and 6)."""
    return len({v for v in values if not exempt(int(v), state)}) > 1


class Profile(NamedTuple):
    info: UserInfo
    speech_states: list[int]  # states counted as speech incompatibilities
    head_states: list[int]


def action_codes(policies, function: str, name: str) -> np.ndarray:
    """`policies` as an (n, 24) array of greedy action codes 0..87, n >= 1 (one (24,) policy is n = 1);
    ArgumentError for anything else (pairplay/arguments.py: `extract_info(None)` was numpy's TypeError)."""
    array = np.atleast_2d(np.asarray(policies, dtype=object if policies is None else None))
    if array.dtype.kind not in "iu" or array.ndim != 2 or array.shape[0] == 0 or array.shape[1] != N_STATES:
        raise ArgumentError(f"{name} must be greedy action codes, an (n, {N_STATES}) array of integers "
                            f"0..{N_ACTIONS - 1}, got {given(policies)}", at(function, name))
    if array.min() < 0 or array.max() >= N_ACTIONS:
        raise InputError(f"{name} holds a code outside 0..{N_ACTIONS - 1}: {int(array.min())}..{int(array.max())}",
                         at(function, name))
    return array


def extract_info(policies: np.ndarray, states: Sequence[int] = COMPARED_STATES) -> Profile:
    """Algorithm 3 over one user's policies: (n_policies, 24) greedy action codes.

    `states` narrows the comparison (default: the 23 spatial states, as the thesis);
    shares are then of the states compared.
    """
    policies = action_codes(policies, "extract_info", "policies")
    states = np.asarray(states, dtype=np.int64)
    if states.size == 0:
        raise InputError("no states to compare", at("extract_info", "states"))
    h, v = parts(policies)
    speech, facial, head, gaze = HEARING_SPEECH[h], _FACIAL[h], VISUAL_HEAD[v], _GAZE[v]
    speech_states = [int(s) for s in states if incompatible(speech[:, s], s, exempt_speech)]
    head_states = [int(s) for s in states if incompatible(head[:, s], s, exempt_head)]
    n = len(states)
    info = UserInfo(speech=len(speech_states) / n, head=len(head_states) / n,
                    facial=bool(facial[:, states].any()), gaze=bool(gaze[:, states].any()),
                    compared_states=n)
    return Profile(info, speech_states, head_states)


def trained_states(updates: np.ndarray, min_updates: int) -> np.ndarray:
    """The spatial states every policy updated at least `min_updates` times: (n_policies, 24) counts.

    Thesis 6.4 traced its stray incompatibilities to untrained states; comparing
    only trained ones tells those apart from a user's real inconsistencies.
    """
    counts = np.atleast_2d(np.asarray(updates))[:, COMPARED_STATES]
    return COMPARED_STATES[(counts >= min_updates).all(axis=0)]


def merge_info(infos: Sequence[UserInfo]) -> UserInfo:
    """Merged user information: min of the errors, AND of the booleans (thesis 5.2.2)."""
    return UserInfo(speech=min(i.speech for i in infos), head=min(i.head for i in infos),
                    facial=all(i.facial for i in infos), gaze=all(i.gaze for i in infos),
                    compared_states=min(i.compared_states for i in infos))


class User(NamedTuple):
    """One input of the combination: a policy, its Q-table and its user's information."""

    name: str
    policy: np.ndarray  # (24,) action codes
    q: np.ndarray  # (24, 88)
    info: UserInfo


class Combined(NamedTuple):
    policy: np.ndarray  # (24,)
    q: np.ndarray  # (24, 88): the users' Q-tables averaged (for later combinations and display)
    info: UserInfo
    rules: list[str]  # per state: what decided the hearing and the visual half


def _sum_hearing(values: list[int]) -> int | None:
    """Table 5.1 over several parts; None is an Error."""
    present = {p for p in values if p != HEARING_NOTHING}
    if HEARING_EXACT in present:
        return HEARING_EXACT
    if len(present) > 1:
        return None
    return present.pop() if present else HEARING_NOTHING


def _sum_visual(values: list[int], all_see_gaze: bool) -> int | None:
    """Table 5.2 over several parts; None is an Error."""
    present = {p for p in values if p != VISUAL_NOTHING}
    if VISUAL_GAZE in present and (all_see_gaze or present == {VISUAL_GAZE}):
        return VISUAL_GAZE
    present.discard(VISUAL_GAZE)
    if len(present) > 1:
        return None
    return present.pop() if present else VISUAL_NOTHING


def _resolve_error(users: list[User], state: int, candidates: list[int], hearing: bool) -> int:
    """The candidate part the users value most: sum over users of Q(s, own action with that part)."""
    def score(part: int) -> float:
        total = 0.0
        for u in users:
            h, v = parts(u.policy[state])
            code = code_of(part, int(v)) if hearing else code_of(int(h), part)
            total += float(u.q[state, code])
        return total
    return max(sorted(candidates), key=score)  # exact ties: the lowest part code


def _half(users: Sequence[User], state: int, hearing: bool) -> tuple[int, str]:
    errors = [u.info.speech if hearing else u.info.head for u in users]
    low = min(errors)
    chosen = [u for u, e in zip(users, errors) if e == low]
    own = [int(parts(u.policy[state])[0 if hearing else 1]) for u in chosen]
    name = "hearing" if hearing else "visual"
    fewer = len(chosen) < len(users)
    prefix = f"{name}=fewer-errors({'+'.join(sorted(u.name for u in chosen))})" if fewer else f"{name}=sum"
    if len(set(own)) == 1:
        return own[0], prefix if fewer else f"{name}=equal"
    result = _sum_hearing(own) if hearing else _sum_visual(own, all(u.info.gaze for u in chosen))
    if result is not None:
        return result, prefix
    return _resolve_error(chosen, state, list(set(own)), hearing), f"{prefix}:error->Q"


def combine(users: Sequence[User]) -> Combined:
    """Algorithm 4 for any number of users (see the module rule); InputError for none, ArgumentError
    for an item that is no User (pairplay/arguments.py: users_from_policies makes them)."""
    users = list_argument(users, User, "combine", "users", "a User (pairplay.users_from_policies makes them)")
    policy = np.zeros(N_STATES, dtype=np.int64)
    rules = []
    for s in range(N_STATES):
        hearing, rule_h = _half(users, s, True)
        visual, rule_v = _half(users, s, False)
        policy[s] = code_of(hearing, visual)
        rules.append(f"{rule_h}; {rule_v}")
    q = np.mean([u.q for u in users], axis=0)
    return Combined(policy, q, merge_info([u.info for u in users]), rules)


def represent(name: str, policies: np.ndarray, q_tables: np.ndarray, seed: int) -> tuple[User, Profile]:
    """One user's input to a combination: algorithm 3 over all its policies, and
    one of them, picked at random by `seed` (thesis 6.2: "randomly selects a
    policy from each user"), with its Q-table for resolving Errors."""
    from .rng import game_seed
    profile = extract_info(policies)
    pick = int(np.random.default_rng(game_seed(seed, "combine:" + name, 0)).integers(len(policies)))
    return User(name, np.asarray(policies[pick]), np.asarray(q_tables[pick]), profile.info), profile
