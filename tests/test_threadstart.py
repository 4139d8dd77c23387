"""A thread that dies as it starts is refused at its start (pairplay/threadstart.py), never waited for.

Before: `threading.Thread.start` waits for the new thread to say it runs; one whose first step failed
(MemoryError under `ulimit -v`: its first lock or frame could not be allocated) never said so, and the
starter waited for ever: `pairplay session` under `ulimit -v 1700000` hung in a service's start until
killed (test_cli_out_of_threads failed by its 90 s timeout; 2 runs of 6 at that limit under load), with
Python's "Exception ignored in thread started by: ... MemoryError" on stderr. The failure is the one the
limit causes, raised where the limit raised it (the new thread's `_set_tstate_lock` allocates its first
lock); each check runs in a process of its own, as the command's entry installs the guard in its own."""

from __future__ import annotations

import subprocess
import sys
import textwrap

DIES_AS_IT_STARTS = textwrap.dedent("""
    import threading, time
    from pairplay.errors import out_of_threads
    from pairplay.services.runner import start_unless_stopped
    try:
        from pairplay import threadstart
        threadstart.guard()
    except ImportError:  # before: no guard
        pass

    class Starved(threading.Thread):
        def _set_tstate_lock(self):  # what `ulimit -v` makes of the new thread's first allocation
            raise MemoryError

    def start():  # a service's start, run by the session in a thread of its own, starts one of its threads
        Starved(target=print, daemon=True).start()

    began = time.monotonic()
    try:
        start_unless_stopped(start, threading.Event(), "starved")
    except RuntimeError as err:
        assert out_of_threads(err), err
        print(f"refused in {time.monotonic() - began:.1f} s")
    fine = threading.Thread(target=time.sleep, args=(0.05,))
    fine.start()  # a thread that runs starts as before
    fine.join()
    assert not fine.is_alive()
""")


def test_a_thread_that_dies_as_it_starts_is_out_of_threads_at_once_not_a_hang():
    try:
        r = subprocess.run([sys.executable, "-c", DIES_AS_IT_STARTS], capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        raise AssertionError("still waiting for a thread that died as it started after 30 s") from None
    assert r.returncode == 0 and r.stderr == "", r.stderr[-2000:]
    assert r.stdout.startswith("refused in "), r.stdout
