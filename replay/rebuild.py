"""Rebuild: recordings folded into policy files and learning curves.

Rule: a recording's policy is the fold of its QUpdated events (fold.py: the
learner's own update, bit for bit; an LSPI session's, of its LSPIUpdated samples) and its greedy actions use the study's
seeded tie-break (core.learning.greedy_policy seeded by the session's stream
seed, as core.study does), so a rebuilt policy file equals the one the
in-process study writes for the same seed and persona. Learning curves are per
round: turns (9 is perfect play), picks, total reward, learned updates and
inconsistent suggestions, and whether the file's damage took events of that round
(`damaged`: reader.EventLog.lost_at, `damaged_rounds`). A truncated recording rebuilds what it holds and
says so; a recording without SessionStarted is refused with the reason, and
so is one whose session has no round recorded whole (`NoWholeRound`: check.py
`no_whole_round`; it gave a policy of 0 rounds). A
policy from a partial session (interrupted, aborted, failed, cut short,
damaged or completed by `pairplay recover` of a file that lost events; a
damage that lost none, or a cut after the data section, recovered or not, leaves it whole) says why in its file's `partial`
field and in `Rebuilt.partial`; one whose file lost events in its middle (a
damaged part; a recover of such a file; a hole in the game's or the learner's
seq: `POLICY_SOURCES`) says what in `Rebuilt.lost`: its
policy lacks updates the learner made, so it is no state the learner was ever
in (`pairplay rebuild` writes it only with --partial). A hole in another
source's seq (the participant's, the robot's) is said in `damage_read`: the
policy is made of none of their events, so it is whole. The events are folded as they are read
(reader.stream_log), none kept; a file that lost some is read whole first, the same policy either way.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pairplay import __version__
from pairplay.errors import InputError
from pairplay.outputs import output_file
from pairplay.core.learning import greedy_policy
from pairplay.core.personas import persona
from pairplay.core.policies import to_policy_file
from pairplay.schemas.policy import PolicyFile, write_policy
from pairplay.schemas.session import SessionConfig
from pairplay.schemas.trust import PUBLISHERS, STARTERS

from .check import RoundWatch, check_recording, no_whole_round, read_session
from .fold import READS, SessionFold, fold_any, stream_seed
from .reader import (EventLog, NotStreamed, RecordedEvent, journal_restored, recovered_cut, recovered_lost,
                     said_source_cut, stream_log)
from .recover import journal_more
from .forgery import ONE_PUBLISHER, Contradictions
from .onesession import Started, started_by
from pairplay.numbers import counted


class RebuildError(InputError):
    """A recording that cannot be rebuilt; the message says why."""


class NoWholeRound(RebuildError):
    """A session recording with no round recorded whole: nothing to rebuild (check.py `no_whole_round`)."""


@dataclass
class Rebuilt:
    source: str
    config: SessionConfig
    fold: SessionFold
    policy: PolicyFile
    truncated: bool
    note: str = ""
    partial: str = ""  # why the session is not complete ("" if it is)
    lost: str = ""  # what the file lost in its middle, short: a damaged part, or parts lost before a recover
    damage_read: str = ""  # a damage that lost no event (the policy is whole): said, not a partial session
    damaged_rounds: frozenset[int] = frozenset()  # the rounds whose events the file's damage took some of
    started: Started = Started(None)  # which session the file holds (onesession.py: each once in a batch)


def partial_reason(fold: SessionFold, note: str = "", recovered: dict[str, str] | None = None) -> str:
    """Why a session's recording does not hold a completed session ("" if it does)."""
    why = []
    e = fold.ended
    if e is None:
        n = len(fold.whole_rounds())
        why.append(f"no SessionEnded: the recording stops after {n} round{'s' * (n != 1)}")
    elif e.reason != "completed":
        where = f" in round {e.round + 1} after {counted(e.turns_in_round, 'turn')}" if e.round >= 0 else ""  # from 1, as the board
        why.append(f"{e.reason}{f' ({e.detail})' if e.detail else ''} after {e.rounds_played} of "
                   f"{counted(fold.config.rounds, 'round')}{where}")
    if note:
        why.append(note)
    if recovered:  # a damage that lost no message (an index, a summary), or a cut after the data section, left
        # the session whole: recovering it does not make it partial (a new user's trial: it did)
        lost, cut = recovered_lost(recovered), recovered_cut(recovered)
        damaged = recovered.get("damaged", "[]") not in ("", "[]")
        # events its journal added are a partial session's unless they are its whole rest (reader.journal_restored)
        added = recovered.get("from_journal", "0") not in ("", "0") and not journal_restored(recovered)
        # (a whole file recovered to drop identical copies of events, replay/recover.py, lost none either)
        copies = recovered.get("copies_dropped", "0") not in ("", "0")
        if lost or cut or added or not (damaged or copies or recovered.get("truncated") == "true"):
            # a cut source in the words every verb says it in (reader.said_source_cut)
            why.append("completed by pairplay recover" + (" from a damaged file" if lost else
                                                           f": {said_source_cut(recovered)}" if cut else ""))
    return "; ".join(why)


def rebuild_events(events, source: str = "", truncated: bool = False, note: str = "",
                   recovered: dict[str, str] | None = None, ended: dict[str, str] | None = None,
                   skipped: dict[str, int] | None = None) -> Rebuilt:
    """`events` folded and the learner's policy rebuilt; RebuildError without a SessionStarted.
    `ended` is the recorder's "pairplay.recorder.end" metadata, if the file has it; `skipped`, by
    tag, the events read_log did not decode because the fold only counts them."""
    return rebuild_fold(fold_any(events), source, truncated, note, recovered, ended, skipped)


def rebuild_fold(fold: SessionFold, source: str = "", truncated: bool = False, note: str = "",
                 recovered: dict[str, str] | None = None, ended: dict[str, str] | None = None,
                 skipped: dict[str, int] | None = None) -> Rebuilt:
    """`rebuild_events` of the events `fold` folded (fold.py), as they were read."""
    fold = fold.count(skipped or {})
    if fold.config is None:
        if ended and ended.get("stopped_by"):
            raise RebuildError(f"{source or 'events'}: no SessionStarted: the recording was stopped "
                               f"({ended['stopped_by']}) before its game started")
        raise RebuildError(f"{source or 'events'}: no SessionStarted: not a pairplay session recording")
    c = fold.config
    partial = partial_reason(fold, note, recovered)
    q = fold.q
    greedy = greedy_policy(q, np.random.default_rng(stream_seed(c)))
    who = None
    if c.participant.startswith("sim:"):
        try:
            who = persona(c.persona)
        except KeyError:
            who = None
    policy = to_policy_file(q, np.array(fold.visits), greedy, algorithm=c.algorithm,
                            participant=c.persona or c.participant, persona=who, seed=c.seed, game=c.game_index,
                            rounds=len(fold.whole_rounds()), config=c.learner_config(), software=__version__,
                            reward_bonus=c.reward_bonus, partial=partial,
                            lspi=c.lspi_config() if fold.lspi is not None else None)
    return Rebuilt(source, c, fold, policy, truncated, note, partial)


def rebuild_recording(path: str | Path) -> Rebuilt:
    """The recording at `path` rebuilt; InputError (RebuildError) if it is not a session recording, or if
    it contradicts itself about who published what (replay/forgery.py: a forged start or end), NoWholeRound
    if its session has no round recorded whole."""
    # its events folded as they are read (reader.stream_log), none kept; a file that lost some (a part, a message
    # that does not decode) is read whole, as before: where they were lost is known at its end (`damaged_rounds`)
    try:
        log, seen = _streamed(path)
    except NotStreamed:
        # the events the fold only counts are not decoded (speed), but rounds' starts are: damaged_rounds needs them
        log = read_session(path, only=CURVE_READS, function="rebuild_recording")
        seen = _Seen(ONE_PUBLISHER if log.differing else STARTERS)  # (speed: forgery.py)
        seen(log.events)
    # who published what, first (a forged end before any round is named as that, not as "no whole round"):
    # among the decoded events (every one a fold reads: the game's start, rounds' ends, refusals and end
    # among them); `replay --verify` checks every event (replay/forgery.py)
    forged = seen.forged.found
    if forged:
        raise RebuildError(f"{forged}: not rebuilt", path)
    empty = no_whole_round(seen.said, log.truncated, log.damaged)
    if empty:
        raise NoWholeRound(f"{empty}; nothing to rebuild{journal_more(path)}", path)
    # a damaged part that lost no event (a summary's CRC, an index) leaves the session whole: its policy is the
    # learner's, not partial (a new user's trial: flagged PARTIAL without --partial); said in `damage_read`
    # a cut after the data section's end (in the summary) lost none either
    loss_free = (bool(log.damage) or log.truncated) and log.lost_from < 0 and not log.cut_lost
    note = "" if log.whole or loss_free else f"{'damaged' if log.damage else 'truncated'}: {log.brief}"
    # messages in the file that do not decode are events the fold cannot take (a Q update among them: a Q-table
    # the learner never had); the reader keeps them in `bad` (a new user's trial: rebuilt with exit 0, no word)
    bad = log.undecoded
    # events missing from a source the policy is made of (a hole in the learner's or the game's seq: an update, a
    # round's end): a policy the learner never had, flagged as a damaged file's (a game's hole refused without
    # --partial, but its policy written with it was not flagged); a hole in another source's (the participant's,
    # the robot's) changes no policy: said (`damage_read`), the policy whole (trial29 F10: both passed silently)
    gaps, aside = log.gaps_of(POLICY_SOURCES), log.gaps_of(but=POLICY_SOURCES)
    note = "; ".join(n for n in (note, bad, gaps) if n)
    recovered = log.metadata.get("pairplay.recovered") or {}
    rebuilt = rebuild_fold(seen.fold, str(path), log.truncated, note, recovered,
                           log.metadata.get("pairplay.recorder.end"), skipped=log.skipped)
    # said as every verb says it (reader.EventLog.loss_free), and so are identical copies of events read once and
    # schemas that are not pairplay's (`said_too`) in a file that lost some too
    rebuilt.damage_read = "; ".join(n for n in (log.loss_free or log.said_too,
                                                f"{aside} (the policy does not depend on them)" if aside else "") if n)
    # (a file streamed lost no event: `lost_at` is empty, its events not kept)
    rebuilt.damaged_rounds = damaged_rounds([r.event for r in log.events], log.lost_at)
    rebuilt.started = started_by(seen.first, log)
    lost = log.lost_of(POLICY_SOURCES)
    if lost:  # the file's own damage, or its source's if it was recovered (reader.EventLog.source_lost)
        rebuilt.lost = f"the file is damaged ({lost})" if log.damaged else lost
    return rebuilt


def _streamed(path: str | Path) -> tuple[EventLog, "_Seen"]:
    """The recording at `path` read and folded as it is read (reader.stream_log); NotStreamed for a file that lost
    events, holds a seq twice (a differing event among them: every one-publisher source's seqs are judged then,
    forgery.py) or holds no session (said in read_session's words), which is read whole."""
    path = check_recording(path, function="rebuild_recording")
    seen = _Seen(STARTERS)  # (a stream has no differing events: stream_log reads none)
    log = stream_log(path, CURVE_READS, seen)
    if seen.first is None:
        raise NotStreamed(path)
    return log, seen


class _Seen(RoundWatch):
    """What rebuild makes of a recording's events, given a chunk's at a time as they are read (reader.stream_log) or
    all at once: their fold (fold.py), the first contradiction among them (forgery.py `Contradictions`), and what
    `no_whole_round` looks at (check.py `RoundWatch`: the first SessionStarted, onesession.py, among it)."""

    def __init__(self, one_publisher: frozenset[str]) -> None:
        super().__init__()
        self.fold = SessionFold()
        self.forged = Contradictions(one_publisher)

    def __call__(self, recorded: list[RecordedEvent]) -> None:
        events = [r.event for r in recorded]
        self.fold.fold(events)
        self.forged.take(events)
        self.take(events)


# the events a policy file is made of (fold.py: the config, the Q updates, the rounds recorded whole, the end that
# says whether the session completed), and the sources that publish them (the game, the learner): a hole in
# their seqs is a policy the learner never had (reader.EventLog.gaps_of)
POLICY_TAGS = ("SessionStarted", "QUpdated", "LSPIUpdated", "RoundEnded", "SessionEnded")
POLICY_SOURCES = frozenset().union(*(PUBLISHERS[tag] for tag in POLICY_TAGS))


CURVE_READS = READS | {"RoundStarted"}  # what rebuild decodes: the fold's events, and where rounds start


def damaged_rounds(events: list, lost_at: list[int]) -> frozenset[int]:
    """The rounds a loss in the file hit, at each place events were lost (reader.EventLog.lost_at: a damaged
    part, a message that does not decode): a round with events read on both sides of it (the loss lies inside
    it); the round of the nearest event read before it if that round's RoundEnded was not read (the loss took
    its end); the round of the nearest event read after it if its RoundStarted was not read (the loss took its
    start). A round whose end and start were both read is not hit by a loss between them (a new user's trial:
    round 0's lost RoundEnded flagged the next, intact round and dropped round 0's row). A round lost whole
    has no event read, so it is no round of the curve. `events` must hold the RoundStarted and RoundEnded
    read (`CURVE_READS`)."""
    first: dict[int, int] = {}
    last: dict[int, int] = {}
    ended, started = set(), set()
    rounds = []  # each event's round, -1 for none
    for i, e in enumerate(events):
        r = getattr(e, "round", -1)
        rounds.append(r)
        if r < 0:
            continue
        first.setdefault(r, i)
        last[r] = i
        name = type(e).__name__
        if name == "RoundEnded":
            ended.add(r)
        elif name == "RoundStarted":
            started.add(r)
    # the round of the nearest event read before / from each place (one pass each: a file with thousands of
    # messages that do not decode has as many places, and a scan per place was quadratic)
    before_at, r_before = [None] * (len(rounds) + 1), None
    for i, r in enumerate(rounds):
        before_at[i] = r_before
        r_before = r if r >= 0 else r_before
    before_at[len(rounds)] = r_before
    after_at, r_after = [None] * (len(rounds) + 1), None
    for i in range(len(rounds) - 1, -1, -1):
        r_after = rounds[i] if rounds[i] >= 0 else r_after
        after_at[i] = r_after
    hit = set()
    for at in lost_at:
        hit.update(r for r in first if first[r] < at <= last[r])
        before, after = before_at[at], after_at[at]
        if before is not None and before not in ended:
            hit.add(before)
        if after is not None and after not in started:
            hit.add(after)
    return frozenset(hit)


# `damaged`: 1 for a round the file's damage took events of (Rebuilt.damaged_rounds): its counts may be partial.
# `turns`, `picks` and `matches` come only from the round's RoundEnded: a damaged round whose RoundEnded was lost
# keeps its row (what was read of it: `reward`, `learned`, `inconsistent`, partial) with those three empty, not 0
# (0 picks would read as better than a perfect round's 18)
CURVE_COLUMNS = ("round", "turns", "picks", "matches", "reward", "learned", "inconsistent", "damaged")


def curve_rows(fold: SessionFold, damaged: frozenset[int] = frozenset()) -> list[dict]:
    """One row per round recorded whole, and per damaged round (CURVE_COLUMNS); a round a session stopped in,
    or a file was cut in, has none (fold.py)."""
    return [{"round": r, "turns": s.turns if s.ended else "", "picks": 2 * s.turns if s.ended else "",
             "matches": s.matches if s.ended else "", "reward": s.reward, "learned": s.learned,
             "inconsistent": s.inconsistent, "damaged": int(r in damaged)}
            for r, s in sorted(fold.rounds.items()) if s.ended or r in damaged]


def output_stem(source: str | Path) -> str:
    """The name a recording's outputs share: its file name without `.mcap`, so the
    outputs of different files never collide (X.mcap -> X, X.recovered.mcap -> X.recovered)."""
    name = Path(source).name
    return name[: -len(".mcap")] if name.endswith(".mcap") else name


def output_paths(rebuilt: Rebuilt, out_dir: str | Path) -> list[Path]:
    """Where write_outputs puts a recording's policy file and learning curve."""
    stem = output_stem(rebuilt.source) if rebuilt.source else rebuilt.config.session
    return [Path(out_dir) / f"{stem}.policy.json", Path(out_dir) / f"{stem}.curve.csv"]


def write_outputs(rebuilt: Rebuilt, out_dir: str | Path, force: bool = False) -> list[Path]:
    """<stem>.policy.json and <stem>.curve.csv in `out_dir` (output_paths), each written
    whole or not at all; an existing one is replaced only with `force` (OutputError)."""
    policy_path, curve_path = output_paths(rebuilt, out_dir)
    write_policy(policy_path, rebuilt.policy, force)
    with output_file(curve_path, "w", force, newline="") as f:
        w = csv.DictWriter(f, fieldnames=CURVE_COLUMNS)
        w.writeheader()
        w.writerows(curve_rows(rebuilt.fold, rebuilt.damaged_rounds))
    return [policy_path, curve_path]
