"""The combiner service: user profiles and merged policies on request (thesis 5.2).

Rule: a CombineRequested names policy files and/or recordings; recordings are
rebuilt into policies first (replay/rebuild.py, the learner's own fold). The
policies are grouped by user (the policy's participant); each user's profile
is algorithm 3 over all of that user's policies, and one policy per user
represents it, picked at random by the request's seed
(core.policies.users_from_policies, as the study and `pairplay combine` do). The users'
representatives are merged by algorithm 4 (core.combine.combine), and the
answer is a PolicyCombined with the greedy actions, the rule that decided each
state and the merged information; with `output_path` the combined policy file
is written too. Paths are taken relative to, and must stay inside, the
combiner's directory (`--out` of `pairplay run combiner`, default the current
one). Anything wrong with the request (a missing or corrupt file, no
users left, a policy given twice, mixed reward rules, a user of one policy
(no profile: algorithm 3 compares two or more), an output_path that exists:
it is never replaced) is answered with ok=false and the reason: the combiner
keeps running. The answer copies the request's text (its id and inputs, a path in an
error): one that would not fit the bus's MAX_PAYLOAD (a listener sheds it unread) is
answered instead with ok=false saying so, the error clipped (schemas/trust.py).
"""

from __future__ import annotations

from pathlib import Path

from pairplay import __version__
from pairplay.core.combine import combine
from pairplay.core.policies import (check_distinct, check_profiles_computable, combined_policy_file,
                                    common_reward_bonus, partial_inputs, users_from_policies)
from pairplay.errors import UserError
from pairplay.numbers import counted
from pairplay.replay.rebuild import RebuildError, rebuild_recording
from pairplay.schemas import events as ev
from pairplay.schemas.policy import PolicyFile, PolicyFileError, read_policy, write_policy
from pairplay.schemas.trust import MAX_NAME, MAX_PAYLOAD, MAX_REASON, clip

ENVELOPE = 1024  # bytes left for the envelope stamped on the answer (session, source, seq, time)


class CombinerLogic:
    name = "combiner"
    consumes = frozenset({"CombineRequested"})
    sources: dict = {}
    done = False  # serves until stopped

    def __init__(self, root: str | Path | None = None):
        # every path a request names must lie under this directory: a bus message
        # must not make the combiner read or write anywhere on the machine
        self.root = Path(root or Path.cwd()).resolve()

    def _inside(self, path: str) -> str:
        resolved = (self.root / path).resolve()
        if not resolved.is_relative_to(self.root):
            raise ValueError(f"{path!r} is outside the combiner's directory {self.root}")
        return str(resolved)

    def start(self) -> list[ev.Event]:
        return []

    def handle(self, r: ev.CombineRequested) -> list[ev.Event]:
        inputs = list(r.policies) + list(r.recordings)
        try:
            policies = [read_policy(self._inside(p)) for p in r.policies]
            policies += [rebuild_recording(self._inside(p)).policy for p in r.recordings]
            answer = self._combine(r, inputs, policies)
        except (OSError, PolicyFileError, RebuildError, ValueError, UserError) as err:
            # a requester on the bus gives no command-line option: str() leaves out a fix naming one
            answer = ev.PolicyCombined(request_id=r.request_id, inputs=inputs, actions=[], ok=False,
                                       error=clip(f"{type(err).__name__}: {err}", MAX_REASON))
        return [fitting(answer)]

    def _combine(self, r: ev.CombineRequested, inputs: list[str], policies: list[PolicyFile]) -> ev.PolicyCombined:
        users, _ = users_from_policies(policies, r.seed, exclude=set(r.exclude))
        if not users:
            raise ValueError("no policies left to combine")
        check_distinct(policies, inputs)
        kept = [(p, name) for p, name in zip(policies, inputs) if p.participant not in set(r.exclude)]
        rule = common_reward_bonus([p for p, _ in kept], [name for _, name in kept])
        # as `pairplay combine`: a participant of one policy has no profile, and would be merged as one who
        # perceives every channel
        check_profiles_computable([p for p, _ in kept], [name for _, name in kept], merge=True)
        merged = combine(users)
        out = ""
        if r.output_path:
            write_policy(self._inside(r.output_path),
                         combined_policy_file(merged, users, inputs, r.seed, software=__version__, reward_bonus=rule,
                                              partial=partial_inputs(policies, inputs, set(r.exclude))))
            out = r.output_path
        return ev.PolicyCombined(request_id=r.request_id, inputs=inputs, actions=[int(a) for a in merged.policy],
                                 decided_by=list(merged.rules), output_path=out, users=[u.name for u in users],
                                 speech_error=merged.info.speech, head_error=merged.info.head,
                                 facial=merged.info.facial, gaze=merged.info.gaze)


def fitting(answer: ev.PolicyCombined) -> ev.PolicyCombined:
    """`answer`, or if it would be over the bus's MAX_PAYLOAD once stamped, an ok=false answer saying so
    (see rule: the requester would never hear of its request otherwise, nor the recording hold it)."""
    size = len(ev.encode_event(answer)) + ENVELOPE
    if size <= MAX_PAYLOAD:
        return answer
    return ev.PolicyCombined(request_id=clip(answer.request_id, MAX_NAME), inputs=[], actions=[], ok=False,
                             error=f"the answer would be about {counted(size, 'byte', spec=',')}, over the bus's limit of {MAX_PAYLOAD:,}: "
                                   "name fewer or shorter inputs")
