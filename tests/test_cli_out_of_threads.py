"""Running out of threads is one line, exit 2, at once: never a traceback, a hang, or an abort.

Before (a new user's trial, 2026-12-01): under `ulimit -v 1700000`, `pairplay session --participant
sim:blind --rounds 3` ended in a RuntimeError("can't start new thread") traceback, exit 1 (a thread
of zenoh-python's for a subscriber, or one of ours); `pairplay bench --quick --check` under `ulimit -v
3000000` then raised "cannot join thread before it is started" while closing (a Node's thread that
never started) and hung 11 min in the interpreter's exit: the bus was never closed, and zenoh-python's
subscriber threads are not daemons. Now it is the same kind as running out of memory (cli/main.py):
one line naming `ulimit -v`, exit 2; every close path takes threads that never started, and the bus
is closed whatever failed. The limit is real (`ulimit -v` in the child); a process's address space
at start differs between machines, so several limits are tried, and the test is skipped if none of
them runs out of threads here."""

from __future__ import annotations

import resource
import subprocess
import sys

import pytest

LIMITS_KB = (1_000_000, 1_400_000, 1_700_000, 2_000_000)  # the trial's ran out of threads at 1,000,000-1,790,000


def limited(kb: int):
    def set_limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (kb * 1024, kb * 1024))
    return set_limit


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS as Linux counts it")
def test_a_session_out_of_threads_says_one_line_exit_2_and_ends_at_once(tmp_path):
    hit = []
    for kb in LIMITS_KB:
        try:
            r = subprocess.run([sys.executable, "-m", "pairplay", "session", "--participant", "sim:blind",
                                "--rounds", "3", "--out", str(tmp_path / str(kb))], cwd=tmp_path,
                               capture_output=True, text=True, timeout=90, preexec_fn=limited(kb))
        except subprocess.TimeoutExpired:
            pytest.fail(f"ulimit -v {kb}: still running after 90 s (a hang in the exit)")
        assert "Traceback" not in r.stderr and r.returncode in (0, 2), (kb, r.returncode, r.stderr[-3000:])
        if r.returncode == 2:
            [line] = r.stderr.strip().splitlines()
            assert line.startswith("pairplay session: out of "), line
            if line.startswith("pairplay session: out of threads"):
                assert "ulimit -v" in line, line
                hit.append(kb)
    if not hit:
        pytest.skip(f"no limit of {LIMITS_KB} ran out of threads on this machine")
