"""A verb's worker processes never outlive it (pairplay/processes.py `_watch_parent`). Before: a `pairplay
study` killed by SIGKILL (or the OOM killer) left its spawned figure worker and multiprocessing's resource
tracker running for ever, re-parented to init: the worker waited on its call queue, whose write end it holds."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from childprocs import alive as _alive, children as _children


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
