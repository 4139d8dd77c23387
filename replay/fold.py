"""State as a fold over events: what the learner learned and how the game went.

Rule: `SessionFold.evolve(event)` folds one event; a session's state is the
fold of its log in order. The Q-table is rebuilt from QUpdated events with
`core.learning.q_update`, the very expression the live learner applies (eq.
5.2), on the recorded reward and alpha, so the rebuilt table equals the live
learner's bit for bit. Each QUpdated also carries the learner's q_before: a
disagreement (a lost or reordered update) is counted, not hidden.
An LSPI session (core/lspi.py) is rebuilt from its LSPIUpdated events: the
samples go, in order, through the live learner's own code (a batch of one), so
the weights are the live learner's bit for bit; each event's q_before and, after
a policy improvement, the digest of the weights are checked the same way.
Learning curves come from RoundEnded (turns per round: 9 is perfect play) and
RewardGiven (reward per round), over the whole rounds only (`whole_rounds`: those
whose RoundEnded is in the log). A round a session stopped in, or a file was cut
in, was a row of 0 turns and 0 picks (its rewards had made it a round): curves
ended in a "perfect" 0, the mean picks fell, and rebuild, lab and session
counted it as played. Its updates still count in the Q-table.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pairplay.arguments import at, given
from pairplay.core.actions import N_ACTIONS
from pairplay.core.geometry import N_STATES
from pairplay.core.learning import q_update
from pairplay.core.lspi import LSPILearner, weights_digest
from pairplay.core.rng import UniformStream, game_seed
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import Event
from pairplay.errors import ArgumentError, InputError
from pairplay.schemas.session import SessionConfig


def stream_seed(config: SessionConfig) -> int:
    """The seed of a session's per-role streams (core.rng), named as in the study:
    the persona's key (or the human participant's id) and the game index, by the
    stream derivation the session records (1 for recordings of pairplay <= 0.2)."""
    return game_seed(config.seed, config.persona or config.participant, config.game_index, config.streams)


@dataclass
class RoundStats:
    turns: int = 0
    matches: int = 0
    reward: float = 0.0
    learned: int = 0
    inconsistent: int = 0
    ended: bool = False  # its RoundEnded is in the log: a whole round


@dataclass
class SessionFold:
    config: SessionConfig | None = None
    q_rows: list[list[float]] = field(default_factory=lambda: [[0.0] * N_ACTIONS for _ in range(N_STATES)])
    visits: list[int] = field(default_factory=lambda: [0] * N_STATES)
    rounds: dict[int, RoundStats] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    q_mismatches: int = 0
    rejections: list[str] = field(default_factory=list)
    ended: ev.SessionEnded | None = None
    events: int = 0
    lspi: LSPILearner | None = None  # an LSPI session's learner, rebuilt sample by sample

    @property
    def q(self) -> np.ndarray:
        if self.lspi is not None:
            return self.lspi.q[0].copy()
        return np.array(self.q_rows, dtype=np.float64)

    def round(self, index: int) -> RoundStats:
        stats = self.rounds.get(index)
        if stats is None:
            stats = self.rounds[index] = RoundStats()
        return stats

    def evolve(self, event: Event) -> None:
        self.events += 1
        name = type(event).__name__
        self.counts[name] = self.counts.get(name, 0) + 1
        handler = _HANDLERS.get(name)
        if handler is not None:
            handler(self, event)

    def count(self, skipped: dict[str, int]) -> "SessionFold":
        """Count events not decoded because no handler reads them (read_log's `only=READS`), by tag."""
        for name, n in skipped.items():
            self.events += n
            self.counts[name] = self.counts.get(name, 0) + n
        return self

    def fold(self, events) -> "SessionFold":
        """`evolve` of each event in order, its steps inlined (a call and three attribute look-ups per event
        were a third of rebuild's fold)."""
        counts, handlers = self.counts, _HANDLERS
        for e in events:
            self.events += 1
            name = type(e).__name__
            counts[name] = counts.get(name, 0) + 1
            handler = handlers.get(name)
            if handler is not None:
                handler(self, e)
        return self

    def whole_rounds(self) -> list[int]:
        """The indices of the rounds whose RoundEnded is in the log, in order (module rule)."""
        return [r for r in sorted(self.rounds) if self.rounds[r].ended]

    def turns_per_round(self) -> list[int]:
        return [self.rounds[r].turns for r in self.whole_rounds()]

    def picks_per_round(self) -> list[int]:
        """Cards picked per whole round, the study's unit (2 per turn; 18 = perfect play)."""
        return [2 * self.rounds[r].turns for r in self.whole_rounds()]

    def reward_per_round(self) -> list[float]:
        return [self.rounds[r].reward for r in self.whole_rounds()]


def _session_started(s: SessionFold, e: ev.SessionStarted) -> None:
    s.config = e.config
    if e.config.algorithm == "lspi":
        try:
            s.lspi = LSPILearner(1, UniformStream([stream_seed(e.config)], "agent"), e.config.learner_config(),
                                 e.config.lspi_config())
        except ValueError as err:
            s.rejections.append(f"SessionStarted: cannot rebuild its LSPI learner: {err}")


def _lspi_updated(s: SessionFold, e: ev.LSPIUpdated) -> None:
    learner = s.lspi
    if learner is None or not (0 <= e.state < N_STATES and 0 <= e.action < N_ACTIONS):
        s.q_mismatches += 1  # an LSPI sample in a session that has no LSPI learner, or off the table
        return
    if learner.q[0, e.state, e.action] != e.q_before:
        s.q_mismatches += 1
    improved = learner.learn(np.array([e.state]), np.array([e.action]), np.array([e.reward]),
                             np.array([True])).size > 0
    if improved != e.improved or int(learner.samples[0]) != e.samples or \
            (improved and weights_digest(learner.theta[0]) != e.weights):
        s.q_mismatches += 1
    s.visits[e.state] += 1


def _q_updated(s: SessionFold, e: ev.QUpdated) -> None:
    row = s.q_rows[e.state]
    if row[e.action] != e.q_before:
        s.q_mismatches += 1
    row[e.action] = q_update(row[e.action], e.reward, e.alpha)
    s.visits[e.state] += 1


def _reward(s: SessionFold, e: ev.RewardGiven) -> None:
    stats = s.round(e.round)
    stats.reward += e.reward
    stats.learned += e.learned


def _perceived(s: SessionFold, e: ev.SuggestionPerceived) -> None:
    if e.considered and not e.consistent:
        s.round(e.round).inconsistent += 1


def _round_ended(s: SessionFold, e: ev.RoundEnded) -> None:
    stats = s.round(e.round)
    stats.ended = True
    stats.turns, stats.matches = e.turns, e.matches


def _rejected(s: SessionFold, e) -> None:
    s.rejections.append(f"{e.source}: {e.reason}")


def _ended(s: SessionFold, e: ev.SessionEnded) -> None:
    s.ended = e


_HANDLERS = {
    "SessionStarted": _session_started, "QUpdated": _q_updated, "LSPIUpdated": _lspi_updated, "RewardGiven": _reward,
    "SuggestionPerceived": _perceived, "RoundEnded": _round_ended, "MessageRejected": _rejected,
    "PickRejected": _rejected, "SessionEnded": _ended,
}

READS = frozenset(_HANDLERS)  # the event tags a fold reads; any other it only counts


def fold_events(events) -> SessionFold:
    """The fold of `events`, in order: events as a read log holds them (`e.event for e in log.events`); the public
    API's (`pairplay.fold_events`). ArgumentError (pairplay/arguments.py) for anything else: a non-iterable at
    once, an item that is no event when it comes (`fold_events([1, 2])` was an empty fold, a log's records were
    counted as events). InputError for no event at all: an empty log is no fold of a session (no config, no
    round, a Q-table of zeros that passed for a learner's: `fold_events([])`, or a filter that kept nothing, gave
    one with no word), as every verb refuses a recording that holds no session. `fold_any` folds nothing too."""
    fold = SessionFold().fold(_events(events))
    if not fold.events:
        raise InputError("events is empty: no event to fold (a fold of nothing is no session's; "
                         "a read log's are `e.event for e in log.events`)", at("fold_events", "events"))
    return fold


class Summed:
    """A session's recording summed up as it is read, a chunk's events at a time (reader.fold_log: none kept): its
    fold (`fold_any` of them), how many events, the game's last SessionEnded, whether it holds the questionnaire's
    answers, and the events of the `keep` tags (the robot's RobotActed: a delivery line). For the code that says
    how a session went from its recording (session, lab, a study server's game end): a 5,000-round session's read
    back was its file's records, events and bytes, 930 MB."""

    def __init__(self, keep: frozenset[str] = frozenset()) -> None:
        self.fold = SessionFold()
        self.events = 0
        self.game_end = None
        self.answered = False
        self.keep, self.kept = keep, []

    def __call__(self, recorded: list) -> None:
        events = [r.event for r in recorded]
        self.fold.fold(events)
        self.events += len(events)
        keep = self.keep
        for e in events:
            tag = type(e).__name__
            if tag == "SessionEnded" and getattr(e, "source", "") == "game":
                self.game_end = e
            elif tag == "QuestionnaireAnswered":
                self.answered = True
            if tag in keep:
                self.kept.append(e)


def fold_any(events) -> SessionFold:
    """The fold of `events` (events, in order), none too: an empty fold. For the code that folds what a session
    recorded, whatever it recorded (a session a signal stopped before its first event: lab, session, a study
    server's game end, rebuild's count), and says so in its own words."""
    return SessionFold().fold(events)


def _events(events):
    if isinstance(events, (str, bytes, dict)) or not hasattr(events, "__iter__"):
        raise ArgumentError(f"events must be an iterable of events, got {given(events)}", at("fold_events", "events"))
    from .reader import UnknownEvent
    return _each_event(events, (Event, UnknownEvent))


def _each_event(events, kinds):
    for place, e in enumerate(events):
        if not isinstance(e, kinds):
            hint = " (a read log's records hold theirs: `e.event for e in log.events`)" if hasattr(e, "event") else ""
            raise ArgumentError(f"events[{place}] must be an event{hint}, got {given(e)}", at("fold_events", "events"))
        yield e


def fold_sessions(events) -> dict[str, SessionFold]:
    """One fold per session id, for logs that hold several sessions."""
    folds: dict[str, SessionFold] = {}
    for e in events:
        f = folds.get(e.session)
        if f is None:
            f = folds[e.session] = SessionFold()
        f.evolve(e)
    return folds
