"""A verb's worker processes never outlive it (pairplay/processes.py `_watch_parent`). Before: a `pairplay
study` killed by SIGKILL (or the OOM killer) left its spawned figure worker and multiprocessing's resource
tracker running for ever, re-parented to init: the worker waited on its call queue, whose write end it holds."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from childprocs import alive as _alive, children as _children

EXAMPLES = Path(__file__).parent.parent / "examples"


def test_a_study_killed_by_sigkill_leaves_no_worker_behind(tmp_path):
    study = subprocess.Popen([sys.executable, "-m", "pairplay", "study", "--out", str(tmp_path / "out"), "--rounds",
                              "3000", "--quiet"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    left: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and study.poll() is None:  # the figure worker starts with the study
            kids = _children(study.pid)
            if any(b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes() for k in kids if _alive(k)):
                break
            time.sleep(0.05)
        time.sleep(1.0)  # the worker has imported matplotlib and waits for figures
        assert study.poll() is None, study.stderr.read()
        left = [k for k in _children(study.pid) if _alive(k)]
        assert left, "the study started no worker process"
        study.send_signal(signal.SIGKILL)
        study.wait()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(_alive(k) for k in left):
            time.sleep(0.05)
        assert not [k for k in left if _alive(k)], "the study's workers outlived it"
    finally:
        if study.poll() is None:
            study.kill()
            study.wait()
        for k in left:  # only the processes this test's study started
            if _alive(k):
                os.kill(k, signal.SIGKILL)


def _group(pgid: int) -> list[tuple[int, str]]:
    """Every process of process group `pgid`, zombies too: (pid, its state)."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, ValueError, IndexError):
            continue
        if proc.name.isdigit() and int(fields[2]) == pgid:
            found.append((int(proc.name), fields[0]))
    return found


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_sweep_leaves_no_process_of_its_group_behind(tmp_path, signum):
    """trial31 #4: `pairplay sweep --workers 2` interrupted exited promptly with its line, but a child stayed in its
    process group 1.0-1.9 s after its exit, a zombie reaped by init: multiprocessing's resource tracker, which
    ends only when our exit closes its pipe (pairplay/processes.py `stop_resource_tracker`, cli/main.py `_end`).
    Real parts: a real sweep of two worker processes in a process group of its own, a real signal once a cell is
    written; the group is looked at as soon as the sweep has exited."""
    out = tmp_path / "sweep"
    sweep = subprocess.Popen([sys.executable, "-m", "pairplay", "sweep", str(EXAMPLES / "sweep-50.toml"), "--workers",
                              "2", "--out", str(out), "--quiet"], cwd=tmp_path, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while sweep.poll() is None and time.monotonic() < deadline and not any((out / "cells").glob("*")):
            time.sleep(0.05)
        assert sweep.poll() is None, sweep.stderr.read()
        sweep.send_signal(signum)
        err = sweep.communicate(timeout=30)[1]
        left = _group(sweep.pid)  # at once: the verb's children are ended and reaped before it ends
        assert sweep.returncode == 128 + signum and "interrupted" in err, err
        assert not left, f"processes of the sweep's group left after its exit: {left}"
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.wait()


# a stand-in for the bench's study child (bench/core.py _STUDY): a pool worker holding work, as the study's figure
# worker, and multiprocessing's resource tracker beside it
_POOL_CHILD = """
import time
from pairplay.processes import worker_pool
with worker_pool(1) as pool:
    pool.submit(time.sleep, 600).result()
"""
_BENCH_PARENT = "import sys; from pairplay.bench.core import _python; _python(sys.argv[1])"


def test_an_interrupted_bench_leaves_no_child_of_its_child_behind(tmp_path):
    """trial32 I, its kind: `pairplay bench` interrupted while its study ran in a child exited in 0.3-0.7 s, but the
    child's figure worker and resource tracker stayed in its group 1.4-2.4 s more: subprocess.run killed the child
    with SIGKILL and returned unwaited. bench/core.py `_python` stops its child as a Ctrl-C would and reaps it.
    Real parts: the bench's own `_python` in a process group of its own, a real pool in its child, a real SIGINT
    once the worker runs; the group is looked at as soon as the parent has exited."""
    parent = subprocess.Popen([sys.executable, "-c", _BENCH_PARENT, _POOL_CHILD], cwd=tmp_path,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while parent.poll() is None and time.monotonic() < deadline and not any(
                b"spawn_main" in _cmdline(pid) for pid, state in _group(parent.pid) if state != "Z"):
            time.sleep(0.05)
        assert parent.poll() is None, parent.stderr.read()
        parent.send_signal(signal.SIGINT)
        err = parent.communicate(timeout=30)[1]
        left = _group(parent.pid)
        assert parent.returncode != 0 and "KeyboardInterrupt" in err, err
        assert not left, f"processes of the bench's group left after its exit: {left}"
    finally:
        if parent.poll() is None:
            os.killpg(parent.pid, signal.SIGKILL)
            parent.wait()


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""
