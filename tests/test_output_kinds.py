"""Only a regular file is ever replaced: a device, a named pipe, a socket or a symbolic link where a verb writes a
file is refused in one line naming what it is, `--force` or not (pairplay/outputs.py `check_kind`).

A new user's trial, as root: `combine rebuilt/ -o mynull --force` (mknod c 1 3) said "wrote mynull", rc 0, and
mynull was a regular file; `-o myfifo --force` and `view --out mynull --force` the same; and `combine -o /dev/null`
said "exists; --force replaces it (/dev/null)", inviting the system's /dev/null to be replaced. Each verb that
writes a file or a folder of files meets it: one shared check (outputs.py), and the recorder's for a session's.
"""

from __future__ import annotations

import os
import shutil
import socket
import stat
from pathlib import Path

import pytest
from test_outputs import ONE_GAME_STUDY

SAMPLES = Path(__file__).resolve().parents[1] / "recordings" / "samples"

GRID = """seeds = 1
[study]
personas = "blind"
games = 1
rounds = 3
eval_rounds = 1
[grid]
reward_bonus = ["correct"]
"""
STUDY = ("--games", "1", "--rounds", "3", "--personas", "blind", "--eval-rounds", "1", "--train-only", "-q")

# verb -> (its arguments, the file it would write that the test makes special); the folders it names exist; the
# last two have no --force (bench --readme replaces its README's table always; a key file is appended to)
VERBS = {
    "combine": (("combine", "rebuilt/", "-o", "merged.json"), "merged.json"),
    "view": (("view", "--recording", "R.mcap", "--out", "R.rrd"), "R.rrd"),
    "recover": (("recover", "cut.mcap", "-o", "fixed.mcap"), "fixed.mcap"),
    "rebuild": (("rebuild", "R.mcap", "--out", "rb", "--no-plot"), "rb/R.policy.json"),
    "study": (("study", "--out", "st", *STUDY), "st/report.md"),
    "counterfactual": (("counterfactual", "R.mcap", "--fit-only", "--out", "cf", "-q"), "cf/counterfactual.md"),
    "sweep": (("sweep", "grid.toml", "--out", "sw", "-q"), "sw/sweep.md"),
    "session": (("session", "--participant", "sim:blind", "--rounds", "2", "--out", "rec", "--session", "s1"),
                "rec/s1.mcap"),
    "protocol init --key-file": (("protocol", "init", "pf", "--study", "one.toml", "--key-file", "key.csv"),
                                 "key.csv"),
    "bench --readme": (("bench", "--readme", "BENCH.md"), "BENCH.md"),
}


def make_inputs(root: Path, pairplay_cli) -> None:
    """What the verbs read, in the folder `root`: a recording, a cut one, rebuilt policies, a study file and a study
    folder (tests/test_input_kinds.py too)."""
    shutil.copy(SAMPLES / "sim-ashley.mcap", root / "R.mcap")
    data = (SAMPLES / "sim-ashley.mcap").read_bytes()
    (root / "cut.mcap").write_bytes(data[:len(data) * 2 // 3])
    r = pairplay_cli("rebuild", "R.mcap", SAMPLES / "sim-helmut-fmt2.mcap", "--out", "rebuilt", "--no-plot", cwd=root)
    assert r.returncode == 0, r.stderr
    (root / "one.toml").write_text(ONE_GAME_STUDY)
    r = pairplay_cli("protocol", "init", "study", "--study", "one.toml", cwd=root)  # for a report (test_output_writers)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def template(tmp_path_factory, pairplay_cli) -> Path:
    """A folder with what the verbs read (`make_inputs`), a grid, and the folders the verbs write into."""
    root = tmp_path_factory.mktemp("kinds")
    make_inputs(root, pairplay_cli)
    (root / "grid.toml").write_text(GRID)
    for folder in ("rb", "st", "cf", "sw", "rec"):
        (root / folder).mkdir()
    return root


def _make(kind: str, path: Path) -> str:
    """Make a `kind` at `path`; what the refusal calls it."""
    if kind == "fifo":
        os.mkfifo(path)
        return "is a named pipe (FIFO)"
    if kind == "device":
        os.mknod(path, 0o644 | stat.S_IFCHR, os.makedev(1, 3))  # /dev/null's
        return "is a character device"
    if kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        s.close()
        return "is a socket"
    path.symlink_to("elsewhere.json")  # dangling: replacing it loses the link, following it writes elsewhere
    return "is a symbolic link (to elsewhere.json)"


def _kind(path: Path) -> int:
    return stat.S_IFMT(os.lstat(path).st_mode)


NO_FORCE = ("protocol init --key-file", "bench --readme")


def _refused(r, said: str, path: Path, kind_before: int, args) -> None:
    assert r.returncode == 2 and r.stderr.count("\n") == 1, (args, r.returncode, r.stdout, r.stderr)
    assert said in r.stderr and str(path.name) in r.stderr, (args, r.stderr)
    assert "--force replaces" not in r.stderr, (args, r.stderr)  # the hint only where --force would
    assert _kind(path) == kind_before, args  # still what it was


@pytest.mark.parametrize("verb", VERBS)
def test_a_pipe_where_a_verb_writes_is_refused_force_or_not(verb, template, tmp_path, pairplay_cli):
    args, target = VERBS[verb]
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    said = _make("fifo", root / target)
    before = _kind(root / target)
    for force in ((),) if verb in NO_FORCE else ((), ("--force",)):
        r = pairplay_cli(*args, *force, cwd=root, timeout=180)
        _refused(r, said, root / target, before, (*args, *force))


KINDS = ["fifo", "socket", "link"] + (["device"] if os.geteuid() == 0 else [])


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_of_special_file_is_refused(kind, template, tmp_path, pairplay_cli):
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    said = _make(kind, root / "merged.json")
    before = _kind(root / "merged.json")
    for force in ((), ("--force",)):
        r = pairplay_cli("combine", "rebuilt/", "-o", "merged.json", *force, cwd=root)
        _refused(r, said, root / "merged.json", before, (kind, *force))
        assert "--force or not" in r.stderr, r.stderr


@pytest.mark.skipif(os.geteuid() != 0 or not os.path.exists("/dev/null"), reason="needs root and /dev/null")
def test_dev_null_is_never_offered_to_force(tmp_path, pairplay_cli):
    """`combine -o /dev/null` said "exists; --force replaces it (/dev/null)": as root, --force would have."""
    shutil.copytree(SAMPLES, tmp_path / "s")
    r = pairplay_cli("rebuild", "s/sim-ashley.mcap", "--out", "rebuilt", "--no-plot", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = pairplay_cli("combine", "rebuilt/", "-o", "/dev/null", cwd=tmp_path)
    assert r.returncode == 2 and "is a character device" in r.stderr and "--force replaces" not in r.stderr, r.stderr
    assert stat.S_ISCHR(os.lstat("/dev/null").st_mode)


def test_a_special_file_where_a_folder_is_written_is_named(template, tmp_path, pairplay_cli):
    """A pipe where a folder of outputs goes was called "a file"."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    os.mkfifo(root / "out")
    r = pairplay_cli("rebuild", "R.mcap", "--out", "out", "--no-plot", cwd=root)
    assert r.returncode == 2 and "is a named pipe (FIFO), not a folder" in r.stderr, r.stderr


@pytest.mark.parametrize("verb", ["rebuild", "study"])
def test_a_link_to_an_empty_folder_as_the_output_folder_fills_the_folder_it_names(verb, template, tmp_path,
                                                                                    pairplay_cli):
    """A trial (trial25): `rebuild R --out link4` with link4 -> an empty folder said "Not a directory
    (.link4.<pid>.<hex>.tmp -> link4)": the output's rename onto the link. The folder it names is the output."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    (root / "real").mkdir()
    os.symlink("real", root / "link")
    args = ("rebuild", "R.mcap", "--out", "link", "--no-plot") if verb == "rebuild" else \
        ("study", "--out", "link", *STUDY)
    r = pairplay_cli(*args, cwd=root, timeout=300)
    assert r.returncode == 0, r.stderr
    assert (root / "link").is_symlink() and os.readlink(root / "link") == "real"  # the link stays a link
    assert any(p.is_file() for p in (root / "real").iterdir()), list((root / "real").iterdir())
    assert not list(root.glob(".*.tmp")) and not list((root / "real").glob(".*.tmp"))


@pytest.mark.parametrize("target", ["nowhere", "R.mcap"])
def test_a_link_naming_no_folder_as_the_output_folder_is_named(target, template, tmp_path, pairplay_cli):
    """A dangling link (or one to a file) where a folder of outputs goes said "cannot write there: File exists"."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    os.symlink(target, root / "out")
    for force in ((), ("--force",)):
        r = pairplay_cli("rebuild", "R.mcap", "--out", "out", "--no-plot", *force, cwd=root)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert f"is a symbolic link (to {target}), which names no folder" in r.stderr and "(out)" in r.stderr, \
            r.stderr
    assert os.readlink(root / "out") == target
