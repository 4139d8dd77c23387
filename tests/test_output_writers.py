"""One writer per output (pairplay/outputs.py `hold`), and a study folder made only where no other work is.

A new user's trial: two `pairplay sweep sweep-psi.toml` on the same output 1 s apart both computed every cell (rc
0 and 0), the work done twice; nothing refused or waited, unlike a study folder's one writer. Now a verb writing an
output holds its writer lock from before its checks to its end, and a second writer of it is refused at once in one
line naming the holder. And `protocol init wt1` on a folder holding the README walkthrough's recordings/, rebuilt/
and merged.json said rc 0, then `session`/`rebuild --out` there were refused: a folder holding other work is now
refused in one line (hidden files aside).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from test_output_kinds import GRID, ONE_GAME_STUDY, SAMPLES, template  # noqa: F401  (the module's fixture)


def test_a_second_sweep_of_one_output_is_refused_while_the_first_writes(tmp_path, pairplay_cli):
    """The trial's two sweeps, the first held (a test pause) after its folder is written, before it ends."""
    (tmp_path / "grid.toml").write_text(GRID)
    go = tmp_path / "go"
    env = dict(os.environ, PAIRPLAY_TEST_PAUSE=f"folder-written:{go}")
    first = subprocess.Popen([sys.executable, "-m", "pairplay", "sweep", "grid.toml", "--out", "sw", "-q"],
                             cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    try:
        assert first.stderr.readline() == "pairplay-test: paused at folder-written\n"
        before = sorted(p.relative_to(tmp_path).as_posix() for p in (tmp_path / "sw").rglob("*"))
        r = pairplay_cli("sweep", "grid.toml", "--out", "sw", "--force", cwd=tmp_path)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert r.stderr.startswith(f"pairplay sweep: busy: pairplay sweep (pid {first.pid}, since "), r.stderr
        assert r.stderr.rstrip().endswith("writes it; wait for it to end, or give another output (sw)"), r.stderr
        assert sorted(p.relative_to(tmp_path).as_posix() for p in (tmp_path / "sw").rglob("*")) == before
    finally:
        go.touch()
        first.communicate(timeout=120)
    assert first.returncode == 0
    r = pairplay_cli("sweep", "grid.toml", "--out", "sw", cwd=tmp_path)  # the first ended: its lock went with it
    assert r.returncode == 0 and "nothing to do" in r.stdout, r.stderr


# verb -> (its arguments, the output it writes)
WRITERS = {
    "sweep": (("sweep", "grid.toml", "--out", "sw"), "sw"),
    "study": (("study", "--out", "st", "--games", "1", "--rounds", "3", "--personas", "blind", "--eval-rounds", "1",
               "--train-only"), "st"),
    "counterfactual": (("counterfactual", "R.mcap", "--fit-only", "--out", "cf"), "cf"),
    "report": (("report", "study", "--out", "rp"), "rp"),
    "rebuild": (("rebuild", "R.mcap", "--out", "rb", "--no-plot"), "rb"),
    "view": (("view", "--recording", "R.mcap", "--out", "R.rrd"), "R.rrd"),
    "combine": (("combine", "rebuilt/", "-o", "merged.json"), "merged.json"),
    "recover": (("recover", "cut.mcap", "-o", "fixed.mcap"), "fixed.mcap"),
    "protocol init": (("protocol", "init", "new", "--study", "one.toml"), "new"),
    "bench --readme": (("bench", "--readme", "BENCH.md"), "BENCH.md"),
}
NO_FORCE = ("protocol init", "bench --readme")


@pytest.mark.parametrize("verb", WRITERS)
def test_every_writer_of_an_output_is_refused_while_another_writes_it(verb, template, tmp_path, pairplay_cli):
    """Each verb writing an output: another process holding that output's writer lock (here this test's, as a
    running writer holds it) refuses it at once, in one line naming the holder; nothing is written."""
    from pairplay import outputs

    args, out = WRITERS[verb]
    root = tmp_path / "w"
    shutil.copytree(template, root)
    before = sorted(p.relative_to(root).as_posix() for p in root.rglob("*"))
    outputs.hold(root / out, "sweep")  # by another name of it: the lock is the output's, however it is named
    try:
        r = pairplay_cli(*args, *(() if verb in NO_FORCE else ("--force",)), cwd=root, timeout=180)
    finally:
        outputs.release_held()
    assert r.returncode == 2 and r.stderr.count("\n") == 1, (r.stdout, r.stderr)
    assert f"busy: pairplay sweep (pid {os.getpid()}, since " in r.stderr and f"({out})" in r.stderr, r.stderr
    assert sorted(p.relative_to(root).as_posix() for p in root.rglob("*")) == before


def test_protocol_init_refuses_a_folder_holding_other_work(tmp_path, pairplay_cli):
    """The README walkthrough's folder (recordings/, rebuilt/, merged.json) is no new study's; a folder holding
    only hidden files (a file manager's .DS_Store), or nothing, is; another verb's manifest counts as work."""
    (tmp_path / "one.toml").write_text(ONE_GAME_STUDY)
    wt1 = tmp_path / "wt1"
    (wt1 / "recordings").mkdir(parents=True)
    shutil.copy(SAMPLES / "sim-ashley.mcap", wt1 / "recordings" / "R.mcap")
    (wt1 / "rebuilt").mkdir()
    (wt1 / "merged.json").write_text("{}")
    before = sorted(p.relative_to(wt1).as_posix() for p in wt1.rglob("*"))
    r = pairplay_cli("protocol", "init", "wt1", "--study", "one.toml", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr == (
        "pairplay protocol init: holds other work (merged.json, rebuilt/, recordings/); a study folder is made in a "
        "new or empty folder (hidden files aside): give another folder (wt1)\n"), r.stderr
    assert sorted(p.relative_to(wt1).as_posix() for p in wt1.rglob("*")) == before
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / ".DS_Store").write_text("a file manager's")
    r = pairplay_cli("protocol", "init", "hidden", "--study", "one.toml", cwd=tmp_path)
    assert r.returncode == 0 and (hidden / "journal.jsonl").is_file() and (hidden / ".DS_Store").exists(), r.stderr
    made = tmp_path / "made"
    (made / ".pairplay-rebuild.manifest").parent.mkdir()
    (made / ".pairplay-rebuild.manifest").write_text("{}")
    r = pairplay_cli("protocol", "init", "made", "--study", "one.toml", cwd=tmp_path)
    assert r.returncode == 2 and "holds other work (.pairplay-rebuild.manifest)" in r.stderr, r.stderr
