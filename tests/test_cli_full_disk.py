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
    stayed. 40 KiB holds the first recording's policy and curve, not the second's: the second fails, and
    nothing was moved into full/rb (every output is written beside it first: outputs.output_folder)."""
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
    assert line.startswith("pairplay rebuild: No space left on device (full/rb/"), line  # nothing was moved in
    assert r.stdout.strip() == "", r.stdout  # nothing left: neither the first recording's outputs nor a temp file


TINY_GRID = 'seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\neval_rounds = 1\n'


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
@pytest.mark.parametrize("fill", [0, 4096], ids=["cell", "grid-copy"])
def test_sweep_on_a_full_disk_is_exit_2_one_line_naming_the_file_and_nothing_left(tmp_path, fill):
    """Before: a full disk while the sweep wrote its first cell exited 1 (README's table: 2, the system
    refused what was asked), said "[Errno 28] No space left on device" naming no file, and left the
    cell's temporary file, grid.toml and the folders; one full before grid.toml named no file either.
    A 4 KiB tmpfs holds grid.toml (one page) and not a cell; pre-filled, not grid.toml."""
    full = tmp_path / "full"
    full.mkdir()
    (tmp_path / "grid.toml").write_text(TINY_GRID)
    script = ('mount -t tmpfs -o size=4k tmpfs full && { [ "$1" = 0 ] || head -c "$1" /dev/zero >full/fill; } '
              '2>/dev/null; "$0" -m pairplay sweep grid.toml --out full/sw -q >out 2>err; echo $? >rc; '
              'find full -mindepth 1 ! -name fill')
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, sys.executable,
                        str(fill)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = (tmp_path / "err").read_text()
    assert (tmp_path / "rc").read_text().strip() == "2" and "Traceback" not in err, err
    [line] = err.strip().splitlines()
    named = "full/sw/grid.toml" if fill else "full/sw/cells/"
    assert line.startswith("pairplay sweep: No space left on device (") and named in line, line
    assert r.stdout.strip() == "", r.stdout  # nothing left: no cell's temporary file, no grid.toml, no folder
    assert (tmp_path / "out").read_text() == ""


def _in_full_tmpfs(tmp_path: Path, fill: int, *args: str) -> tuple[int, str, list[str]]:
    """`python -m pairplay ARGS` in tmp_path with ./full a 4 KiB tmpfs holding `fill` bytes already:
    its status, its stderr and the files and folders it left in ./full (found inside the namespace)."""
    (tmp_path / "full").mkdir()
    script = ('mount -t tmpfs -o size=4k tmpfs full && { [ "$1" = 0 ] || head -c "$1" /dev/zero >full/fill; } '
              '2>/dev/null; shift; "$0" -m pairplay "$@" >/dev/null 2>err; echo $? >rc; find full -mindepth 1 ! -name fill')
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, sys.executable,
                        str(fill), *args], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    return int((tmp_path / "rc").read_text()), (tmp_path / "err").read_text(), r.stdout.split()


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_lab_whose_recording_fails_says_so_in_one_line_exit_1_as_a_session(tmp_path):
    """Before: `pairplay session` said it (exit 1, README: a session that failed) but `pairplay lab`, which
    runs the same session, ended in a RecordingFailed traceback (`protocol pilot` too: one handler now)."""
    code, err, _ = _in_full_tmpfs(tmp_path, 0, "lab", "--participant", "human:p1", "--session", "s1",
                                  "--out", "full/rec", "--linger", "0")
    assert code == 1 and "Traceback" not in err, err
    [line] = [x for x in err.splitlines() if x.startswith("pairplay lab:")]
    assert "writing full/rec/s1.mcap failed (" in line and "pairplay recover full/rec/s1.mcap" in line, err


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_protocol_init_of_the_example_on_a_full_disk_names_the_folder_asked_for(tmp_path):
    """Before: `pairplay protocol init: : No space left on device` (its own OSError line, no file named;
    its temporary copy of the example was written beside the folder, which the error left unnamed)."""
    code, err, left = _in_full_tmpfs(tmp_path, 3000, "protocol", "init", "full/st", "--study", "thesis-ch7")
    assert (code, err.strip()) == (2, "pairplay protocol init: No space left on device (full/st)")
    assert left == []


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_bench_readme_table_on_a_full_disk_names_the_readme_and_leaves_it_whole(tmp_path):
    """Before: `bench --readme` wrote README.md.tmp beside it and renamed it: a full disk named no file
    (cli/main.py's line said `No space left on device`) and left the partial README.md.tmp."""
    (tmp_path / "full").mkdir()
    script = ('mount -t tmpfs -o size=4k tmpfs full && printf "a\\n<!-- bench:start -->\\nold\\n<!-- bench:end -->\\n" '
              '>full/README.md && "$0" -c "$1" 2>err; echo $? >rc; ls -A full; cat full/README.md')
    code = ("import sys\nfrom pathlib import Path\nfrom pairplay.cli import bench\n"
            "bench.README_START, bench.README_END = '<!-- bench:start -->', '<!-- bench:end -->'\n"
            "try:\n    bench.write_readme(Path('full/README.md'), 'x' * 8000)\n"
            "except OSError as err:\n    print(err.strerror, err.filename, file=sys.stderr)\n")
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, sys.executable, code],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert (tmp_path / "err").read_text().strip() == "No space left on device full/README.md"
    assert r.stdout.split("\n", 1) == ["README.md", "a\n<!-- bench:start -->\nold\n<!-- bench:end -->\n"], r.stdout


@pytest.mark.skipif(not CAN_UNSHARE, reason="needs root and unshare for a private tmpfs")
def test_sweep_filling_the_disk_after_a_cell_keeps_it_exit_2_and_says_the_same_command_resumes(tmp_path):
    """8 KiB hold grid.toml and the first cell (a page each), not the second: the finished cell stays, as
    after a signal, and the one line says so and names the file that could not be written."""
    (tmp_path / "grid.toml").write_text(TINY_GRID.replace("seeds = 1", "seeds = 2"))
    (tmp_path / "full").mkdir()
    script = ('mount -t tmpfs -o size=8k tmpfs full && "$0" -m pairplay sweep grid.toml --out full/sw -q >out 2>err; '
              'echo $? >rc; find full -mindepth 1 -type f')
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, sys.executable],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = (tmp_path / "err").read_text()
    assert (tmp_path / "rc").read_text().strip() == "2" and "Traceback" not in err, err
    [line] = err.strip().splitlines()
    assert line.startswith("pairplay sweep: No space left on device (full/sw/cells/") and line.endswith(
        "; 1 of 2 cells finished, kept in full/sw/cells: the same command resumes from them"), line
    files = sorted(r.stdout.split())
    assert len(files) == 2 and files[1] == "full/sw/grid.toml" and files[0].startswith("full/sw/cells/"), files
