"""Feeding a source into the view: every event folded and drawn, every note logged.

Rule: a source yields (event, note) pairs (services/view/sources.py); `drive`
hands events to the view and notes (gaps, rejections) to its event log, until
the source ends or `stop` is set, then closes the view.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Iterable

from pairplay.services.bus import shutdown_wait
from pairplay.services.view.rerun_logger import RerunView


@dataclass
class ViewSummary:
    events: int = 0
    notes: int = 0
    q_logged: int = 0


def drive(view: RerunView, items: Iterable, *, stop: threading.Event | None = None, echo=None) -> ViewSummary:
    """Fold every item of a source into the view; notes go to the event log (and `echo`)."""
    summary = ViewSummary()
    for event, note in items:
        if stop is not None and stop.is_set():
            break
        if note is not None:
            view.note(note)
            summary.notes += 1
            if echo:
                echo(f"view: {note}")
        else:
            view.handle(event)
            summary.events += 1
    view.close(shutdown_wait(stop, 1e9, reserve=0.4))  # stopped: within the shutdown's deadline
    summary.q_logged = view.q_logged
    return summary
