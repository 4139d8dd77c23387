"""The learner service: suggestions, rewards and Q updates for one session.

Rule (thesis 5.1, 5.3, 6.1.3, 7.1.2): the session config picks the algorithm:
Q-learning ("q-learning"), pi-reuse of the bias policy ("pi-reuse"), a fixed
policy ("fixed") or online LSPI ("lspi", core.lspi.LSPILearner, which records
an LSPIUpdated per learned sample instead of QUpdated); the learner is
core.learning.Learner (or its LSPI subclass) with a batch of one and
the session's "agent" stream, so a session on the bus learns exactly what the
in-process study (core.simulate) learns for the same seed and persona.
Each SuggestionRequested gets one SuggestionMade. A suggestion is settled once
its turn is resolved and, under the "perceived" ignore rule, the participant
has said what it perceived: RewardGiven (always, learned or not) and QUpdated
(when the table changed, with q_before/q_after). A new request in the same
turn means "wrong suggestion" (thesis 7.1.3): the open one gets -3 first.
The next suggestion waits until the previous one is settled (NotYet), so Q is
updated in the same order as in the study whatever order the bus delivered.
"""

from __future__ import annotations

import numpy as np

from pairplay.core.actions import ACTION_NAMES
from pairplay.core.geometry import N_STATES
from pairplay.core.learning import How, Learner
from pairplay.core.lspi import LSPILearner, weights_digest
from pairplay.core.reward import WRONG_SUGGESTION, human_reward, simulated_reward_one
from pairplay.core.rng import UniformStream
from pairplay.schemas import events as ev
from pairplay.schemas.session import MODE_OF_ALGORITHM

from pairplay.services.node import NotYet, Rejected, refused_start, stream_seed

HOW_NAMES = {How.GREEDY: "greedy", How.EXPLORE: "explore", How.BIAS: "bias", How.FIXED: "fixed"}


class LearnerLogic:
    name = "learner"
    consumes = frozenset({"SessionStarted", "SuggestionRequested", "SuggestionPerceived", "TurnResolved",
                          "SessionEnded"})
    by_tag = True  # every ordering between keys is handled (NotYet), so subscribe to just these
    sources = {"SessionStarted": frozenset({"game"}), "SuggestionRequested": frozenset({"game"}),
               "TurnResolved": frozenset({"game"}), "SessionEnded": frozenset({"game"}),
               "SuggestionPerceived": frozenset({"participant"})}

    def __init__(self):
        self.config = None
        self.learner: Learner | None = None
        self.open: ev.SuggestionMade | None = None
        self.perceived: dict[tuple[int, int, int], ev.SuggestionPerceived] = {}
        self.resolved: dict[tuple[int, int], ev.TurnResolved] = {}
        self.round_started = -1
        self.ended = False
        self.refused = ""  # why we refused the session's start (refused_start)
        # the batch of one an LSPI learner reads, filled in place per update (the Q-learner's live path is
        # core/learning.py suggest_one / learn_one, which keep their own), and the round for start_round
        self._state, self._action, self._round = (np.zeros(1, dtype=np.int64) for _ in range(3))
        self._reward_one, self._learn_one = np.zeros(1), np.ones(1, dtype=bool)

    @property
    def done(self) -> bool:
        return self.ended and self.open is None

    def start(self) -> list[ev.Event]:
        return []

    def handle(self, e: ev.Event) -> list[ev.Event]:
        if isinstance(e, ev.SessionStarted):
            return self._configure(e)
        if self.config is None:
            self.ended = refused_start(self, e)  # NotYet until the start comes; after a refused one, the end
            return []
        if isinstance(e, ev.SuggestionRequested):
            return self._suggest(e)
        if isinstance(e, ev.SuggestionPerceived):
            self.perceived[(e.round, e.turn, e.attempt)] = e
        elif isinstance(e, ev.TurnResolved):
            self.resolved[(e.round, e.turn)] = e
        elif isinstance(e, ev.SessionEnded):
            self.ended = True
            if e.reason != "completed" and self.open is not None:
                # an aborted game leaves its last suggestion unsettled: recorded, not learned from
                return self._reward(self.open, 0.0, False, f"unsettled: the session ended ({e.reason})")
        return self._settle()

    def _configure(self, e: ev.SessionStarted) -> list[ev.Event]:
        if self.config is not None:
            raise Rejected("the session has already started")
        try:
            e.config.validate()
            schedule = e.config.learner_config()
        except ValueError as err:
            self.refused = f"cannot learn with this session config: {err}"
            raise Rejected(self.refused) from None
        # a policy of the wrong length or codes is refused by validate (SessionConfig), as the game refuses it
        policy = np.array(e.config.policy_actions, dtype=np.int64) if e.config.policy_actions else None
        mode = MODE_OF_ALGORITHM[e.config.algorithm]
        stream = UniformStream([stream_seed(e.config)], "agent")
        if mode == "lspi":
            self.learner = LSPILearner(1, stream, schedule, e.config.lspi_config())
        else:
            self.learner = Learner(1, stream, schedule, mode, bias=policy if mode == "reuse" else None,
                                   policy=policy if mode == "fixed" else None)
        self.schedule, self.mode, self.config = schedule, mode, e.config
        return []

    def _suggest(self, r: ev.SuggestionRequested) -> list[ev.Event]:
        if not (0 <= r.state < N_STATES):
            raise Rejected(f"state {r.state} is outside 0..{N_STATES - 1}")
        out: list[ev.Event] = []
        if self.open is not None:
            o = self.open
            if (r.round, r.turn, r.attempt) != (o.round, o.turn, o.attempt + 1):
                raise NotYet  # the previous suggestion is not settled yet
            out += self._reward(o, WRONG_SUGGESTION, True, "wrong suggestion pressed")
        self._round[0] = r.round
        if r.round != self.round_started:
            self.learner.start_round(self._round)
            self.round_started = r.round
            # per-round schedule values, for the record (computed once a round: latency)
            self.epsilon, self.alpha = self.learner.schedule(r.round)
        psi = float(self.learner.psi[0]) if self.mode == "reuse" else 0.0  # before the suggestion decays it
        action, how = self.learner.suggest_one(r.state, r.round)
        self.open = ev.SuggestionMade(
            round=r.round, turn=r.turn, attempt=r.attempt, state=r.state, action=action,
            chosen_by=HOW_NAMES[how], epsilon=self.epsilon, alpha=self.alpha, psi=psi,
            observed=r.observed, target=r.match, action_name=ACTION_NAMES[action], request_seq=r.seq)
        return out + [self.open]

    def _settle(self) -> list[ev.Event]:
        o = self.open
        if o is None:
            return []
        turn = self.resolved.get((o.round, o.turn))
        if turn is None:
            return []
        if self.config.ignore_rule == "time":
            # the game timed the picks on the session's clock (server or page) and decided
            reward, learn = human_reward(turn.matched, ignored=turn.ignored_by_time)
            why = "ignored: picked too fast" if not learn else ("match" if turn.matched else "miss")
        else:
            p = self.perceived.get((o.round, o.turn, o.attempt))
            if p is None:
                return []  # the participant has not said yet what it perceived
            holds_match = (p.candidate_mask >> o.target) & 1 == 1
            reward, learn = simulated_reward_one(turn.matched, p.considered, p.consistent, p.candidate_size,
                                                 holds_match, self.config.reward_bonus)
            why = ("ignored: match from memory" if p.from_memory else "ignored: not considered") if not learn else (
                "inconsistent" if not p.consistent else ("match" if turn.matched else "miss"))
        self.perceived.pop((o.round, o.turn, o.attempt), None)
        self.resolved.pop((o.round, o.turn), None)
        self.open = None
        return self._reward(o, reward, learn, why)

    def _reward(self, o: ev.SuggestionMade, reward: float, learn: bool, why: str) -> list[ev.Event]:
        self.open = None
        learned = learn and self.mode != "fixed"
        out: list[ev.Event] = [ev.RewardGiven(round=o.round, turn=o.turn, attempt=o.attempt, state=o.state,
                                              action=o.action, reward=float(reward), learned=learned, reason=why)]
        if learned:
            before = float(self.learner.q[0, o.state, o.action])
        if learned and self.mode == "lspi":
            self._state[0], self._action[0], self._reward_one[0], self._round[0] = o.state, o.action, reward, o.round
            improved = self.learner.learn(self._state, self._action, self._reward_one, self._learn_one,
                                          self._round).size > 0
            out.append(ev.LSPIUpdated(
                round=o.round, turn=o.turn, attempt=o.attempt, state=o.state, action=o.action, reward=float(reward),
                samples=int(self.learner.samples[0]), improved=improved, q_before=before,
                q_after=float(self.learner.q[0, o.state, o.action]),
                weights=weights_digest(self.learner.theta[0]) if improved else ""))
        elif learned:
            self.learner.learn_one(o.state, o.action, reward, o.round)
            out.append(ev.QUpdated(round=o.round, turn=o.turn, attempt=o.attempt, state=o.state, action=o.action,
                                   alpha=o.alpha, reward=float(reward),
                                   q_before=before, q_after=float(self.learner.q[0, o.state, o.action])))
        return out
