"""Action-level user information and combination (thesis chapter 8, first future work).

Rule: algorithm 3 (core/combine.py extract_info, thesis 5.2.1) compares a user's
policies suggestion by suggestion, so two different composite actions that mean
the same to the user (a user who reads "Maybe up" + turn left as up-left, and
"Maybe left" + turn up too) count as speech and head incompatibilities, and a
pair the user understands only as one whole is split by algorithm 4's part-wise
algebra. The thesis proposes (chapter 8; 7.4 saw the users' "different
interpretations ... in combination with other suggestions") to work "at action
level and not comparing the single suggestions". Here, over one user's n
policies (greedy actions P (n, 24), Q-tables Q (n, 24, 88)):

- values V(s, a) = the mean of Q_i(s, a) over the policies that tried a in s
  (Q starts at 0 and a policy file keeps no per-action counts, so a Q of exactly
  0 counts as untried); 0 when none did: no evidence either way;
- the user RECOGNISES whole action a in state s when V(s, a) > 0: on average
  its suggestions earned more than they lost (reward +1 + bonus for the match,
  -1 for a miss, -3 for an inconsistent suggestion, thesis 4.3);
- the user REJECTS a when V(s, a) < -0.5: tried, and on average it lost at
  least half a miss (a margin, so that two policies' noise around 0 is no
  evidence);
- a WHOLE is a recognised action with a hearing part and a visual part whose
  parts alone the user rejects: (hearing part, nothing) and (nothing, visual
  part) are both rejected;
- a state algorithm 3 counts as a speech (head) incompatibility is a SYNONYM
  state, and not counted, when the user recognises every policy's action there
  and the actions that are not wholes agree in speech (head) by algorithm 3's
  rule: the wholes are compared as wholes (distinct recognised wholes are
  several forms of one meaning), the rest part by part. Otherwise it stays: an
  impaired channel stays counted (a blind user's head parts differ while the
  speech alone carries the meaning, so those actions are no wholes), as do
  untrained states (an action not recognised).
  The action-level user information is algorithm 3's without the synonym
  states (same denominator: the compared states); smile and gaze as algorithm 3.

Combination (`combine_actions`): algorithm 4 (core/combine.py) on the users with
their action-level information, then, per state, the merged action is kept
unless another action is recognised by more of the users; then the action
recognised by the most users replaces it (ties: the larger sum of the users'
V, then the lowest code). So algorithm 4 still decides wherever its action is
as widely understood as any, and a pair a user reads only as one whole is never
replaced by parts fewer users understand. Pure numpy; no randomness.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS
from pairplay.schemas.policy import UserInfo

from .actions import HEARING_NOTHING, N_ACTIONS, VISUAL_NOTHING, code_of
from .combine import (VISUAL_HEAD, HEARING_SPEECH, COMPARED_STATES, Combined, User, exempt_head, exempt_speech, combine,
                      extract_info, incompatible, parts)
from pairplay.numbers import counted

RECOGNISED = 0.0  # V(s, a) above this: the user recognises the whole action
REJECTED = -0.5  # V(s, a) below this: the user rejects it


class ActionProfile(NamedTuple):
    """Action-level user information of one user (see the module rule)."""

    info: UserInfo  # algorithm 3's shares without the synonym states
    values: np.ndarray  # (24, 88) V (action_values)
    speech_states: list[int]  # speech incompatibilities that remain at action level
    head_states: list[int]
    synonym_states: list[int]  # states algorithm 3 counts whose differing actions the user all recognises
    wholes: list[tuple[int, int]]  # (state, action): a policy's recognised pair whose parts alone are not
    algorithm3: UserInfo  # algorithm 3 on the same policies and states, for comparison


def recognised(values: np.ndarray) -> np.ndarray:
    """Bool (..., 88): the whole actions a user recognises (V > 0)."""
    return np.asarray(values) > RECOGNISED


def action_values(q_tables: np.ndarray) -> np.ndarray:
    """V (24, 88) of one user's Q-tables (n, 24, 88): the mean over the tables that tried each action."""
    q = np.asarray(q_tables, dtype=np.float64)
    tried = (q != 0).sum(axis=0)
    return np.where(tried > 0, q.sum(axis=0) / np.maximum(tried, 1), 0.0)


def whole_actions(values: np.ndarray) -> np.ndarray:
    """Bool (24, 88): the user's wholes (see the module rule) from its values V (24, 88)."""
    values = np.asarray(values)
    h, v = parts(np.arange(N_ACTIONS))
    alone_h = values[:, code_of(h, VISUAL_NOTHING)] < REJECTED  # (24, 88): the hearing part alone is rejected
    alone_v = values[:, code_of(HEARING_NOTHING, v)] < REJECTED
    pair = (h != HEARING_NOTHING) & (v != VISUAL_NOTHING)
    return recognised(values) & alone_h & alone_v & pair[None]


def extract_action_info(policies: np.ndarray, q_tables: np.ndarray,
                        states: Sequence[int] = COMPARED_STATES) -> ActionProfile:
    """Action-level user information over one user's policies: (n, 24) greedy codes, (n, 24, 88) Q-tables.

    ValueError if the shapes disagree or no state is compared (as extract_info)."""
    policies = np.atleast_2d(np.asarray(policies, dtype=np.int64))
    q_tables = np.asarray(q_tables, dtype=np.float64).reshape(-1, *policies.shape[1:], N_ACTIONS)
    if len(q_tables) != len(policies):
        raise ValueError(f"{counted(len(policies), 'policy', 'policies')} but {len(q_tables)} Q-tables")
    base = extract_info(policies, states)
    values = action_values(q_tables)
    whole = whole_actions(values)

    def synonyms_at(s: int, speech: bool) -> bool:
        actions = policies[:, s]
        if not recognised(values[s, actions]).all():
            return False
        h, v = parts(actions[~whole[s, actions]])
        family = HEARING_SPEECH[h] if speech else VISUAL_HEAD[v]
        return not incompatible(family, s, exempt_speech if speech else exempt_head)

    speech = [s for s in base.speech_states if not synonyms_at(s, True)]
    head = [s for s in base.head_states if not synonyms_at(s, False)]
    synonyms = sorted((set(base.speech_states) | set(base.head_states)) - set(speech) - set(head))
    wholes = [(int(s), int(a)) for s in np.asarray(states, dtype=np.int64)
              for a in np.unique(policies[:, s]) if whole[s, a]]
    n = base.info.compared_states
    info = UserInfo(speech=len(speech) / n, head=len(head) / n, facial=base.info.facial, gaze=base.info.gaze,
                    compared_states=n)
    return ActionProfile(info, values, speech, head, synonyms, wholes, base.info)


def combine_actions(users: Sequence[User], values: Sequence[np.ndarray]) -> Combined:
    """Algorithm 4, then whole actions kept (see the module rule): `values[i]` (24, 88) is user i's V.

    The users carry their action-level information (ActionProfile.info). Each
    state's rule gains "; whole=kept" or "; whole=chosen(k of n)"."""
    if len(users) != len(values):
        raise ValueError("one value table per user")
    return keep_wholes(combine(users), values)


def keep_wholes(merged: Combined, values: Sequence[np.ndarray]) -> Combined:
    """The wholes step of `combine_actions` on algorithm 4's merge of the users whose V are `values`."""
    known = np.stack([recognised(v) for v in values])  # (users, 24, 88)
    total = np.sum(values, axis=0)  # (24, 88)
    policy = merged.policy.copy()
    rules = []
    for s, rule in enumerate(merged.rules):
        votes = known[:, s].sum(axis=0)  # (88,) users recognising each action
        m = int(policy[s])
        if votes[m] >= votes.max():
            rules.append(f"{rule}; whole=kept")
            continue
        best = np.flatnonzero(votes == votes.max())
        choice = int(best[np.argmax(total[s, best])])  # argmax: the first (lowest code) of equal sums
        policy[s] = choice
        rules.append(f"{rule}; whole=chosen({int(votes[choice])} of {len(values)})")
    return Combined(policy, merged.q, merged.info, rules)


# --- the study report's experiment (report/future_actions.py) ----------------------------------

STRATEGIES = ("algorithm 3 + 4", "action-level info + algorithm 4", "action-level info + wholes kept")
# Merges of the reading personas (core/personas.py READING_PERSONAS) with the thesis's personas:
# the control "plain" beside each reader, then everyone who reads or perceives differently at once.
MERGES = (("plain", "tatiana"), ("duo", "tatiana"), ("compass", "tatiana"),
          ("plain", "deaf"), ("duo", "deaf"), ("compass", "deaf"), ("duo", "compass", "deaf", "blind"))
GAMES = 10  # policies per persona: 5 replicates of 2, as the human study's phase 1 (thesis 7.2)


class ActionLevelExperiment(NamedTuple):
    persona: list[str]  # every persona profiled: the readers, then the partners
    profiles: dict  # key -> ActionProfile over all GAMES policies
    replicate_info: np.ndarray  # (personas, replicates, 4): algorithm 3 speech, head; action-level speech, head
    merges: tuple[tuple[str, ...], ...]
    strategies: tuple[str, ...]
    picks: np.ndarray  # (strategies, replicates, members): merged policy on each member; members = merges flattened
    members: list[tuple[int, str]]  # (merge index, persona key) of each column of picks
    replaced: np.ndarray  # (replicates, merges): states whose algorithm-4 action the wholes step replaced
    info_changed: np.ndarray  # (replicates, merges): states where the action-level information alone changed the merge


def action_level_experiment(seed: int, rounds: int, training=None, replicates: int = 5, eval_games: int = 4,
                            eval_rounds: int = 50, reward_bonus: str = DEFAULT_REWARD_BONUS,
                            progress=None) -> ActionLevelExperiment:
    """`add_action_level` on a batch of its own, played at once (the study shares its batch instead)."""
    from .study import Evaluations
    batch = Evaluations(seed)
    pending = add_action_level(batch, seed, rounds, training, replicates, eval_games, eval_rounds, reward_bonus,
                               progress)
    batch.play()
    return pending()


def add_action_level(batch, seed: int, rounds: int, training=None, replicates: int = 5, eval_games: int = 4,
                     eval_rounds: int = 50, reward_bonus: str = DEFAULT_REWARD_BONUS,
                     progress=None) -> Callable[[], ActionLevelExperiment]:
    """Profile the reading personas and their partners both ways, and merge them three ways per replicate;
    the evaluation games are queued in `batch` (a core.study.Evaluations seeded `seed`), and the returned
    `pending()` reads the experiment from it once it has played.

    Training: GAMES games of `rounds` rounds per persona (core/study.py train, so
    game g of persona P is the default study's game g of P); rows of `training`
    (a core.study.Training of the same seed, rounds and reward rule) are reused for partners
    it holds with GAMES games. Replicate r takes games r, r + R, ... of each persona;
    each merge's member is represented by the first of them (the thesis picks one
    at random, 6.2; here all strategies see the same one). Every merged policy
    plays the same `eval_games` evaluation games of each member, epsilon 0, one batch."""
    from .personas import PERSONAS, READING_PERSONAS
    from .study import train
    keys = list(dict.fromkeys(k for m in MERGES for k in m))
    readers = [k for k in keys if k in READING_PERSONAS]
    partners = [k for k in keys if k not in READING_PERSONAS]
    everyone = {**PERSONAS, **READING_PERSONAS}
    reuse = training is not None and training.result.picks.shape[1] == rounds and all(
        (np.array([p.key for p in training.personas]) == k).sum() >= GAMES for k in partners)
    fresh = readers if reuse else keys
    own = train([everyone[k] for k in fresh], GAMES, rounds, seed, progress=progress, reward_bonus=reward_bonus)
    greedy, q = {}, {}
    for source, names in ((own, fresh), (training, partners if reuse else [])):
        for k in names:
            rows = [i for i, (p, g) in enumerate(zip(source.personas, source.game_index)) if p.key == k and g < GAMES]
            greedy[k], q[k] = source.greedy[rows], source.result.q[rows]
    profiles = {k: extract_action_info(greedy[k], q[k]) for k in keys}
    info = np.zeros((len(keys), replicates, 4))
    named: dict = {}
    replaced = np.zeros((replicates, len(MERGES)), dtype=np.int64)
    info_changed = np.zeros_like(replaced)
    for r in range(replicates):
        reps = {k: extract_action_info(greedy[k][r::replicates], q[k][r::replicates]) for k in keys}
        for i, k in enumerate(keys):
            a3, al = reps[k].algorithm3, reps[k].info
            info[i, r] = a3.speech, a3.head, al.speech, al.head
        for j, merge in enumerate(MERGES):
            first = {k: (greedy[k][r], q[k][r]) for k in merge}
            thesis = combine([User(k, *first[k], reps[k].algorithm3) for k in merge])
            informed = combine([User(k, *first[k], reps[k].info) for k in merge])
            kept = keep_wholes(informed, [reps[k].values for k in merge])
            for s, m in enumerate((thesis.policy, informed.policy, kept.policy)):
                named[(s, r, j)] = m
            replaced[r, j] = sum("whole=chosen" in rule for rule in kept.rules)
            info_changed[r, j] = int((named[(1, r, j)] != named[(0, r, j)]).sum())
    members = [(j, k) for j, merge in enumerate(MERGES) for k in merge]
    # a (persona, policy, game) is played once: equal merges (strategies that agree) share their games
    order = [(k, named[(s, r, j)].tobytes(), g) for s in range(len(STRATEGIES)) for r in range(replicates)
             for j, k in members for g in range(eval_games)]
    unique = list(dict.fromkeys(order))
    rows = batch.add([everyone[k] for k, _, _ in unique], np.array([np.frombuffer(b, np.int64) for _, b, _ in unique]),
                     eval_rounds, [g for *_, g in unique])

    def pending() -> ActionLevelExperiment:
        played = dict(zip(unique, batch.picks[rows]))
        picks = np.array([played[o] for o in order]).reshape(len(STRATEGIES), replicates, len(members),
                                                             eval_games).mean(-1)
        return ActionLevelExperiment(keys, profiles, info, MERGES, STRATEGIES, picks, members, replaced, info_changed)
    return pending
