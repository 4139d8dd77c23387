"""SIGINT and SIGTERM: a signal ignored stays ignored, and the command's first handler records.

Rule: every SIGINT/SIGTERM handler pairplay installs goes through `handle`,
which installs nothing over a signal that is ignored (SIG_IGN). An ignored
signal is one the process inherited ignored: a POSIX shell starts a
background job (`cmd &` in a script) with SIGINT ignored, and `nohup`-like
launchers do the same; pairplay itself only ignores them in a pool's workers
(pairplay/processes.py) and once a command's status is decided (cli/main.py).
Such a process ignores that signal for its whole life: stop it with the other
one (`kill PID` sends SIGTERM), which ends it with its one line and 143.

Why leave it, when the contract says a process exits on SIGINT: the kernel
discards an ignored signal, so one that came before our first line ran (the
interpreter's own start-up, then the command's) is gone unseen; taking the
signal back later made the same `kill -INT` stop the process or not by the
moment it came (a new user's trial: `pairplay protocol serve F &`, SIGINT 0.05 s
after start, served 618 s until a second SIGINT; one at 0.2 s stopped it). Only
"ignored from the first instant to the last" holds at every moment, and it is
the POSIX rule (the shell's and Python's own: Python installs no
KeyboardInterrupt handler over an inherited SIG_IGN).

`record` is the handler the command installs first of all (cli/start.py),
before it loads anything: it only notes the signal in `received` (the first
one), which cli/main.py reads once its own handler (cli/interrupts.py) is in
place. Not raising there: a KeyboardInterrupt raised inside an import printed
importlib's traceback, and SIGTERM before any handler killed the process
without a line.

A handler that raises KeyboardInterrupt must not raise it inside a finalizer
(`in_finalizer`): a `__del__` or a standard-library weak-reference callback the
garbage collector runs in the main thread, where Python prints the exception as
"Exception ignored" and swallows it (a study went on and exited 0 after a
Ctrl-C: CI, fresh clone of 61bc185). It delivers the signal again a moment
later instead (`deliver_again`); finalizers are short. A signal delivered to the
main thread that way (`send_to_main`) is owed under a token of its own and woken for
by WAKE (SIGUSR2), sent again until the main thread's WAKE handler has taken the token:
one that lands as the main thread enters a blocking call wakes nothing. The WAKE
handler hands each owed signal to the handler in place for it, once (`resent()` is
true during that call); a WAKE with nothing owed does nothing. So a copy is never
taken for a second signal, nor a second signal for a copy: SIGINT and SIGTERM only
ever come from outside. Before, the signal itself was sent again and its copies told
from a second Ctrl-C by time (a copy within 0.25 s of its send was dropped): a main
thread descheduled longer took a copy for a second Ctrl-C, and a user's second Ctrl-C
within that time was dropped. A generator closed by the collector or the callback of a
bare `weakref.ref` is not seen (none runs in our main thread). WAKE's handler is
installed with every handler (`handle`, main thread); `kill -USR2` does nothing else.

A verb that stops on signals itself (services/bus.py `stop_on_signals`) raises
nothing: it notes the signal in `stopping`, which a wait that is not its stop
event's reads to end at once (pairplay/folderlock.py: a study folder's lock
waited for up to 8 s after the signal, then refused as busy, exit 2). A second signal while it stops is
noted in `again` (the line says which) and raises KeyboardInterrupt from its handler, SIGINT and SIGTERM
alike: a second SIGTERM once raised nothing and was heard only in the waits that looked for it (a new user's
trial: two SIGTERMs 0.02-0.3 s apart, never "interrupted again"); a wait on the way out that a second signal
must cut (`wait_cut`) ends on either too, as the user meant (a `protocol serve` waiting for its journal took a
second SIGTERM and waited on).

A step that must be whole once begun (a file renamed into place and said so; a recording finished and its
journal removed: services/recorder.py `Recorder.close`) runs under `held`: SIGINT and SIGTERM wait until
it is over, then meet the handlers they would have met (a second signal then cuts what follows it). The
step is short (a rename, an fsync, an unlink): the signal is late by that much, never lost. In a thread
other than the main one nothing can be held (signals reach the main thread): there the step is counted
(`_elsewhere`), and a verb about to say what a cut left on disk waits for such steps to be over
(`held_elsewhere_over`, cli/session.py `cut_line`): `protocol serve` finishes a game's recording in the
console's thread, and its second signal said "may lack its end" of a file a moment from whole.

Imports nothing but `signal` when loaded (its C part is loaded with the interpreter).
"""

from __future__ import annotations

import signal

# SIGHUP: the terminal closed or the ssh link dropped; before, it killed every verb at once, no line, a live
# session's recording left cut (a hostile user's trial, trial28 F8): the same stop as SIGTERM's, exit 129
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

received = 0  # the first signal `record` met (0: none)
stopping = 0  # the signal a verb's own handler took to stop on (services/bus.py stop_on_signals); 0: none
again = 0  # a second signal that handler took while stopping on the first (module rule); 0: none
WAIT_POLL_S = 0.05  # how often `wait_cut` looks for a second signal
FINALIZER_RETRY_S = 0.01  # a signal held while a finalizer runs is delivered again this much later
RESEND_S = 0.02  # a signal sent to the main thread is sent again this often until its handler took it
HELD_ELSEWHERE_S = 5.0  # how long `held_elsewhere_over` waits for another thread's held step (an fsync, loaded)
_elsewhere: list = []  # the held steps running in threads other than the main one (module rule)
RESEND_FOR_S = 5.0  # and for at most this long
WAKE = signal.SIGUSR2  # what `send_to_main` sends: the main thread's cue to take what is owed (module rule)
_owed: dict[object, int] = {}  # token -> signal: what `send_to_main` delivers whose handler has not run yet
_delivering = 0  # > 0 while `_wake` runs a handler for an owed signal (`resent`)
_WEAKREF_FILES = ("weakref.py", "_weakrefset.py")  # the standard library's weak-reference callbacks live here


def said(why: object) -> str:
    """What a verb's line on stderr calls the signal `why` (its number, or its name as `stop.why` holds it):
    "Ctrl-C" for SIGINT, its name for another (SIGTERM), anything else as it is. One rule for every verb's
    `interrupted (...)` and `stopped (...)` line: the verbs without a bus said "(Ctrl-C)", those with one
    "(SIGINT)", their stop's name (a new user's trial). What a recording keeps (SessionEnded's reason) is its
    name, data, not a line: unchanged."""
    if isinstance(why, int) and not isinstance(why, bool):
        why = signal.Signals(why).name if why in set(signal.Signals) else str(why)
    return "Ctrl-C" if why == "SIGINT" else str(why)


def handle(handler: object, signals: tuple[int, ...] = SIGNALS) -> None:
    """Install `handler` for each of `signals` not ignored (module rule), and WAKE's (`send_to_main`) if it is
    not in place yet. Main thread only."""
    for signum in signals:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, handler)
    if signal.getsignal(WAKE) is not _wake:
        signal.signal(WAKE, _wake)


def ignored(signum: int) -> bool:
    """Whether `signum` is ignored in this process (module rule: it stays so)."""
    return signal.getsignal(signum) is signal.SIG_IGN


def record(signum: int, frame: object) -> None:
    """The command's first handler (module rule): notes the first signal, raises nothing."""
    global received
    received = received or signum


def take() -> int:
    """The signal `record` noted (0: none), forgotten once taken."""
    global received
    signum, received = received, 0
    return signum


def in_finalizer(frame) -> bool:
    """Whether `frame` (a handler's) runs inside a finalizer (module rule): a `__del__`, or a standard-library
    weak-reference callback, anywhere in its chain (an exception raised below one ends there)."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or code.co_filename.endswith(_WEAKREF_FILES):
            return True
        frame = frame.f_back
    return False


def send_to_main(signum: int) -> None:
    """`signum` to the main thread's handler for it, woken by a real signal: it wakes a sleep or a wait the main
    thread is blocked in (`_thread.interrupt_main` only sets the flag, and the interrupt waited for the wait's
    end: a study held in numba's compiler then interrupted only when its next 5-second wait ended). Called from a
    helper thread.

    Owed under a token of its own, and WAKE sent every RESEND_S until the main thread's WAKE handler has taken
    the token (`_wake`), for at most RESEND_FOR_S (module rule): a signal that lands as the main thread is
    entering a blocking call (the GIL handed to this thread as that one lets it go for the call) runs nothing and
    wakes nothing, and the call slept on (1 of ~240 runs of test_a_ctrl_c_inside_a_finalizer_is_not_swallowed at
    load 4-8; a 120-s sleep). Nothing once no Python handler takes `signum` (a default SIGTERM would kill the
    process); without WAKE's handler (none was installed through `handle`) `signum` itself is sent, once."""
    import threading
    import time
    main = threading.main_thread().ident
    token = object()
    _owed[token] = signum
    end = time.monotonic() + RESEND_FOR_S
    while token in _owed:
        if not callable(signal.getsignal(signum)):
            _owed.pop(token, None)
            return
        if signal.getsignal(WAKE) is not _wake:
            _owed.pop(token, None)
            signal.pthread_kill(main, signum)
            return
        signal.pthread_kill(main, WAKE)
        time.sleep(RESEND_S)
        if time.monotonic() >= end:  # still owed: the next WAKE (another's) delivers it; never lost
            return


def _wake(_signum: int, frame) -> None:
    """WAKE's handler (main thread): each signal owed (`send_to_main`) to the handler in place for it now, once,
    in the order they were sent (module rule). One that raises leaves the rest owed: their WAKE comes again."""
    global _delivering
    for token in list(_owed):
        signum = _owed.pop(token, None)
        if signum is None:
            continue
        handler = signal.getsignal(signum)
        if not callable(handler):  # (as a real signal would meet no Python handler: nothing to deliver it to)
            continue
        _delivering += 1
        try:
            handler(signum, frame)
        finally:
            _delivering -= 1


def resent() -> bool:
    """Whether the handler running now runs for a signal `send_to_main` delivered (one taken before and held:
    cli/interrupts.py), not for one that came from outside (module rule)."""
    return _delivering > 0


def wait_cut(waited, timeout_s: float | None = None) -> bool:
    """A wait on the way out of a verb stopping on a signal: an Event's (whether it was set) or a thread's end
    (whether it ended), for at most `timeout_s` (None: no limit); in the main thread a second signal (`again`,
    SIGINT or SIGTERM alike) cuts it with KeyboardInterrupt (module rule). Elsewhere it only waits: a signal
    is the main thread's to act on."""
    import threading
    import time
    if isinstance(waited, threading.Thread):
        def wait(s: float) -> bool:
            waited.join(s)
            return not waited.is_alive()
    else:
        wait = waited.wait
    main = threading.current_thread() is threading.main_thread()
    end = None if timeout_s is None else time.monotonic() + timeout_s
    while not wait(WAIT_POLL_S if end is None else max(0.0, min(WAIT_POLL_S, end - time.monotonic()))):
        if again and main:
            raise KeyboardInterrupt
        if end is not None and time.monotonic() >= end:
            return False
    return True


def deliver_again(signum: int, before=None, delay_s: float = FINALIZER_RETRY_S) -> None:
    """`signum` comes to the main thread's handler again `delay_s` seconds from now (`send_to_main`);
    `before()` runs first, in the helper thread (it must only set flags)."""
    import threading
    import time

    def again():
        time.sleep(delay_s)
        if before is not None:
            before()
        send_to_main(signum)
    threading.Thread(target=again, name="pairplay-interrupt", daemon=True).start()


def held():
    """A context manager: SIGINT and SIGTERM wait until its block is over, then are delivered to the handlers
    they would have met (module rule). Main thread only: Python runs signal handlers there; elsewhere nothing
    is held. An ignored signal stays ignored (`handle`)."""
    import contextlib
    import threading

    @contextlib.contextmanager
    def hold():
        if threading.current_thread() is not threading.main_thread():
            token = object()
            _elsewhere.append(token)  # (list.append and remove are atomic: no lock, nothing else to import)
            try:
                yield
            finally:
                _elsewhere.remove(token)
            return
        came: list[int] = []
        before = {s: signal.getsignal(s) for s in SIGNALS}
        handle(lambda signum, _frame: came.append(signum))
        try:
            yield
        finally:
            for s, handler in before.items():
                signal.signal(s, handler)
            for signum in came:  # each in order: a first one stops, a second cuts (services/bus.py stop_on_signals)
                signal.raise_signal(signum)
    return hold()


def held_elsewhere_over(timeout_s: float = HELD_ELSEWHERE_S) -> bool:
    """Wait until no other thread is in a `held` step (module rule), at most `timeout_s`; whether none is. The
    steps are milliseconds: what a signal in the main thread's own step would wait for too."""
    import time

    end = time.monotonic() + timeout_s
    while _elsewhere:
        if time.monotonic() >= end:
            return False
        time.sleep(0.005)
    return True
