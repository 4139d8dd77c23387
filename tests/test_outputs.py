"""No file is ever lost: the one writer every verb uses (pairplay.outputs), and the verbs that use it.

An existing output is replaced only when asked (`force`), a write appears whole
or not at all (a temporary file renamed at the end, removed on any error), and
outputs of different inputs never collide (rebuild names outputs by file).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pairplay.errors import OutputError
from pairplay.outputs import check_outputs, output_file, output_folder, output_path, write_bytes, write_text
from pairplay.schemas.policy import read_policy

from rewrite_mcap import another_session

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"


@pytest.fixture
def pairplay(pairplay_cli):
    """`python -m pairplay ARGS` in `cwd`, each its own process (conftest's pairplay_cli)."""
    return lambda *args, cwd=None: pairplay_cli(*args, cwd=cwd, timeout=180)


def test_an_existing_file_is_replaced_only_with_force(tmp_path):
    target = tmp_path / "a.json"
    write_text(target, "first")
    with pytest.raises(OutputError, match="exists") as err:
        write_text(target, "second")
    # the way out is named only where it exists: by a verb that has --force (tests/test_hints.py)
    assert err.value.line({"--force"}) == f"exists; --force replaces it ({target})"
    assert err.value.line({"--out"}) == str(err.value) == f"exists ({target})"
    assert target.read_text() == "first"
    write_text(target, "third", force=True)
    assert target.read_text() == "third"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]  # no temporary file left


def test_a_failed_write_leaves_nothing_and_the_old_file_intact(tmp_path):
    target = tmp_path / "out.bin"
    with pytest.raises(RuntimeError):
        with output_file(target) as f:
            f.write(b"half")
            raise RuntimeError("crash in the middle")
    assert list(tmp_path.iterdir()) == []
    write_bytes(target, b"whole")
    with pytest.raises(KeyboardInterrupt):
        with output_file(target, force=True) as f:
            f.write(b"half")
            raise KeyboardInterrupt
    assert target.read_bytes() == b"whole" and list(tmp_path.iterdir()) == [target]


def test_a_file_that_appears_while_we_write_is_not_replaced(tmp_path):
    target = tmp_path / "race.txt"
    with pytest.raises(OutputError, match="appeared while"):
        with output_path(target) as tmp:
            tmp.write_text("ours")
            target.write_text("someone else's")
    assert target.read_text() == "someone else's" and list(tmp_path.iterdir()) == [target]


def test_places_that_cannot_take_a_file_are_refused_before_any_work(tmp_path):
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="is a folder"):
        write_text(tmp_path / "folder", "x")
    with pytest.raises(OutputError, match="a file stands where a folder is needed"):
        write_text(tmp_path / "file" / "below.txt", "x")
    with pytest.raises(OutputError, match="same file"):
        check_outputs([tmp_path / "x.json", tmp_path / "." / "x.json"])


def test_a_folder_of_outputs_appears_whole_and_is_merged_only_with_force(tmp_path):
    out = tmp_path / "report"
    with output_folder(out) as tmp:
        (tmp / "a.txt").write_text("a")
        assert not out.exists()  # nothing visible until it is complete
    assert (out / "a.txt").read_text() == "a"
    with pytest.raises(OutputError, match="not empty"):
        with output_folder(out):
            pass
    (out / "mine.txt").write_text("the user's")
    with output_folder(out, force=True) as tmp:
        (tmp / "a.txt").write_text("new")
    assert (out / "a.txt").read_text() == "new" and (out / "mine.txt").read_text() == "the user's"
    with pytest.raises(RuntimeError):
        with output_folder(tmp_path / "never") as tmp:
            (tmp / "half.txt").write_text("x")
            raise RuntimeError
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
    with pytest.raises(RuntimeError):
        with output_path(tmp_path / "new" / "deeper" / "x.rrd"):
            raise RuntimeError  # a failure leaves no folder made for the output either
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_rebuild_names_outputs_by_file_so_a_recovered_copy_keeps_its_own(tmp_path, pairplay):
    from pairplay.replay.mcapscan import scan
    last = scan(SAMPLE).chunks[-1]  # X.mcap cut after its last chunk, as a crash leaves it: recover writes a copy
    (tmp_path / "X.mcap").write_bytes(SAMPLE.read_bytes()[:last.offset + last.length])
    r = pairplay("recover", "X.mcap", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "X.recovered.mcap").exists(), r.stderr
    r = pairplay("rebuild", "X.mcap", "X.recovered.mcap", "--out", "rebuilt", cwd=tmp_path)
    assert r.returncode == 2 and "X.mcap and X.recovered.mcap hold the same session" in r.stderr  # (onesession.py)
    r = pairplay("rebuild", "X.mcap", "--out", "rebuilt", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = pairplay("rebuild", "X.recovered.mcap", "--out", "rebuilt", "--no-plot", cwd=tmp_path)  # beside it, alone
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in (tmp_path / "rebuilt").iterdir() if p.name != ".pairplay-rebuild.manifest")
    assert names == ["X.curve.csv", "X.policy.json", "X.recovered.curve.csv", "X.recovered.policy.json",
                     "learning-curves.png"]
    assert read_policy(tmp_path / "rebuilt" / "X.policy.json").q == \
        read_policy(tmp_path / "rebuilt" / "X.recovered.policy.json").q
    assert "picks per round (18 = perfect)" in r.stdout
    before = (tmp_path / "rebuilt" / "X.policy.json").read_bytes()
    r = pairplay("rebuild", "X.mcap", "--out", "rebuilt", cwd=tmp_path)
    assert r.returncode == 2 and "exists; --force" in r.stderr
    r = pairplay("rebuild", "X.mcap", "--out", "rebuilt", "--force", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "rebuilt" / "X.policy.json").read_bytes() == before
    assert [p.name for p in (tmp_path / "rebuilt").glob(".*")] == [".pairplay-rebuild.manifest"]  # no temporary file


def test_recover_and_view_never_replace_what_exists(tmp_path, pairplay):
    shutil.copy(SAMPLE, tmp_path / "R.mcap")
    (tmp_path / "R.rrd").write_bytes(b"a saved view")
    r = pairplay("view", "--recording", "R.mcap", "--session", "wrong", cwd=tmp_path)
    assert r.returncode == 2 and (tmp_path / "R.rrd").read_bytes() == b"a saved view"
    r = pairplay("view", "--recording", "R.mcap", "--force", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "R.rrd").stat().st_size > 1000 and "saved R.rrd" in r.stdout
    r = pairplay("recover", "R.mcap", "-o", "R.mcap", cwd=tmp_path)
    assert r.returncode == 2 and (tmp_path / "R.mcap").read_bytes() == SAMPLE.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["R.mcap", "R.rrd"]


def test_a_forced_folder_loses_the_earlier_runs_own_files_this_run_did_not_write(tmp_path):
    """`study --force` over an older study kept the older study's files the new one does not write (a
    persona's policies no longer in it): stale files that looked current. Now the files the writer names
    as its own (`owned`), an earlier run wrote (its manifest) and this run did not write go, with the folders
    that leaves empty; every other file, and a folder holding one, stays."""
    out = tmp_path / "report"
    owned = ("policies/*/game-*.json", "report.md", "reuse.csv")
    with output_folder(out, owned=owned, manifest=".m") as tmp:
        for rel in ("report.md", "reuse.csv", "policies/a/game-00.json", "policies/b/game-00.json"):
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            (tmp / rel).write_text("old")
    (out / "notes.txt").write_text("the user's")
    (out / "policies" / "b" / "mine.txt").write_text("the user's")
    (out / "policies" / "b" / "deeper").mkdir()
    (out / "policies" / "b" / "deeper" / "game-00.json").write_text("not a pattern's depth")
    with output_folder(out, force=True, owned=owned, manifest=".m") as tmp:
        (tmp / "policies" / "a").mkdir(parents=True)
        (tmp / "policies" / "a" / "game-00.json").write_text("new")
        (tmp / "report.md").write_text("new")
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert left == [".m", "notes.txt", "policies/a/game-00.json", "policies/b/deeper/game-00.json", "policies/b/mine.txt",
                    "report.md"]
    assert (out / "report.md").read_text() == "new"
    with output_folder(out, force=True, owned=owned, manifest=".m") as tmp:  # the folder it leaves empty goes too
        (tmp / "report.md").write_text("newer")
    assert not (out / "policies" / "a").exists() and (out / "policies" / "b" / "mine.txt").exists()


def test_a_signal_while_a_forced_folder_is_merged_waits_until_every_file_is_in(tmp_path, monkeypatch):
    """`study --force` over an earlier study, Ctrl-C while its files were moved in one by one: the folder
    held 11 of 33 files of the new run and the rest of the earlier one's, and the verb said "nothing more
    was written" (a new user's trial). The merge now finishes, then the signal is delivered."""
    import signal

    from pairplay import outputs

    target = tmp_path / "out"
    target.mkdir()
    for name in ("a.csv", "b.csv", "c.csv"):
        (target / name).write_text("old")
    real_replace = outputs.os.replace
    moved: list[str] = []

    def replace(src, dst):
        if not moved:
            signal.raise_signal(signal.SIGINT)  # the user's Ctrl-C, in the middle of the merge
        real_replace(src, dst)
        moved.append(str(dst))
    monkeypatch.setattr(outputs.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with outputs.output_folder(target, force=True) as tmp:
            for name in ("a.csv", "b.csv", "c.csv"):
                (tmp / name).write_text("new")
    assert [(target / n).read_text() for n in ("a.csv", "b.csv", "c.csv")] == ["new"] * 3


def test_no_verb_replaces_one_of_its_own_inputs_even_with_force(tmp_path, pairplay):
    """A new user's trial: `combine a.json b.json -o a.json --force` replaced its input a.json with the merged
    policy, silently. Now every verb whose output can be one of its inputs refuses it in one line, by any name
    the input is given (./a.json, a hard link), --force or not: combine -o, view --out, rebuild's outputs."""
    import os

    helmut = SAMPLE.with_name("sim-helmut-fmt2.mcap")
    assert pairplay("rebuild", SAMPLE, helmut, "--out", "rb", "--no-plot", cwd=tmp_path).returncode == 0
    os.replace(tmp_path / "rb" / "sim-ashley.policy.json", tmp_path / "a.json")
    os.replace(tmp_path / "rb" / "sim-helmut-fmt2.policy.json", tmp_path / "b.json")
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    (tmp_path / "out").mkdir()
    shutil.copy(SAMPLE, tmp_path / "out" / "learning-curves.png")  # an MCAP file by any name is a recording
    os.link(tmp_path / "a.json", tmp_path / "a-link.json")
    cases = [("combine", "a.json", "b.json", "-o", "a.json"), ("combine", "a.json", "b.json", "-o", "./a.json"),
             ("combine", "a-link.json", "b.json", "-o", "a.json"),
             ("view", "--recording", "rec.mcap", "--out", "rec.mcap"),
             ("rebuild", "out/learning-curves.png", "--out", "out")]
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    for args in cases:
        r = pairplay(*args, "--force", cwd=tmp_path)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, (args, r.stderr)
        assert "is one of the inputs; an input is never replaced, --force or not" in r.stderr, (args, r.stderr)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_a_folder_named_dot_is_written_into(tmp_path, pairplay):
    """`rebuild --out .` was a traceback after the last change (no folder beside `.` can be named after it),
    and `study --out . --force` one before it: such a folder is filled from a temporary folder inside it."""
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    r = pairplay("rebuild", "rec.mcap", "--out", ".", "--no-plot", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = pairplay("study", "--out", ".", "--force", "--games", "1", "--rounds", "3", "--personas", "blind",
                 "--eval-rounds", "1", "-q", cwd=tmp_path)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    names = {p.name for p in tmp_path.iterdir()}
    assert {"rec.mcap", "rec.policy.json", "rec.curve.csv", "report.md"} <= names
    # no temporary folder left; each verb's manifest of what it wrote there
    assert sorted(n for n in names if n.startswith(".")) == [".pairplay-rebuild.manifest", ".pairplay-study.manifest"]


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_a_forced_rebuild_of_fewer_recordings_keeps_none_of_the_earlier_ones_outputs(tmp_path, pairplay):
    """A trial: `rebuild A B C --out D`, then `rebuild A --out D --force`: B's and C's policies and curves stayed
    in D beside A's new ones (and the figure of A alone), one folder of two runs. rebuild's --out may hold the
    user's files, so its patterns alone cannot tell its own: it lists what it wrote in its manifest, and
    --force removes what an earlier rebuild wrote there and this one does not; the user's files stay, one
    named like a policy too. Without --force, a rebuild of another recording adds to the folder (and to the
    manifest, so a later --force removes those as well)."""
    for k, name in enumerate("ABCE"):  # four sessions (one session in two files is refused: replay/onesession.py)
        another_session(tmp_path / f"{name}.mcap", k, SAMPLE)
    assert pairplay("rebuild", "A.mcap", "B.mcap", "C.mcap", "--out", "D", cwd=tmp_path).returncode == 0
    d = tmp_path / "D"
    (d / "notes.txt").write_text("the user's")
    (d / "mine.policy.json").write_text("the user's, named like a policy")
    r = pairplay("rebuild", "A.mcap", "--out", "D", "--force", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ours = ["A.curve.csv", "A.policy.json", "learning-curves.png"]
    assert _files(d) == sorted([".pairplay-rebuild.manifest", *ours, "mine.policy.json", "notes.txt"])
    r = pairplay("rebuild", "E.mcap", "--out", "D", "--no-plot", cwd=tmp_path)  # added beside, not replacing
    assert r.returncode == 0 and (d / "E.policy.json").exists() and (d / "A.policy.json").exists(), r.stderr
    r = pairplay("rebuild", "A.mcap", "--out", "D", "--force", cwd=tmp_path)
    assert r.returncode == 0 and _files(d) == sorted([".pairplay-rebuild.manifest", *ours, "mine.policy.json",
                                                       "notes.txt"]), _files(d)


def test_a_manifest_names_no_file_outside_its_writers_own(tmp_path):
    """An output folder's manifest is read, not trusted: a file it lists is removed by a --force run only if
    the writer's patterns name it too, inside the folder (a forged or garbled manifest removed nothing else)."""
    out = tmp_path / "D"
    out.mkdir()
    (out / "notes.txt").write_text("the user's")
    (tmp_path / "outside.policy.json").write_text("the user's")
    (out / ".m.json").write_text('{"format": "pairplay.outputs/1", "files": ["notes.txt", "../outside.policy.json", '
                                 '"old.policy.json"]}')
    (out / "old.policy.json").write_text("an earlier run's")
    with output_folder(out, force=True, owned=("*.policy.json",), among_others=True, manifest=".m.json") as tmp:
        (tmp / "new.policy.json").write_text("this run's")
    assert _files(out) == [".m.json", "new.policy.json", "notes.txt"] and (tmp_path / "outside.policy.json").exists()
    (out / ".m.json").write_text("not json")  # unreadable: nothing is taken from it
    (out / "other.policy.json").write_text("the user's")
    with output_folder(out, force=True, owned=("*.policy.json",), among_others=True, manifest=".m.json") as tmp:
        (tmp / "newer.policy.json").write_text("this run's")
    assert _files(out) == [".m.json", "new.policy.json", "newer.policy.json", "notes.txt", "other.policy.json"]


def test_a_manifests_ignored_entries_are_named_in_one_warning(tmp_path, caplog):
    """Before: a tampered manifest (`../victim.x`, an absolute path, a file not named like the writer's outputs)
    removed nothing outside, but said nothing: the entries were dropped silently. Now they are named in one
    warning; the writer's own entries are still read (an earlier run's stale output goes)."""
    import logging

    out = tmp_path / "D"
    out.mkdir()
    (tmp_path / "victim.x").write_text("the user's")
    (out / "notes.txt").write_text("the user's")
    (out / "old.policy.json").write_text("an earlier run's")
    (out / ".m.json").write_text(json.dumps({"format": "pairplay.outputs/1", "files": [
        "../victim.x", str(tmp_path / "victim.x"), "notes.txt", "old.policy.json"]}))
    with caplog.at_level(logging.WARNING, logger="pairplay.outputs"):
        with output_folder(out, force=True, owned=("*.policy.json",), among_others=True, manifest=".m.json") as tmp:
            (tmp / "new.policy.json").write_text("this run's")
    said = [r.getMessage() for r in caplog.records if "ignored" in r.getMessage()]
    assert len(said) == 1, [r.getMessage() for r in caplog.records]
    assert all(repr(e) in said[0] for e in ("../victim.x", str(tmp_path / "victim.x"), "notes.txt")), said
    assert "old.policy.json" not in said[0] and str(out / ".m.json") in said[0] and "3 entries" in said[0]
    assert _files(out) == [".m.json", "new.policy.json", "notes.txt"] and (tmp_path / "victim.x").exists()


def test_a_killed_writers_temporaries_are_removed_by_the_next_writer_and_a_live_ones_stay(tmp_path):
    """A trial: SIGKILL during `rebuild --force` left `.<out>.<pid>.<hex>.tmp` folders (up to ~1 MB) beside
    --out, and later runs left them there for good. The next writer of the same output removes those of a
    process that is gone; a live process's temporary stays (it is being written)."""
    import os

    from pairplay.outputs import output_folder, write_text

    out = tmp_path / "out"
    dead = tmp_path / ".out.99999999.abcdef.tmp"  # above every pid_max: no such process
    (dead / "sub").mkdir(parents=True)
    (dead / "sub" / "policy.json").write_text("{}")
    live = tmp_path / f".out.{os.getppid()}.abcdef.tmp"
    live.mkdir()
    dead_file = tmp_path / ".report.md.99999999.a1b2c3.tmp"
    dead_file.write_text("half")
    not_ours = tmp_path / ".out.99999997.zz.tmp"  # a dead pid, but not a name _temp_name gives (a trial)
    (not_ours / "important.txt").parent.mkdir()
    (not_ours / "important.txt").write_text("the user's")
    with output_folder(out) as tmp:
        (tmp / "a.txt").write_text("a")
    write_text(tmp_path / "report.md", "whole")
    assert not dead.exists() and not dead_file.exists()
    assert live.is_dir() and (not_ours / "important.txt").read_text() == "the user's"
    assert (out / "a.txt").read_text() == "a" and (tmp_path / "report.md").read_text() == "whole"



def test_a_dead_writers_temporaries_are_removed_through_the_public_helper_the_combiner_uses_too(tmp_path):
    """services/biasfile.py removed a killed combination's temporaries through outputs' private
    `_remove_dead_temps`: the helper is public (`remove_dead_temps`), one function, and the combiner's is it."""
    from pairplay import outputs
    from pairplay.services import biasfile

    dead = tmp_path / ".x.policy.json.99999999.abcdef.tmp"  # above every pid_max: no such process
    dead.write_text("half")
    outputs.remove_dead_temps(tmp_path / "x.policy.json")
    assert not dead.exists()
    assert biasfile.remove_dead_temps is outputs.remove_dead_temps and not hasattr(outputs, "_remove_dead_temps")

ONE_GAME_STUDY = """[study]
id = "one"
title = "one game"
seed = 0
ignore_window_ms = 1500
wrong_suggestion_button = true
robot = "none"

[[phase]]
id = "phase1"
title = "phase 1"
games = 1
rounds = 1
algorithm = "q-learning"
preset = "human-phase1"
players = "new"
"""
STUDY_ARGS = ("--games", "1", "--rounds", "3", "--eval-rounds", "1", "--train-only")

# verb -> (its first run into D, its forced run into D (writing fewer files than the first), a user's file named
# like one of its outputs, an earlier run's output the forced run no longer writes, the verb's manifest); the forced
# run without -q, which would keep its warnings (what it left) to itself
FORCED = {
    "study": (("study", "--out", "D", "--personas", "blind,deaf", *STUDY_ARGS, "-q"),
              ("study", "--out", "D", "--personas", "blind", *STUDY_ARGS),
              "policies/mine/game-01.json", "policies/deaf/game-00.json", ".pairplay-study.manifest"),
    "counterfactual": (("counterfactual", "rec.mcap", "--policy", "same", "--seeds", "2", "--out", "D", "-q"),
                       ("counterfactual", "rec.mcap", "--fit-only", "--out", "D"),
                       "alice.usermodel.json", "counterfactual.csv", ".pairplay-counterfactual.manifest"),
    "report": (("report", "pf", "--out", "D"), ("report", "pf", "--out", "D"),
               "users-mine.png", "users-phase9.png", ".pairplay-report.manifest"),
}


@pytest.mark.parametrize("verb", FORCED)
def test_a_forced_folder_verb_removes_only_what_it_wrote_and_says_what_it_left(verb, tmp_path, pairplay):
    """A trial: `study --force`, `counterfactual --force` and `report --force` removed every file their
    patterns name that the run did not write: a user's notes named like a game file, their own `users-*.png`
    or `*.usermodel.json`, gone. Each folder verb now keeps a manifest of what it wrote there (as rebuild and
    sweep did); --force removes an earlier run's stale file it lists, keeps the user's, and says so."""
    first, forced, users, stale, manifest = FORCED[verb]
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    if verb == "report":  # a study folder with one scripted game played over the bus
        (tmp_path / "one.toml").write_text(ONE_GAME_STUDY)
        for args in (("protocol", "init", "pf", "--study", "one.toml"), ("protocol", "register", "pf"),
                     ("protocol", "pilot", "pf", "--personas", "blind", "-q")):
            r = pairplay(*args, cwd=tmp_path)
            assert r.returncode == 0, r.stderr
    r = pairplay(*first, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    d = tmp_path / "D"
    if verb == "report":  # an earlier report's figure 7.6 of a phase this one no longer has
        (d / stale).write_bytes(b"an earlier report's")
        if (d / manifest).is_file():
            listed = json.loads((d / manifest).read_text())
            (d / manifest).write_text(json.dumps({**listed, "files": sorted([*listed["files"], stale])}))
    assert (d / stale).is_file()
    (d / users).parent.mkdir(parents=True, exist_ok=True)
    (d / users).write_text("the user's, named like an output")
    (d / "notes.txt").write_text("the user's")
    r = pairplay(*forced, "--force", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (d / users).is_file(), f"--force removed the user's {users}"
    assert (d / users).read_text() == "the user's, named like an output" and (d / "notes.txt").is_file()
    assert not (d / stale).exists()  # an earlier run's, listed: stale, removed
    lines = [line for line in r.stderr.splitlines() if users in line]
    assert len(lines) == 1 and "left 1 file" in lines[0] and manifest in lines[0], r.stderr
    assert users not in json.loads((d / manifest).read_text())["files"]  # still not ours: a later --force keeps it


def test_a_writer_that_names_its_own_files_keeps_a_manifest(tmp_path):
    """The patterns alone cannot tell a writer's files from the user's: output_folder refuses `owned` without
    a `manifest` (a programming error), so no folder writer can go back to removing by pattern alone."""
    with pytest.raises(ValueError, match="manifest"):
        with output_folder(tmp_path / "D", owned=("*.csv",)):
            pass
    assert list(tmp_path.iterdir()) == []


def _writers():
    """Every verb that fills a folder of outputs: (verb, its patterns, its manifest, among others' files)."""
    from pairplay.cli.rebuild import MANIFEST as REBUILD_MANIFEST, REBUILD_OUTPUTS
    from pairplay.report.counterfactual import COUNTERFACTUAL_MANIFEST, COUNTERFACTUAL_OUTPUTS
    from pairplay.report.human import HUMAN_MANIFEST, HUMAN_OUTPUTS
    from pairplay.report.study import STUDY_MANIFEST, STUDY_OUTPUTS
    from pairplay.report.sweep import MANIFEST as SWEEP_MANIFEST, SWEEP_OUTPUTS
    return [("study", STUDY_OUTPUTS, STUDY_MANIFEST, False), ("report", HUMAN_OUTPUTS, HUMAN_MANIFEST, False),
            ("counterfactual", COUNTERFACTUAL_OUTPUTS, COUNTERFACTUAL_MANIFEST, False),
            ("rebuild", REBUILD_OUTPUTS, REBUILD_MANIFEST, True), ("sweep", SWEEP_OUTPUTS, SWEEP_MANIFEST, True)]


def _shared_pairs():
    """(first writer, second writer, a file name both write): each pattern of one made a name ('*' -> 'x')
    that the other's patterns name too (study and report both write report.md and merged.png)."""
    from pairplay.outputs import is_owned
    pairs = []
    for a in _writers():
        for b in _writers():
            if a[0] == b[0]:
                continue
            for pattern in a[1]:
                name = pattern.replace("*", "x")
                if is_owned(name, b[1]):
                    pairs.append((a, b, name))
    return pairs


def test_the_writers_share_names_so_the_check_is_needed():
    shared = {(a[0], b[0], name) for a, b, name in _shared_pairs()}
    assert {("report", "study", "report.md"), ("study", "report", "merged.png")} <= shared


@pytest.mark.parametrize("a,b,name", _shared_pairs(), ids=lambda v: v[0] if isinstance(v, tuple) else v)
def test_a_file_another_verbs_manifest_lists_is_never_replaced_by_a_forced_writer(a, b, name, tmp_path):
    """`study --out R --force`, R holding what `pairplay report --out R` wrote (report.md, merged.png: the two
    write those names), replaced them silently. A file another writer's manifest lists is not this writer's to
    replace, --force or not: refused before the work, naming the file and the verb that wrote it."""
    out = tmp_path / "out"
    with output_folder(out, owned=a[1], among_others=a[3], manifest=a[2]) as tmp:
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp / name).write_text(f"{a[0]}'s\n")
    with pytest.raises(OutputError, match=rf"was written by `pairplay {a[0]}` \(its manifest {a[2]} lists it\)") \
            as info:
        with output_folder(out, force=True, owned=b[1], among_others=b[3], manifest=b[2]) as tmp:
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text(f"{b[0]}'s\n")
    assert str(out / name) in str(info.value)
    assert (out / name).read_text() == f"{a[0]}'s\n"


def test_study_force_refuses_a_folder_holding_a_reports_files_before_any_work(tmp_path, capsys):
    """The new user's case, by the command line: one line naming the report's file and its verb, exit 2."""
    from pairplay.cli.main import main
    from pairplay.report.human import HUMAN_MANIFEST, HUMAN_OUTPUTS
    out = tmp_path / "r"
    with output_folder(out, owned=HUMAN_OUTPUTS, manifest=HUMAN_MANIFEST) as tmp:
        (tmp / "report.md").write_text("the human-world report\n")
        (tmp / "merged.png").write_bytes(b"\x89PNG")
    assert main(["study", "--quiet", "--train-only", "--personas", "blind", "--games", "1", "--rounds", "5",
                 "--out", str(out), "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "`pairplay report`" in err and str(out / "merged.png") in err, err
    assert (out / "report.md").read_text() == "the human-world report\n"
    assert sorted(p.name for p in out.iterdir()) == sorted([HUMAN_MANIFEST, "merged.png", "report.md"])
