"""A thread that dies as it starts is refused at its start, never waited for.

Rule: `threading.Thread.start` waits until the new thread says it runs (`_started`). A thread the OS
did start but whose first step failed never says so, and its starter waited for ever: under `ulimit -v`
the new thread's first frame or first lock could not be allocated (MemoryError; Python reports it as
"Exception ignored in thread started by: ..." and the thread ends), and `pairplay session` under
`ulimit -v 1700000` hung in a `start()` until killed (test_cli_out_of_threads, 1 run in ~5 at that limit
under load). `guard()` (the command's entry, cli/main.py) makes every `Thread.start` in the process, ours
and zenoh-python's, wait for the new thread to run or to fail: a failure before it ran is the starter's
RuntimeError("can't start new thread"), the error of a start the OS refused, which every caller already
takes as running out of threads (pairplay/errors.py `out_of_threads`: one line, exit 2). The thread is
then as one that never started (`_started` unset: `join` refuses it, `is_alive` is False). Python's
report of such a death ("Exception ignored in thread started by: ...") is taken, not printed: the
starter's one line says it; any other unraisable report is printed as before, at the next thread start
or at the exit (`guard` says why it waits).
"""

from __future__ import annotations

import atexit
import collections
import sys
import threading
import time

REFUSED = "can't start new thread"  # the words of the OS's refusal (errors.out_of_threads)
GRACE_S = 10.0  # a new thread not running Python by then, and gone from the interpreter, died as it started: the
# last resort (its death is reported through the unraisable hook first), long enough for a loaded machine to
# schedule a new thread (one not yet scheduled is not in the interpreter under its own id either)
_pending: dict = {}  # a bootstrap not yet running -> its start's state (`guard`)


class _Start:
    """One thread's start: whether its bootstrap runs, failed before its thread ran, or was refused."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.running = self.failed = self.refused = False


def guard() -> None:
    """Install the rule in this process (once; the command's entry)."""
    if getattr(threading._start_new_thread, "_pairplay_guard", False):
        return
    real = threading._start_new_thread
    previous_hook = sys.unraisablehook

    def start(function, args, kwargs=None):
        unraisable()
        thread = getattr(function, "__self__", None)
        if not isinstance(thread, threading.Thread) or getattr(function, "__name__", "") != "_bootstrap":
            return real(function, args) if kwargs is None else real(function, args, kwargs)
        state = _Start()

        def bootstrap():
            with state.lock:
                _pending.pop(bootstrap, None)
                if state.refused:  # its starter gave up on it (below): it never runs
                    return
                state.running = True
            try:
                function()
            except BaseException:
                if thread._started.is_set():
                    raise
                state.failed = True  # died before it ran (MemoryError): its starter says so

        _pending[bootstrap] = state
        try:
            ident = real(bootstrap, ())
        except BaseException:
            _pending.pop(bootstrap, None)
            raise
        # Thread.start waits for `_started` next: wait here for it or for the thread's death, a slice at a
        # time (at once when the thread runs, as it does but for the failure)
        began = time.monotonic()
        while not thread._started.wait(0.05):
            unraisable()
            if not state.failed and time.monotonic() - began >= GRACE_S and ident not in sys._current_exceptions():
                with state.lock:  # not running Python, and its thread state gone (or never there)
                    state.refused = not state.running
            if state.failed or state.refused:
                _pending.pop(bootstrap, None)
                thread._is_stopped = True  # as a thread that never started: not alive, nothing to join
                raise RuntimeError(f"{REFUSED} (it died as it started: the process's memory limit)")
        return ident

    def unraisable() -> None:
        """Take what Python reported unraisable: a bootstrap that could not run marks its start failed (its
        starter says it, in one line); anything else goes to Python's own hook as before, late by at most
        until the next thread start or the exit (cli/main.py runs the exit functions)."""
        while reported:
            hook_args = reported.popleft()
            state = _pending.get(hook_args.object)
            if state is not None:
                state.failed = True
            else:
                previous_hook(hook_args)

    # Python calls its unraisable hook in the thread that could not run: when that thread's first frame could
    # not be allocated, no Python function can run there either (a hook of ours was itself "Exception ignored
    # in sys.unraisablehook: ... MemoryError", two more lines on stderr). deque.append is C: it only keeps the
    # report, for `unraisable` to read in a thread that can.
    reported: collections.deque = collections.deque()
    start._pairplay_guard = True
    threading._start_new_thread = start
    sys.unraisablehook = reported.append
    atexit.register(unraisable)
