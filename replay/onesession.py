"""Each session once in a batch of recordings: the check before a verb folds several into one output.

Rule: a session is its game's SessionStarted (its session id, its seq and the time the game stamped it
with): two recordings holding the same one hold the same session, whatever their names, e.g. X.mcap and
the X.recovered.mcap `pairplay recover` writes beside it (a copy of its intact parts), a recorder's
continuation of an earlier file, or a copy under another name. Rebuilt twice, the session gave two
policies of one learning (profile and combine then refused the folder: "the same policy as ..."); fitted
twice (counterfactual --fit-also), its turns counted double. `check_once` refuses such a batch in one line
naming both files, and which one is a recovered copy of which (its RECOVERED record's source). Two runs
that reuse a session id are different sessions: their games started at different times.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, NamedTuple

from pairplay.errors import InputError

from .reader import RECOVERED, EventLog


class Started(NamedTuple):
    """Which session a recording holds (see rule), and what it was recovered from ("" if it is no copy)."""

    key: tuple[str, int, int] | None  # (session id, seq, time_ns) of its SessionStarted; None: it holds none
    recovered_from: str = ""


def started(log: EventLog) -> Started:
    """The session `log` holds (module rule)."""
    first = next((r.event for r in log.events if type(r.event).__name__ == "SessionStarted"), None)
    return started_by(first, log)


def started_by(first, log: EventLog) -> Started:
    """The session `log` holds, given its first SessionStarted (`first`, None if none): for a log whose events were
    folded as they were read, not kept (reader.stream_log)."""
    key = None if first is None else (first.session, first.seq, int(first.time_ns))
    return Started(key, Path(log.metadata.get(RECOVERED, {}).get("source", "")).name)


def check_once(named: Iterable[tuple[str, Started]]) -> None:
    """InputError naming both files if two of the (file, `started`) hold the same session (module rule)."""
    seen: dict[tuple, tuple[str, Started]] = {}
    for name, what in named:
        if what.key is None:
            continue
        first, earlier = seen.setdefault(what.key, (name, what))
        if first is name:
            continue
        copies = [f"{Path(n).name} was recovered from {w.recovered_from}" for n, w in ((first, earlier), (name, what))
                  if w.recovered_from]
        hint = " (the recovered copy holds what recover could save)" if copies else ""
        raise InputError(f"{first} and {name} hold the same session {what.key[0]!r}"
                         f"{''.join(f'; {c}' for c in copies)}: it would count twice; give one of them{hint}", name)
