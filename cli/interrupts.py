"""Ctrl-C never lands inside numba's compiler: it waits for the compile in hand (about a second).

Rule: the pairplay command's SIGINT handler raises KeyboardInterrupt at once,
except while the main thread holds numba's compiler lock (compiling a kernel,
or loading one from the cache). Then the interrupt is held: a helper thread
waits for the lock (it is free once the main thread has left the compiler) and
delivers the interrupt to the main thread again (pairplay/signals.py `send_to_main`: the
signal that came, sent to the main thread, so that it also wakes a wait the main thread
has gone on to). A
second Ctrl-C while one is held interrupts at once.

Why: numba compiles through llvmlite, which calls back into Python from C
(`_raw_object_cache_notify`). A KeyboardInterrupt raised in such a callback is
printed as "Exception ignored" and swallowed, so the study went on and exited 0
after the user's Ctrl-C (measured: 1 of 6 runs interrupted 0.2 s into a study
with a cold cache); one raised elsewhere in the compiler leaves llvmlite's
native objects half-built, and freeing them printed AttributeErrors at exit or
aborted the process with "double free detected" (seen in CI). numba is not
imported here (it costs seconds): if it is not loaded, nothing is compiling.
Verbs that stop on signals themselves (services/bus.py `stop_on_signals`)
replace this handler with theirs, which only sets an event.

SIGTERM is handled as SIGINT (the same deferral; KeyboardInterrupt unwinds
the verb, its temporary outputs removed); `received` keeps which signal came,
so the exit status says it (cli/main.py `exit_code_of`: 130 SIGINT, 143
SIGTERM). Before, SIGTERM killed a verb without its own handler outright (no
line, a temporary file left) while one with a handler exited 0.

A signal that comes while the main thread runs a finalizer (`__del__`, a WeakSet's
`_remove`, `weakref.finalize`: pairplay/signals.py `in_finalizer`) is held too, 10 ms at
a time: raised there, Python prints the KeyboardInterrupt as "Exception ignored" and
swallows it (the study went on and exited 0: CI, test_ctrl_c_during_a_study..., the
signal landed in WeakSet._remove).

Once a verb's work is done (its outputs complete; `work_done`, called by a
verb before it prints its result, and by cli/main.py when the verb returns),
a signal stops nothing: it is recorded in `late`, and the command still
exits 128 + its number, saying on one line that the work was done (cli/main.py),
up to the process's last step (cli/main.py `_end`). The same once a verb was
stopped and says so (cli/main.py calls `work_done` as it catches the
KeyboardInterrupt): a signal then raises nothing more, its status is the first's.
Before, one raised in the line's print or in the exit's clean-up escaped as a
KeyboardInterrupt traceback (`python -m pairplay`: exit 1; a new user's trial at
load 35, a copy of a held signal sent again, `send_to_main`, or a second Ctrl-C).
Before, a signal just after `rebuild` wrote its outputs exited 130 with no
line at all (the interpreter's teardown met it), or said "nothing more was
written" for outputs that were all there.
"""

from __future__ import annotations

import signal
import sys
import threading

from pairplay import signals


def _compiler_lock():
    """numba's global compiler lock (an RLock wrapper), or None if numba is not loaded."""
    module = sys.modules.get("numba.core.compiler_lock")
    return getattr(module, "global_compiler_lock", None)


received = 0  # the number of the signal that interrupted the verb (0: none yet)
late = 0  # the number of a signal that came once the verb's work was done (work_done)


def work_done() -> None:
    """The verb's work is complete (module rule): from now on SIGINT/SIGTERM are recorded in `late`
    and raise nothing. Main thread only (elsewhere: nothing to do; signals reach the main thread)."""
    if threading.current_thread() is threading.main_thread():
        signals.handle(_record_late)


def _record_late(signum, frame) -> None:
    global late
    late = late or signum


class DeferredInterrupt:
    """The SIGINT and SIGTERM handler of the module rule; `install()` it in the main thread."""

    def __init__(self):
        self.held = False  # an interrupt waits for the compiler
        self._retrying = False  # a signal held in a finalizer is to come back (_again)

    def install(self) -> None:
        signals.handle(self.handler)  # not over an ignored signal (pairplay/signals.py)

    def handler(self, signum, frame) -> None:
        global received
        # a held interrupt comes back (_deliver_after, a finalizer's retry): the same signal, not a second. Told by
        # how it came (pairplay/signals.py `resent`: delivered by send_to_main), not by a flag set before it was
        # sent (a Ctrl-C from outside between the two was the flag's)
        redelivered = signals.resent()
        if not redelivered:
            received = signum
        if signals.in_finalizer(frame):  # raised here, it would be printed and swallowed (module rule)
            if not self._retrying:
                self._retrying = True
                signals.deliver_again(signum, before=self._again)
            return
        if self.held and not redelivered:  # a second Ctrl-C: the user insists
            raise KeyboardInterrupt
        lock = _compiler_lock()
        if lock is not None and lock.is_locked():  # is_locked: held by this (the main) thread
            if not self.held or redelivered:
                threading.Thread(target=self._deliver_after, args=(lock, signum), name="pairplay-interrupt",
                                 daemon=True).start()
            self.held = True
            return
        self.held = False
        raise KeyboardInterrupt

    def _again(self) -> None:  # a signal held in a finalizer comes back (signals.deliver_again)
        self._retrying = False

    def _deliver_after(self, lock, signum: int) -> None:
        with lock._lock:  # free once the main thread has left numba's compiler
            pass
        signals.send_to_main(signum)  # (woken for until taken: not while holding the compiler's lock)
