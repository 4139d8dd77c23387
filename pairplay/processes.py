"""Child processes that never outlive an interruption: the parent owns Ctrl-C; work that
must not be interrupted half-way runs off the main thread.

Rule: a pool's workers ignore SIGINT and SIGHUP. A terminal's Ctrl-C (or hang-up) reaches the whole
foreground process group; if each worker also raised KeyboardInterrupt, every
one would print its own traceback and the user would see a screenful instead
of the verb's one line. The parent alone is interrupted, and on the way out
(`worker_pool`'s exit with an exception) it cancels what has not started and
terminates what is running instead of waiting for it, so the verb exits
promptly. Workers are started with "spawn": a forked child would inherit the
parent's threads' locks (zenoh, numba's compiler) in whatever state they were.
A worker is started with SIGINT blocked (the mask survives fork and exec), as
CPython's own resource tracker is (multiprocessing/resource_tracker.py,
ensure_running): a Ctrl-C that reaches the group while the worker still
imports waits, and its initializer's SIG_IGN discards it (without this, a
worker interrupted before its initializer printed a traceback). The parent's
own Ctrl-C is held the same short while and raised once the pool has recorded
the new worker, so `stop_pool` can stop it.

A worker also never outlives its parent (`_watch_parent`): a parent killed by SIGKILL or
the OOM killer runs no code of ours, and its idle worker waited for ever on its call queue
(it holds that pipe's write end itself, so it never reads EOF), re-parented to init with
the resource tracker it keeps alive. Each worker's thread compares its parent's pid with the
pid that started it every `PARENT_POLL_S` and ends the worker at once (os._exit) when they
differ. Not prctl(PR_SET_PDEATHSIG): Linux sends that when the *thread* that forked the
child ends, and a pool's workers are started by whichever thread submits (off_main_thread's
among them), which may end long before the process.

A worker that dies while the pool holds work (SIGKILL from the system's out-of-memory killer, a crash)
breaks the pool: every waiting future, and every later `submit`, raises BrokenProcessPool, whose text
names no process and no cause (a trial: its traceback, exit 1). `result_of` and the pool's `submit`
turn it into `pairplay.errors.WorkerLost` naming the worker that died and how (`died_how`: the signal
or exit status, from the pool's record of every process it started), which the command line says in
one line, exit 1.

`off_main_thread` runs a call that Python cannot safely interrupt (numba's
compiler: see cli/interrupts.py) in a thread while the main thread waits for
it. Ctrl-C interrupts the wait at once; the call is abandoned, still running,
and dies with the process (the command ends with os._exit after an
interruption, cli/main.py `entry`).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Iterator, TypeVar

from pairplay.errors import WorkerLost

T = TypeVar("T")


def off_main_thread(fn: Callable[..., T], *args) -> T:
    """`fn(*args)` in a daemon thread, the caller waiting: its result, or its exception raised here."""
    done: Future = Future()

    def work():
        try:
            done.set_result(fn(*args))
        except BaseException as err:  # handed to the waiting caller
            done.set_exception(err)

    threading.Thread(target=work, name=f"pairplay-{getattr(fn, '__name__', 'work')}", daemon=True).start()
    return done.result()


# what the terminal sends to every process of its foreground group, the workers too: the parent alone stops on it and
# ends them (a Ctrl-C, and a hang-up: the terminal closed)
GROUP_SIGNALS = {signal.SIGINT, signal.SIGHUP}
PARENT_POLL_S = 0.25  # a worker whose parent died ends within this (and its own scheduling)


def _watch_parent(parent: int) -> None:
    """End this worker as soon as its parent `parent` is gone (re-parented: our parent pid changed)."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)  # nothing of the parent's is left to hand a result to; no teardown to wait on


def _worker_start(parent: int) -> None:
    """A pool worker's initializer: SIGINT and SIGHUP ignored (module rule), and the parent watched."""
    for signum in GROUP_SIGNALS:  # a Ctrl-C (or a hang-up) that came while starting up is discarded with it
        signal.signal(signum, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, GROUP_SIGNALS)
    if os.getppid() != parent:  # it died while we started
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), name="pairplay-parent-watch", daemon=True).start()


class _ParentInterruptedPool(ProcessPoolExecutor):
    """Workers are started (lazily, by `submit`) with SIGINT blocked: a child inherits its parent
    thread's signal mask, so a Ctrl-C while the child's Python is still starting, before its
    initializer could ignore SIGINT, waits blocked and is discarded by `_worker_start`
    instead of printing a traceback from the child's start-up."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # every worker it started, by pid: the pool forgets a dead one, and `died_how` must find it after
        self.started: dict[int, multiprocessing.process.BaseProcess] = {}

    def _spawn_process(self):
        super()._spawn_process()
        self.started.update(self._processes)

    def submit(self, fn, /, *args, **kwargs):
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, GROUP_SIGNALS)
        try:
            return super().submit(fn, *args, **kwargs)
        except BrokenProcessPool:  # a worker died before: said as the waiting futures say it (`result_of`)
            raise worker_lost(self) from None
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)  # a Ctrl-C that came meanwhile is raised now


def died_how(pool: ProcessPoolExecutor) -> str:
    """How the pool's worker that broke it ended: "killed by signal 9 (SIGKILL: ...)", "exit status 3".
    The one that died first is not known; a signal other than SIGTERM is preferred, as the pool ends the
    others with SIGTERM once one died."""
    manager = getattr(pool, "_executor_manager_thread", None)
    if manager is not None and manager is not threading.current_thread():
        # it marks the futures broken, then ends and joins the workers: until then a dead worker's exit
        # status may be unread (read by its join, not here: a test's line said "how is not known")
        manager.join(timeout=5)
    ended = [p.exitcode for p in getattr(pool, "started", {}).values() if p.exitcode is not None]
    if not ended:
        return "how is not known"
    code = min(ended, key=lambda c: (c == -signal.SIGTERM, c >= 0))
    if code >= 0:
        return f"exit status {code}"
    try:
        name = signal.Signals(-code).name
    except ValueError:
        name = "?"
    why = ": the system's out-of-memory killer sends it" if -code == signal.SIGKILL else ""
    return f"killed by signal {-code} ({name}{why})"


def worker_lost(pool: ProcessPoolExecutor) -> WorkerLost:
    """The WorkerLost of a pool broken by a worker's death (module rule)."""
    return WorkerLost(f"a worker process died ({died_how(pool)}) while it held work")


def result_of(pool: ProcessPoolExecutor, future: Future):
    """`future.result()` of work submitted to `pool`; a dead worker is WorkerLost (module rule), not
    BrokenProcessPool. An exception the work itself raised is raised as it is."""
    try:
        return future.result()
    except BrokenProcessPool:
        raise worker_lost(pool) from None


def max_workers() -> int:
    """The most local worker processes a verb starts: the CPUs this process may run on (at least 2).

    Why: each worker runs one CPU-bound cell on one thread (core/threads.py) and holds its own
    compiled kernels and arrays, so more workers than CPUs only queue the cells and multiply the
    memory; `sweep --workers 1000` was accepted. 2 at least, so `--workers 2` runs anywhere."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cpus = os.cpu_count() or 1
    return max(2, cpus)


def check_workers(workers: int) -> int:
    """`workers` if 1..max_workers(); ValueError saying the range and why otherwise."""
    top = max_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= top:
        raise ValueError(f"workers must be 1..{top} (the CPUs this process may use: more only queue cells), "
                         f"got {workers!r}")
    return workers


def process_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of `workers` (>= 1) spawned processes that ignore SIGINT. Stop it with `stop_pool`."""
    return _ParentInterruptedPool(workers, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_worker_start, initargs=(os.getpid(),))


def stop_pool(pool: ProcessPoolExecutor, abandon: bool) -> None:
    """Shut `pool` down: wait for its work, or, when `abandon` (an error or an interruption is on its
    way out), cancel what has not started and terminate the workers now."""
    if not abandon:
        pool.shutdown(wait=True)
        return
    # ProcessPoolExecutor.terminate_workers() is Python 3.14+; before it, the pool's own process table.
    processes = getattr(pool, "_processes", None) or {}
    workers = list(processes.values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for stop in ("terminate", "kill"):  # SIGTERM; a worker that outlives it (still starting up) gets SIGKILL
        alive = [w for w in workers + list(processes.values()) if w.is_alive()]
        for worker in alive:
            getattr(worker, stop)()
        for worker in alive:
            worker.join(timeout=2)
    if manager is not None:  # it sees the workers gone and closes the pool's queues
        manager.join(timeout=2)


TRACKER_STOP_S = 1.0  # what the resource tracker has to end in (it unlinks what is left: milliseconds)


def stop_resource_tracker() -> None:
    """End multiprocessing's resource tracker, if this process started one, and reap it: a verb's last step
    (cli/main.py `_end`), so that no child of the verb outlives it.

    Why: the tracker (started with the first pool, in the verb's process group) ends only when its pipe's
    write end closes, at our exit: it then unlinks what the pool left (an interrupted pool's semaphores) and
    exits after us, re-parented to init, which reaps it when it gets to it: an interrupted `sweep --workers 2`
    left it in its process group for 1.0-1.9 s after its exit (trial31 #4, "a worker outlives it as a
    zombie"). Closing the pipe here does the same clean-up before we end; one that has not ended within
    TRACKER_STOP_S is killed (the prompt exit comes first; what it had left to unlink stays, as after a kill)."""
    from multiprocessing import resource_tracker

    tracker = getattr(resource_tracker, "_resource_tracker", None)
    # (private: the tracker's pipe, pid and lock, the same on 3.11-3.13; its own `_stop` waits without a bound); a
    # Python whose tracker has other names is left to its exit, as before (one that lacked them failed every verb's end)
    lock = getattr(tracker, "_lock", None)
    if (getattr(tracker, "_fd", None) is None or not hasattr(tracker, "_pid") or not hasattr(lock, "acquire")
            or not lock.acquire(timeout=TRACKER_STOP_S)):
        return  # none started, or a thread of ours holds it (registering something): left to the exit, as before
    try:
        fd, pid = tracker._fd, tracker._pid
        if fd is None:
            return
        tracker._fd = tracker._pid = None
        os.close(fd)  # EOF: it cleans up and exits
        deadline = time.monotonic() + TRACKER_STOP_S
        while os.waitpid(pid, os.WNOHANG) == (0, 0):
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return
            time.sleep(0.005)
    except (OSError, ChildProcessError):  # reaped already, or gone: nothing of it is left
        pass
    finally:
        tracker._lock.release()


@contextlib.contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """`process_pool(workers)` for a `with` block: waited for on a normal exit, abandoned on any exception."""
    pool = process_pool(workers)
    try:
        yield pool
    except BaseException:
        stop_pool(pool, abandon=True)
        raise
    stop_pool(pool, abandon=False)
