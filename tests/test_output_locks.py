"""An output's writer lock file is removed as its holder lets go, and the lock stays one writer's.

Before, `pairplay/outputs.py hold` left one empty file in `$TMPDIR/pairplay-outputs-<uid>/` per output ever
written, for ever. Now the holder removes it while it still holds it (pairplay/folderlock.py `release`'s
`remove`), and a writer that opened the file before that finds, once it holds it, that the name is no longer
its file's, and opens the name again (`take_file`): without that check it would hold the removed file's lock
beside the next writer's lock of the new file, both writing one output. Real processes (`pairplay rebuild` of a
sample recording), the removal landed between a writer's open and its lock by a test pause
(pairplay/testpause.py: `lock-opened`, `folder-written`).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SAMPLE = Path(__file__).parent.parent / "recordings" / "samples" / "sim-ashley-fmt2.mcap"


def rebuild(tmp_path: Path, out: str, *more: str, pause: str = "") -> subprocess.Popen:
    """`pairplay rebuild SAMPLE --out OUT` with its own temporary folder (where the output locks are), paused at
    `pause` (`moment:go-file`) if given."""
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"), PYTHONUNBUFFERED="1")
    env.pop("PAIRPLAY_TEST_PAUSE", None)
    if pause:
        env["PAIRPLAY_TEST_PAUSE"] = pause
    return subprocess.Popen([sys.executable, "-m", "pairplay", "rebuild", str(SAMPLE), "--out", out, "--no-plot",
                             *more], cwd=tmp_path, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def locks(tmp_path: Path) -> list[str]:
    return sorted(p.name for p in (tmp_path / "tmp").glob("pairplay-outputs-*/*"))


def paused(proc: subprocess.Popen, moment: str) -> None:
    line = proc.stderr.readline()
    assert line == f"pairplay-test: paused at {moment}\n", line + proc.stderr.read()


def test_the_output_locks_folder_holds_no_file_of_an_output_nobody_writes(tmp_path):
    (tmp_path / "tmp").mkdir()
    for n in range(3):
        p = rebuild(tmp_path, f"rb{n}")
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert locks(tmp_path) == [], n  # before: one file more per output written


def test_a_writer_that_opened_the_lock_file_its_holder_then_removed_does_not_write_beside_the_next(tmp_path):
    (tmp_path / "tmp").mkdir()
    first = rebuild(tmp_path, "rb", pause=f"folder-written:{tmp_path / 'go-first'}")
    second = third = None
    try:
        paused(first, "folder-written")  # it holds rb's lock, its output written
        [lock] = locks(tmp_path)
        # the second has opened the lock file the first holds, and waits before it locks it
        second = rebuild(tmp_path, "rb", "--force", pause=f"lock-opened:{tmp_path / 'go-second'}")
        paused(second, "lock-opened")
        (tmp_path / "go-first").touch()
        assert first.wait(120) == 0, first.stderr.read()
        assert locks(tmp_path) == []  # removed as the first let go (the second holds the removed file open)
        third = rebuild(tmp_path, "rb", "--force", pause=f"folder-written:{tmp_path / 'go-third'}")
        paused(third, "folder-written")  # it holds rb's lock: a new file of the same name
        assert locks(tmp_path) == [lock]
        (tmp_path / "go-second").touch()  # its flock of the removed file succeeds: the name is another file's now
        _, err = second.communicate(timeout=120)
        assert second.returncode == 2 and err.count("\n") == 1, err
        assert err.startswith(f"pairplay rebuild: busy: pairplay rebuild (pid {third.pid}, since "), err
        (tmp_path / "go-third").touch()
        assert third.wait(120) == 0, third.stderr.read()
    finally:
        for proc in (first, second, third):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert locks(tmp_path) == []
