"""Feeding a source into the view: every event folded and drawn, every note logged.

Rule: a source yields (event, note) pairs (services/view/sources.py); `drive`
hands events to the view and notes (gaps, rejections) to its event log, until
the source ends or `stop` is set, then closes the view.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from dataclasses import dataclass
from typing import Iterable

from pairplay.services.bus import shutdown_wait
from pairplay.services.view.rerun_logger import RerunView
from pairplay.services.view.sources import Info
from pairplay.numbers import counted


@contextlib.contextmanager
def lowered_priority(steps: int):
    """Run the block with the calling thread `steps` nice levels lower (Linux sets niceness per
    thread), then restore it. The live view's main thread (decode, fold, draw) yields the CPU to the
    session it watches; Zenoh's receive threads keep their priority, so samples still reach the
    ring buffer at once and never push back on the publishers (a starved receiver would: BLOCK)."""
    tid = threading.get_native_id()
    try:
        before = os.getpriority(os.PRIO_PROCESS, tid)
        if steps > 0:
            os.setpriority(os.PRIO_PROCESS, tid, min(19, before + steps))
    except OSError:  # no such control here: the view runs at its priority
        before = None
    try:
        yield
    finally:
        if before is not None and steps > 0:
            with contextlib.suppress(OSError):  # raising it back needs CAP_SYS_NICE: then it stays lower
                os.setpriority(os.PRIO_PROCESS, tid, before)


@dataclass
class ViewSummary:
    events: int = 0
    notes: int = 0
    q_logged: int = 0
    stopped: bool = False  # `stop` was set before the source ended: the view is partial


def drive(view: RerunView, items: Iterable, *, stop: threading.Event | None = None, echo=None) -> ViewSummary:
    """Fold every item of a source into the view; notes go to the event log (and `echo(text, level)`,
    a logging level: INFO for an `Info` note, WARNING for the rest). An idle item `(None, None)` lets
    a coalescing view draw what it holds (RerunView.idle)."""
    summary = ViewSummary()
    for event, note in items:
        if stop is not None and stop.is_set():
            break
        if note is not None:
            level = logging.INFO if isinstance(note, Info) else logging.WARNING
            view.note(note, "INFO" if level == logging.INFO else "WARN")
            summary.notes += 1
            if echo:
                echo(f"view: {note}", level)
        elif event is not None:
            view.handle(event)
            summary.events += 1
        else:
            view.idle()
    summary.stopped = stop is not None and stop.is_set()
    if summary.stopped:  # the file itself says it is not the whole source
        view.note(f"view stopped by {getattr(stop, 'why', '') or 'a stop'} after {counted(summary.events, 'event')}, "
                  "before its source ended: this view is partial")
    view.close(shutdown_wait(stop, 1e9, reserve=0.4))  # stopped: within the shutdown's deadline
    summary.q_logged = view.q_logged
    return summary
