"""A full disk while a verb writes: no traceback, exit 2, a line naming the output, nothing left behind.

Before (found by the trial, 2026-11-30): `pairplay view --recording REC --out X.rrd` on a full
file system (or under `ulimit -f`) ended in a traceback, exit 1: rerun's file writer stopped and
the view's final flush raised RuntimeError("File-writer thread shut down prematurely"). rerun's own
log lines (its writer's error, which names the cause) are left as they are.
The full disk is a 64 KiB tmpfs in a mount namespace of the test's own (`unshare`, as root)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
CAN_UNSHARE = os.geteuid() == 0 and shutil.which("unshare") is not None


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_view_on_a_full_disk_is_one_line_of_ours_exit_2_and_no_rrd(tmp_path):
    full = tmp_path / "full"
    full.mkdir()
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    command = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
               'mount -t tmpfs -o size=64k tmpfs "$0" && exec "$@"', str(full),
               sys.executable, "-m", "pairplay", "view", "--recording", "rec.mcap", "--out", "full/v.rrd"]
    r = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    ours = [line for line in r.stderr.splitlines() if line.startswith("pairplay view: ")
            and not line.startswith("pairplay view: drawing")]
    assert len(ours) == 1 and "writing the .rrd failed" in ours[0] and "full/v.rrd" in ours[0], r.stderr


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_rebuild_on_a_full_disk_names_the_file_and_leaves_nothing(tmp_path):
    """Before (the trial): "No space left on device" named no file, and the policies written before it
    stayed. 40 KiB holds the first recording's policy and curve, not the second's: the second fails."""
    full = tmp_path / "full"
    full.mkdir()
    helmut = SAMPLE.with_name("sim-helmut-fmt2.mcap")
    # the tmpfs lives as long as its namespace: the files it holds are listed inside it, after the verb
    script = ('mount -t tmpfs -o size=40k tmpfs full && "$0" -m pairplay rebuild "$1" "$2" --out full/rb >/dev/null 2>err; '
              'echo $? >rc; find full -type f')
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, sys.executable,
                        str(SAMPLE), str(helmut)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = (tmp_path / "err").read_text()
    assert (tmp_path / "rc").read_text().strip() == "2" and "Traceback" not in err, err
    [line] = err.strip().splitlines()
    assert line.startswith("pairplay rebuild: No space left on device; removed the ") and "(full/rb/" in line, line
    assert r.stdout.strip() == "", r.stdout  # nothing left: neither the first recording's outputs nor a temp file
