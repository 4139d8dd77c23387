"""A recorded participant's turns as the arrays the user fit reads (core/userfit.py Observations).

Rule: one row per TurnResolved of the recording's session, in file order: the
two picks, the first card's partner and the covered cards before the turn
(from the round's deal in RoundStarted and the pairs matched so far), and the
last suggestion made in that turn (SuggestionMade: after a wrong-suggestion
press the participant answered the new one), with the card it was relative
to. A simulated participant's SuggestionPerceived (considered, from memory) is
kept for the fit's counted check; a person's recording has none (-1). What
happened is summarised the same way the simulated arms are (core/counterfactual.py):
picks per complete round, and the share of suggestions after which the second
card matched. Events of another session in the same file are left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pairplay.core.geometry import ALL_CARDS, N_CARDS
from pairplay.core.user import known_partners
from pairplay.core.userfit import Observations
from pairplay.errors import InputError
from pairplay.numbers import counted
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig

from .check import session_events
from .forgery import contradiction
from .onesession import Started, started_by


@dataclass
class RecordedTurns:
    source: str
    config: SessionConfig
    observations: Observations
    picks_per_round: list[int]  # complete rounds only (RoundEnded)
    note: str = ""  # what is wrong with the file, if anything
    skipped: list[str] = field(default_factory=list)  # turns that could not be read, and why
    started: Started = Started(None)  # which session the file holds (onesession.py: each once in a fit)


def _later(e, than) -> bool:
    """Is `e` a later attempt of its turn than `than` (None: nothing yet)?"""
    return than is None or e.attempt >= than.attempt


def turns_from_events(events, source: str = "", note: str = "") -> RecordedTurns:
    """The first session's turns; InputError if there is no session or no resolved turn, or if the events contradict
    themselves about who published what (replay/forgery.py, as rebuild checks it: the first of two different
    events of one seq was taken: trial29 F2)."""
    events = list(events)
    forged = contradiction(events)
    if forged:
        raise InputError(f"{forged}: not fitted", source)
    config: SessionConfig | None = None
    partner, deal_round = None, -1  # the deal read, and its round
    covered = ALL_CARDS
    made: dict[tuple[int, int], ev.SuggestionMade] = {}
    perceived: dict[tuple[int, int], ev.SuggestionPerceived] = {}
    rows: list[tuple] = []
    partners: list[np.ndarray] = []
    picks: list[int] = []
    skipped: list[str] = []
    undealt: dict[int, int] = {}  # round -> its turns resolved with no deal of it read
    events = list(events)
    for e in events:  # the session, and each turn's last suggestion (file order need not be turn order)
        if isinstance(e, ev.SessionStarted) and config is None:
            config = e.config
        elif config is not None and e.session == config.session:
            if isinstance(e, ev.SuggestionMade) and _later(e, made.get((e.round, e.turn))):
                made[(e.round, e.turn)] = e
            elif isinstance(e, ev.SuggestionPerceived) and _later(e, perceived.get((e.round, e.turn))):
                perceived[(e.round, e.turn)] = e
    for e in events:
        if config is None or e.session != config.session:
            continue
        if isinstance(e, ev.RoundStarted):
            partner, deal_round = known_partners(np.asarray(e.faces, dtype=np.int64))[0], e.round
            covered = ALL_CARDS
        elif isinstance(e, ev.RoundEnded):
            picks.append(2 * e.turns)
        elif isinstance(e, ev.TurnResolved):
            if partner is None or e.round != deal_round:  # (its round's deal not read: another round's is no deal
                # of it: an impossible turn under it made the fit's likelihood NaN, a traceback: a cut RoundStarted)
                undealt[e.round] = undealt.get(e.round, 0) + 1  # said once a round (below)
                continue
            if partner[e.first] >= N_CARDS:  # a malformed deal: the first card's face appears once
                skipped.append(f"round {e.round + 1} turn {e.turn + 1}: card {e.first} has no partner in the deal")
                continue
            s = made.get((e.round, e.turn))
            p = perceived.get((e.round, e.turn))
            rows.append((e.round, e.first, e.second, int(partner[e.first]), covered,
                         s.observed if s else -1, s.action if s else -1,
                         (int(p.considered) if p else -1), (int(p.from_memory) if p else -1)))
            partners.append(partner)
            if e.matched:
                covered &= ~((1 << e.first) | (1 << e.second))
    skipped += [f"round {r + 1} ({counted(n, 'turn')}): no RoundStarted before it" for r, n in undealt.items()]
    if config is None:
        raise InputError("no SessionStarted: not a pairplay session recording", source)
    if not rows:  # what left none, if the file is damaged or cut (a new user's trial: the damage unnamed)
        raise InputError(f"holds no resolved turn{f' in its intact parts ({note})' if note else ''}: nothing to "
                         "fit a user to", source)
    cols = np.array(rows, dtype=np.int64).T
    obs = Observations(np.zeros(len(rows), dtype=np.int64), cols[0], cols[1], cols[2], cols[3], cols[4], cols[5],
                       cols[6], np.stack(partners).astype(np.int64), cols[7], cols[8])
    return RecordedTurns(source, config, obs, picks, note, skipped)


def read_turns(path) -> RecordedTurns:
    """A recording's turns (see the module rule); InputError naming the file if it has none to fit."""
    log, events = session_events(path, function="read_turns")  # (the events alone kept: check.session_events)
    note = log.missing  # what its damage, cut and undecodable messages lost (reader.EventLog), as rebuild's
    turns = turns_from_events(events, str(path), note)
    turns.started = started_by(next((e for e in events if type(e).__name__ == "SessionStarted"), None), log)
    return turns
