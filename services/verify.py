"""Verify a recording: fresh services, fed the recorded inputs, must say what was recorded.

Rule: for every service whose logic is deterministic (game, learner, simulated
participant), a fresh logic in a Driver is fed the recording's events from the
other sources, each source's in its own sequence order (whatever order the
recorder wrote them in), and the Driver holds an input until what it depends on
has been handled (node.py's `NotYet`, a source's later events waiting behind its
earlier ones), and the experimenter's pause and resume where the game's ControlTaken
says it took them (an abort where its SessionEnded says: node.py `resume`), so every
order a recorder can hold gives the same verdict; and every event it derives is compared, field by field
without the envelope's wall time and sequence number, with the event the live
service recorded, one by one in order. A recomputed event the recording lacks
or a recorded one never recomputed is a failure too, unless the recording was
cut short, or recovered from a cut (then the tail is excused and reported; a
cut after the data section's end, in the summary, lost none: reader.recovered_cut).
A session that stopped before its end (SessionEnded interrupted, aborted or
failed: a signal, the experimenter, a service lost; or no SessionEnded at all)
is verified up to where it stopped, whatever the moment: the game is fed the
inputs it handled before its shell ended it and is then ended the same way
(node.py `resume(stopped=...)`), and what the other services would have
derived from inputs they got after the stop is counted, not failed (they were
stopped). A tampered or missing event before the stop still fails. The
verdict says how far it verified (`Verification.reach`). The robot's RobotActed
comes from hardware and is not recomputed. Events of types this version does
not know (a newer pairplay's) are counted and named, and the verdict is about
the events this version derives. A file with a damaged part (a chunk that fails
its CRC, chunks out of order, a bad data-section or summary CRC: replay/mcapscan.py)
or a file recovered from one is never verified as whole: FAIL, naming the part
(`verify: FAIL: the file is damaged (...)`, what was lost where in a short line:
reader.EventLog.brief), unless its damage lost no event and is all after the data section
(the summary, the footer: reader.EventLog.data_intact; every event is as recorded, proved by
the chunks' and the data section's CRCs, and is compared): that PASSes, the damage said after
it in the line every verb says of such a file (reader.EventLog.loss_free). Damage among the
events that lost none (an index, the data section's CRC, chunks moved) still FAILs: bytes
there changed. A message that does not decode is damage too, and a
lost event. The first lost event (a part whose events are lost, or a message
that does not decode: reader.EventLog.lost_at) ends the comparison there, as a
cut would: every event after it follows lost ones, and was printed as DIFFERS
before "verified the whole session"; how many events came after it, not
compared, is said (`Verification.not_compared`). A file `pairplay recover` made of a
damaged one is whole, but its metadata says where the lost parts were (replay/recover.py
`lost_at`), and the reader marks a loss there: it is compared up to the first of them, as
the damaged file is (it printed every event after the hole as DIFFERS: artefacts of the
loss, not differences), and FAILs naming the parts; one whose damage lost no message (an
index, a CRC) is verified whole and says it was recovered.

The last line (`Verification.verdict`) says in one line whether the events
verified and how far: `verify: PASS` for a whole session; for a session
stopped early `verify: PASS up to where the session stopped (...)`; for a file
cut by a crash (or recovered from one) without its session's end `verify: PASS
as far as the file goes: the file is cut, the session's end is missing
(verified N events, rounds 1-K of R recorded ...)`, and a cut file whose end
is in it (only its index was lost) says that too. Rounds are counted from 1, as
the board shows them. A verdict about what is there, so the exit status is 0
for all of these (as for a stopped session), 1 for FAIL (cli/replay.py).
Before, a cut file said a plain `verify: PASS`. A file cut (or without its
session's end) before round 1 ended is refused (`verify_recording` raises
InputError: replay/check.py `no_whole_round`; a damaged one still FAILs,
naming the part): it said "PASS as far as the file goes" with exit 0 about no
whole round. A session that ended in round 1 (aborted, interrupted) is
verified: its whole life is in the file, and the verdict says where it stopped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pairplay.errors import InputError
from pairplay.replay.check import check_recording, no_whole_round
from pairplay.replay.recover import journal_more
from pairplay.replay.forgery import contradiction
from pairplay.replay.reader import events_of, recovered_cut, recovered_lost, said_source, said_source_made
from pairplay.schemas.events import RoundEnded, SessionEnded, SessionStarted

from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import SHELL_TAGS, Driver
from pairplay.services.participant import ParticipantLogic
from pairplay.numbers import counted
from pairplay.schemas.nesting import json_loads


SHOWN = 5  # of a service's differences, listed by `replay --verify` (then how many more)


def said(e) -> str:
    """A recomputed event in a line: its type, seq and round/turn where it has them (a FAIL for events
    recomputed beyond the recording named none of them, even with -v: trial33 L), counted from 1 as every line
    a person reads counts them ("rounds 1-18 of 20 recorded whole"); the events' fields count from 0, and one
    output said "round 18" of both the 19th round and the 18th (trial34 C)."""
    where = ", ".join(f"{k} {getattr(e, k) + 1}" for k in ("round", "turn") if isinstance(getattr(e, k, None), int))
    return f"{type(e).__name__} seq {e.seq}{f' ({where})' if where else ''}"


@dataclass
class ServiceCheck:
    service: str
    compared: int
    mismatches: list[str] = field(default_factory=list)
    extra: int = 0  # recomputed but not in the recording
    beyond: list[str] = field(default_factory=list)  # the first SHOWN of them, in words (`said`)

    def ok(self, truncated: bool) -> bool:
        return not self.mismatches and (self.extra == 0 or truncated)


@dataclass
class Verification:
    source: str
    checks: list[ServiceCheck]
    truncated: bool = False  # cut short (or recovered from a cut): a tail of every stream may be missing
    error: str = ""
    unknown: dict[str, int] = field(default_factory=dict)  # events of types this version does not know
    stopped: str = ""  # how a session that did not complete stopped ("" if it completed)
    reach: str = ""  # how far it was verified, in words
    events: int = 0  # events of the session in the file
    rounds: int = 0  # rounds the session was configured for
    rounds_recorded: int = 0  # rounds whose RoundEnded is in the file
    ended: bool = False  # the game's SessionEnded is in the file
    damaged: str = ""  # what a damaged file lost where, short (reader.EventLog.brief); "" if not damaged
    lost_part: bool = False  # verified only up to a part of the file whose events are lost
    not_compared: int = 0  # events after that part, not compared (they follow lost events)
    source_cut: str = ""  # a whole copy of a cut file: what its source's cut lost (reader.EventLog.source_cut)
    read_whole: str = ""  # a damage that lost no event (reader.EventLog.loss_free): said with the PASS, not a FAIL

    @property
    def verdict(self) -> str:
        """The last line of `replay --verify` (module rule); a damage that lost no event is said after a PASS."""
        said = self._verdict
        return f"{said}; {self.read_whole}" if self.read_whole and said.startswith("verify: PASS") else said

    @property
    def _verdict(self) -> str:
        if self.damaged:
            return f"verify: FAIL: the file is damaged ({self.damaged})"
        if not self.ok:
            return "verify: FAIL"
        if self.truncated and not self.ended:
            return (f"verify: PASS as far as the file goes: the file is cut, the session's end is missing "
                    f"(verified {counted(self.events, 'event')}, {_rounds_words(self.rounds_recorded, self.rounds)}; "
                    f"what came after the cut is lost)")
        if self.truncated:
            return (f"verify: PASS; the file is cut, after its session's end was recorded ("
                    f"{counted(self.events, 'event')} verified; what the cut lost came after it)")
        if self.stopped:
            return f"verify: PASS up to where the session stopped ({self.stopped})"
        return "verify: PASS"

    @property
    def excused(self) -> bool:
        """Whether recomputed events beyond the recording are excused: the session did not run to its end."""
        return self.truncated or bool(self.stopped) or self.lost_part

    @property
    def ok(self) -> bool:
        return not self.error and not self.damaged and all(c.ok(self.excused) for c in self.checks)


def in_source_order(events: list) -> list:
    """The events with each source's own in its sequence order, in the slots that source has in the file.

    A recorder writes what it receives when it receives it, and may hold a source's
    later event before an earlier one (different keys, different links); the
    sources' order among each other is left to the logics (NotYet, node.py)."""
    by_source: dict[str, list] = {}
    for e in events:
        by_source.setdefault(e.source, []).append(e)
    ordered = {s: iter(sorted(es, key=lambda e: e.seq)) for s, es in by_source.items()}
    return [next(ordered[e.source]) for e in events]


def verify_events(events, source: str = "", truncated: bool = False) -> Verification:
    events = in_source_order(list(events))
    started = [e for e in events if isinstance(e, SessionStarted)]
    if not started:
        return Verification(source, [], truncated, "no SessionStarted: nothing to verify")
    config = started[0].config
    ends = [e for e in events if isinstance(e, SessionEnded) and e.source == "game"]
    end = ends[-1] if ends else None
    stopped = None if end is None or end.reason == "completed" else end  # ended by the shell (module rule)
    logics = [GameLogic(config), LearnerLogic()]
    if config.participant.startswith("sim:"):
        logics.append(ParticipantLogic())
    checks = []
    for logic in logics:
        driver = Driver(logic, config.session, clock=lambda: 0)
        recorded = sum(1 for e in events if e.source == logic.name and type(e).__name__ not in SHELL_TAGS)
        owed = driver.resume(events, stopped=stopped if logic.name == "game" else None)
        if truncated:  # the cut may fall between an input and its outputs
            driver.mismatches = [m for m in driver.mismatches if "was not recomputed" not in m]
        checks.append(ServiceCheck(logic.name, recorded, driver.mismatches, len(owed), [said(e) for e in owed[:SHOWN]]))
    how = stopped_how(end, config.rounds, truncated)
    rounds_recorded = sum(1 for e in events if isinstance(e, RoundEnded) and e.source == "game")
    return Verification(source, checks, truncated, stopped=how, reach=reach_of(end, config.rounds, how),
                        events=len(events), rounds=config.rounds, rounds_recorded=rounds_recorded,
                        ended=end is not None)


def _rounds_words(done: int, rounds: int) -> str:
    """`rounds 1-3 of 15 recorded whole` (counted from 1, as the board shows them)."""
    if done == 0:
        return f"no round of {rounds} recorded whole"
    return f"round{'s 1-%d' % done if done > 1 else ' 1'} of {rounds} recorded whole"


def stopped_how(end, rounds: int, truncated: bool) -> str:
    """How a session that did not run to its end stopped, in words ("" if it completed, whole)."""
    if end is None:
        return "cut short before its end was recorded" if truncated else "no SessionEnded recorded"
    if end.reason == "completed":
        return ""
    return f"{end.reason}{f' ({end.detail})' if end.detail else ''}"


def reach_of(end, rounds: int, how: str) -> str:
    """How far a verification went: the whole session, or up to where it stopped."""
    if not how:
        return f"the whole session ({counted(rounds, 'round')})"
    if end is None:
        return f"up to where the recording stops ({how})"
    # counted from 1, as the board shows them (SessionEnded.round counts from 0)
    where = f"in round {end.round + 1} after {counted(end.turns_in_round, 'turn')}" if end.round >= 0 else "before its first round"
    return f"up to where the session stopped: {how} after {end.rounds_played} of {counted(rounds, 'round')}, {where}"


def verify_recording(path) -> Verification:
    """The verification of the recording at `path` (module rule); InputError if it contradicts itself
    about who published what (replay/forgery.py: two events claiming one game seq, a forged start or end),
    or if it would PASS but holds no round recorded whole (replay/check.py `no_whole_round`)."""
    # every event at once, not folded as read: a service's own recorded outputs are held back before its inputs are
    # fed and each source's events re-sorted by seq (node.py `resume`, `in_source_order`); the events alone are kept,
    # not the file's records and each event's bytes (reader.events_of: a 5,000-round file's verify peaked at 1.6 GB)
    # (not MCAP at all: refused, as the verbs do)
    return verify_read(path, *events_of(check_recording(path, function="verify_recording")))


def verify_read(path, log, events: list) -> Verification:
    """`verify_recording` of the recording at `path` read already: its EventLog and its events in file order
    (reader.events_of; check.session_events, which refuses a file holding no session first: `replay --verify`)."""
    forged = contradiction(events)
    if forged:
        raise InputError(f"{forged}: not verified", path)
    # a file completed by `pairplay recover` still lacks the tail its crash lost
    recovered = log.metadata.get("pairplay.recovered", {})
    cut_before = recovered_cut(recovered)  # (a cut after the data section's end lost no message)
    # the first event lost: in a damaged part, or a message that does not decode (reader.EventLog.lost_at)
    first_lost = log.lost_at[0] if log.lost_at else -1
    if first_lost > 0:  # lost in the middle: every event after it follows lost ones and would "differ"
        # (new users' trials: DIFFERS lines, then "verified the whole session"); verified up to it
        result = verify_events(events[:first_lost], str(path), True)
        result.truncated = log.truncated or cut_before
        result.lost_part = True
        result.not_compared = len(events) - first_lost
        result.reach = (f"up to the damaged part: {counted(result.events, 'event')}, "
                        f"{_rounds_words(result.rounds_recorded, result.rounds)}; the {counted(result.not_compared, 'event')} "
                        "after it are not compared (they follow the lost ones)")
    else:
        result = verify_events(events, str(path), log.truncated or cut_before)
    result.unknown = log.unknown_types()
    errors = []
    result.source_cut = log.source_cut if not log.truncated else ""
    if log.loss_free and log.data_intact:  # damaged after the data section (its summary): every event is as recorded
        # and compared whole; said, not failed, in the words every verb says it in (reader.EventLog.loss_free; a new
        # user's trial: verify FAILed the file rebuild, view and counterfactual took as whole)
        result.read_whole = log.loss_free
    elif log.damaged:  # damaged parts and messages that do not decode, in the words every verb uses (reader.EventLog)
        result.damaged = log.damaged
        if first_lost < 0:
            # (a gap in the game's seq in a file whose every part checks out: events missing, not a damaged part)
            why = "events are missing from it" if log.gaps else "no event lost, but the file is damaged"
            result.reach = f"the {counted(result.events, 'event')} the file holds ({why})"
    lost = json_loads(recovered.get("damaged", "[]") or "[]")
    if lost and not recovered_lost(recovered):  # its damaged parts lost no message (an index, a CRC): whole
        result.reach = f"{result.reach} ({said_source_made(recovered)}; no message was lost)"
    elif lost and first_lost > 0:  # compared up to the first lost part, as in the damaged file itself
        # what the source lost, in the reader's words (reader.EventLog.source_lost), as every verb says it
        errors.append(log.source_lost)
        result.reach = (f"up to the first part lost from {said_source(recovered)}: "
                        f"{counted(result.events, 'event')}, {_rounds_words(result.rounds_recorded, result.rounds)}; "
                        f"the {counted(result.not_compared, 'event')} after it are not compared (they follow the lost "
                        "ones)")
    elif lost:
        errors.append(log.source_lost)
        result.reach = (f"the {counted(result.events, 'event')} the file holds, not the whole session: "
                        f"parts of {said_source(recovered)} were lost")
    result.error = "; ".join(errors) or result.error
    empty = no_whole_round(events, log.truncated, log.damaged)
    if empty and result.ok and not result.ended:  # a PASS about nothing whole (a FAIL, a damaged part, says so)
        raise InputError(f"{empty}; nothing to verify{journal_more(path)}", path)
    return result
