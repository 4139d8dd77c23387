"""`pairplay profile POLICY...` and `pairplay combine POLICY...` on policy files.

Rule: policy files are grouped by their participant; each participant's user
information comes from all of its files (algorithm 3), and one file per
participant, picked by the seed, enters the combination (algorithm 4). Refused
before anything is written (one line, exit 2): a file that cannot be read, a
policy given twice (the same file, a folder named twice, or two files holding
the same learning: it would weigh double), a profile of a participant with a
single policy (algorithm 3 compares policies: it would say 0% / 0%), a merge
of such a participant (algorithm 4 weighs each by that profile: one policy was
merged as a participant perceiving every channel, "hearing=equal" everywhere), an
--exclude naming no participant, policies of different reward rules (the
files of each rule are named; a profile too: a participant's policies would
differ by the rule, not by what the participant perceives), a learned policy that learned nothing (0 rounds,
no state ever updated, its Q-table all 0: an older rebuild of a recording cut
before its first round wrote one; it would count as a participant who agrees
with everything; a table written by hand, with values, is taken),
and an existing --out without --force. A merge of any policy flagged partial
(a session not completed, a damaged recording) is partial: its file's `partial`
field names that input and why (core/policies.py `partial_inputs`), said once; a
profile of one says so after its table and on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from pairplay import __version__
from pairplay.core.actions import ACTIONS
from pairplay.core.actionlevel import combine_actions, extract_action_info
from pairplay.core.combine import COMPARED_STATES, combine, extract_info, trained_states
from pairplay.core.geometry import STATE_NAMES
from pairplay.core.policies import (by_participant, check_distinct, check_exclude, check_profiles_computable,
                                    combined_policy_file, common_reward_bonus, partial_inputs, users_from_policies)
from pairplay.errors import InputError, OptionError, escaped
from pairplay.lists import comma_items
from pairplay.outputs import check_output, hold
from pairplay.schemas.policy import read_policy, write_policy
from pairplay.cli.args import add_force, output_file, seed_number, update_count
from pairplay.numbers import counted


LEARNED = ("q-learning", "lspi", "pi-reuse")  # policies a session learned (not combined, oracle or fixed ones)


def _policy_paths(paths: list[Path]) -> list[Path]:
    """Files as given; a folder stands for every *.json below it (a study's policies/).
    InputError for a path that does not exist, a folder without policy files, a file given twice, a study folder
    (its other JSON files are no policies: its policies/ is meant)."""
    from pairplay.replay.copies import study_root

    out: dict[Path, Path] = {}
    for p in paths:
        if not p.exists():
            raise InputError("no such policy file or folder", p)
        if study_root(p) == p.resolve():  # its settings.json was read as a policy ("no "format" field"), no hint
            raise InputError(f"a study folder, not policy files: give its games' policies, {p / 'policies'} "
                             f"(or {p / 'merged'} for its bias policies)", p)
        found = sorted(p.rglob("*.json")) if p.is_dir() else [p]
        if not found:
            raise InputError("holds no policy files (*.json)", p)
        for f in found:
            if f.resolve() in out:
                raise InputError(f"given twice (also as {out[f.resolve()]}): each policy may count once", f)
            out[f.resolve()] = f
    return list(out.values())


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("policies", nargs="+", type=Path, help="policy files, or folders of them")
    p.add_argument("--seed", type=seed_number, default=0, help="picks each participant's representative policy")


def add_profile_arguments(p: argparse.ArgumentParser) -> None:
    _common(p)
    p.add_argument("--min-updates", type=update_count, default=0,
                   help="compare only the states every policy of a participant updated at least this many "
                        "times (default 0: the 23 spatial states, algorithm 3; thesis 6.4: untrained states)")
    p.add_argument("--actions", action="store_true",
                   help="also the action-level information (thesis chapter 8, future work 1; core/actionlevel.py): "
                        "disagreements between wholes the participant recognises are not counted")


def add_combine_arguments(p: argparse.ArgumentParser) -> None:
    _common(p)
    p.add_argument("--out", "-o", type=output_file(), help="write the merged policy file here")
    p.add_argument("--exclude", help="comma-separated participants to leave out")
    p.add_argument("--actions", action="store_true",
                   help="action-level information and wholes kept (thesis chapter 8, future work 1; "
                        "core/actionlevel.py) instead of algorithms 3 and 4 alone")
    add_force(p, "an existing --out file")


def _load(args) -> tuple[list, list[str]]:
    """(policies, file names): every file read and checked, no policy counted twice (InputError otherwise)."""
    files = _policy_paths(args.policies)
    policies = [read_policy(f) for f in files]
    names = [str(f) for f in files]
    for p, name in zip(policies, names):
        if p.algorithm == "combined":  # a merge of users' policies is no user's: its users would count twice
            # (a new user's trial: a second `combine cf` took the first's cf/m.json as a third policy of ashley)
            raise InputError(f"is a combined policy (merged from {counted(len(p.merged_from), 'file')}), not one user's "
                             "policy: give the users' own policies", name)
        if p.algorithm in LEARNED and p.rounds == 0 and not any(p.visits) and not any(map(any, p.q)):
            raise InputError("holds no whole round: a policy of 0 rounds that learned nothing (no state updated, "
                             "its Q-table all 0); leave it out", name)
    check_distinct(policies, names)
    return policies, names


def _profile_lines(profiles, policies) -> list[str]:
    counts: dict[str, int] = {}
    for p in policies:
        counts[p.participant] = counts.get(p.participant, 0) + 1
    lines = [f"{'participant':16s} {'policies':>8s} {'states':>6s} {'speech %':>9s} {'head %':>7s} {'smile':>6s} "
             f"{'gaze':>5s}  incompatible states"]
    for name, prof in profiles.items():
        if prof is None:
            lines.append(f"{name:16s} {counts[name]:>8d} {0:>6d}  no state trained that often")
            continue
        states = ", ".join([f"{STATE_NAMES[s]}(S)" for s in prof.speech_states] + [f"{STATE_NAMES[s]}(H)" for s in prof.head_states])
        lines.append(f"{name:16s} {counts[name]:>8d} {prof.info.compared_states:>6d} {100 * prof.info.speech:9.1f} "
                     f"{100 * prof.info.head:7.1f} {'yes' if prof.info.facial else 'no':>6s} "
                     f"{'yes' if prof.info.gaze else 'no':>5s}  {states or '-'}")
    return lines


def _trained_profiles(policies, min_updates: int) -> dict:
    """Per participant, algorithm 3 over the states all its policies updated >= min_updates times (or None)."""
    out = {}
    for name, own in by_participant(policies).items():
        states = trained_states(np.array([p.visits for p in own]), min_updates)
        out[name] = extract_info(np.array([p.greedy for p in own]), states) if states.size else None
    return out


def run_profile(args) -> int:
    policies, names = _load(args)
    check_profiles_computable(policies, names)
    # a participant's policies of different reward rules differ by the rule, not by what the participant
    # perceives: refused as combine refuses them (a new user's trial: profile pooled them without a word)
    common_reward_bonus(policies, names)
    if args.min_updates > 0:
        profiles = _trained_profiles(policies, args.min_updates)
        print(f"states every policy of a participant updated at least {counted(args.min_updates, 'time')}")
    else:
        _, profiles = users_from_policies(policies, args.seed)
    # what the columns are (a new user's trial read Blind's "speech 0.0, head 52.2" as "no speech"): the
    # report and the console say "speech incompatible %"; this table keeps its short columns and says it
    print("speech %, head %: share of the compared states where the participant's policies disagree on speech, on "
          "head (algorithm 3: high means the participant does not perceive that channel); smile, gaze: used at all")
    print("\n".join(_profile_lines(profiles, policies)))
    if args.actions:
        print("\naction level (core/actionlevel.py): algorithm 3's shares without the states where the policies' "
              "differing actions are wholes the participant recognises")
        print("\n".join(_action_lines(policies, args.min_updates)))
    # a profile of a partial policy (rebuild --partial) is partial as a merge of one is (a trial: profile said
    # nothing): in the output, which may go to a file, and on stderr, which a reader of the terminal sees
    partial = partial_inputs(policies, names)
    if partial:
        print(f"\nPARTIAL profile: {escaped(partial)}")
        print(f"pairplay profile: PARTIAL profile: {escaped(partial)}", file=sys.stderr)
    return 0


def _action_lines(policies, min_updates: int) -> list[str]:
    """Per participant: algorithm 3 -> action level (speech %, head %), synonym states and wholes."""
    lines = [f"{'participant':16s} {'states':>6s} {'speech %':>15s} {'head %':>15s}  synonym states; wholes"]
    for name, own in by_participant(policies).items():
        states = trained_states(np.array([p.visits for p in own]), min_updates) if min_updates else COMPARED_STATES
        if not states.size:
            lines.append(f"{name:16s} {0:>6d}  no state trained that often")
            continue
        prof = extract_action_info(np.array([p.greedy for p in own]), np.array([p.q for p in own]), states)
        a3, al = prof.algorithm3, prof.info
        wholes = ", ".join(f"{STATE_NAMES[s]}: {ACTIONS[a].name}" for s, a in prof.wholes)
        lines.append(f"{name:16s} {al.compared_states:>6d} {f'{100 * a3.speech:.1f} -> {100 * al.speech:.1f}':>15s} "
                     f"{f'{100 * a3.head:.1f} -> {100 * al.head:.1f}':>15s}  "
                     f"{', '.join(STATE_NAMES[s] for s in prof.synonym_states) or '-'}; {wholes or '-'}")
    return lines


def run_combine(args) -> int:
    if args.out is not None:
        hold(args.out, "combine")  # one writer per output (pairplay/outputs.py)
        check_output(args.out, args.force)  # before any work
    policies, files = _load(args)
    if args.out is not None:
        check_output(args.out, args.force, inputs=files)  # -o a.json --force replaced its own input a.json
        from pairplay.replay.copies import Copies
        copies = Copies("combine", files)  # a study's policies merged: a copy of their data their deletion must know
        copies.check([args.out])
    try:
        exclude = set(comma_items(args.exclude)) if args.exclude is not None else set()
    except ValueError as exc:  # `p1,,p2`: a name lost to a typo would be combined
        raise OptionError(str(exc), "--exclude") from None
    check_exclude(policies, exclude)
    kept = [(p, f) for p, f in zip(policies, files) if p.participant not in exclude]
    if not kept:
        raise OptionError("no policies left to combine", f"--exclude {args.exclude}")
    reward_rule = common_reward_bonus([p for p, _ in kept], [f for _, f in kept])
    # a participant of one policy has no profile: merged as one who perceives everything (a new user's trial)
    check_profiles_computable([p for p, _ in kept], [f for _, f in kept], merge=True)
    users, profiles = users_from_policies(policies, args.seed, exclude)
    if args.actions:  # the same representative policies, with action-level information, then wholes kept
        groups = by_participant(policies, exclude)
        action = [extract_action_info(np.array([p.greedy for p in groups[u.name]]),
                                      np.array([p.q for p in groups[u.name]])) for u in users]
        users = [u._replace(info=a.info) for u, a in zip(users, action)]
        merged = combine_actions(users, [a.values for a in action])
    else:
        merged = combine(users)
    partial = partial_inputs(policies, files, exclude)  # a merge of a partial policy is partial: flagged, said once
    if args.out:  # written before the listing, so a reader that stops early loses nothing
        write_policy(args.out, combined_policy_file(merged, users, files, args.seed, f"pairplay {__version__}",
                                                    reward_rule, partial), args.force)
        copies.journal([args.out], inputs=[f for _, f in kept])  # an excluded participant's data is not in it
    print("\n".join(_profile_lines(profiles, policies)))
    print(f"\nmerged: speech {100 * merged.info.speech:.1f}%, head {100 * merged.info.head:.1f}%, "
          f"smile {merged.info.facial}, gaze {merged.info.gaze}\n")
    for s, (a, rule) in enumerate(zip(merged.policy, merged.rules)):
        print(f"{s:2d} {STATE_NAMES[s]:16s} {int(a):2d} {ACTIONS[int(a)].name:55s} {rule}")
    if partial:  # in the listing and on stderr, -q or not, as profile's (cli/main.py `warn`: -q hid it)
        print(f"\nPARTIAL merge: {escaped(partial)}")
        print(f"pairplay combine: PARTIAL merge: {escaped(partial)}", file=sys.stderr)
    if args.out:
        print(f"\nwrote {escaped(args.out)}")
    return 0


add_arguments, run = add_combine_arguments, run_combine
