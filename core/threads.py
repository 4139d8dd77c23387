"""Independent pieces of one computation on the machine's cores, results as if run in turn.

Rule: `each(work, n)` calls `work(i)` once for every i in range(n), on up to
`WORKERS` threads, pulling the next piece as each
finishes (pieces of unequal cost balance themselves). The pieces must be
independent: each writes only its own rows of shared arrays, so the results are
the same bytes whatever thread ran a piece and in what order; a caller that
gathers per-piece outputs gathers them by index. The work that makes this pay is
the compiled kernels (core/kernels.py, `nogil=True`), which run without the GIL.

The main thread never runs a piece itself: it waits for the pieces' threads,
and that wait is where Python runs its signal handlers. A piece is compiled code
without the GIL that may run for seconds (a batch of games); run on the main
thread it held off Ctrl-C until it returned (`pairplay study` took 2.7-9.9 s to
exit at load ~10). Another thread calling `each` runs pieces too.

A piece's exception is raised in the caller (the first by index) once every
thread has stopped; after an exception, or an interruption of the caller's wait
(KeyboardInterrupt, a signal handler's exception), no new piece starts. The helper threads
are daemons, so an interrupted caller does not wait for them at exit.
PAIRPLAY_THREADS=n caps the threads (e.g. 1 when several studies share the
machine; anything but a positive integer is refused by the command line,
pairplay/environment.py); `pairplay sweep`'s local processes run one thread each.
"""

from __future__ import annotations

import contextlib
import os
import threading
from typing import Callable

from pairplay import environment


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def _workers() -> int:
    """The cores this process may use, or fewer by PAIRPLAY_THREADS (pairplay/environment.py: a value it cannot
    take is refused by the command line before a verb runs)."""
    asked = environment.threads()
    return _cores() if asked is None else min(_cores(), asked)


WORKERS = _workers()
SIGNAL_CHECK_S = 0.1  # the longest a signal waits for its handler while the main thread waits for pieces


@contextlib.contextmanager
def at_most(workers: int):
    """Within the block, `each` uses at most `workers` threads (a one-core measurement: bench/core.py)."""
    global WORKERS
    before = WORKERS
    WORKERS = max(1, min(before, workers))
    try:
        yield
    finally:
        WORKERS = before


def each(work: Callable[[int], object], n: int, workers: int | None = None) -> None:
    """`work(i)` for i in range(n) on up to `workers` (default WORKERS) threads (the caller's among them
    unless it is the main thread, see the module rule); the first piece's exception by index is raised here."""
    workers = max(1, min(n, WORKERS if workers is None else workers))
    on_main = threading.current_thread() is threading.main_thread()
    if workers == 1 and not on_main:
        for i in range(n):
            work(i)
        return
    lock = threading.Lock()
    state = {"next": 0, "stop": False}
    errors: dict[int, BaseException] = {}

    def run() -> None:
        while True:
            with lock:
                i = state["next"]
                if i >= n or errors or state["stop"]:
                    return
                state["next"] = i + 1
            try:
                work(i)
            except BaseException as err:  # handed to the caller below
                with lock:
                    errors[i] = err
                return

    helpers = [threading.Thread(target=run, name="pairplay-piece", daemon=True)
               for _ in range(workers if on_main else workers - 1)]
    try:
        for t in helpers:
            t.start()  # waits for the thread to begin: interruptible too
        if not on_main:
            run()
        for t in helpers:
            while t.is_alive():
                # a signal's handler runs here, on the main thread: acquire is interrupted by a signal, but one
                # that lands just before the wait blocks (seen under load) is only handled when the wait returns
                t.join(SIGNAL_CHECK_S)
    except BaseException:
        with lock:
            state["stop"] = True  # the pieces running finish (compiled code cannot be stopped); no new one starts
        raise
    if errors:
        raise errors[min(errors)]
