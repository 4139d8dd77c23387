"""Every copy of a participant's data a verb writes beyond the study folder's own places is journaled, and their
deletion erases it while it is pairplay's unchanged file, and names it otherwise (replay/copies.py).

A study played by scripted participants on a real bus (test_protocol's `played`), then the verbs run as a
researcher runs them (`pairplay ...` through cli.main), on the study's real recordings and policies.
"""

from __future__ import annotations

import json
import os
import signal
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_protocol import copy_study, names_anywhere, played  # noqa: F401  (the module's fixture)

from pairplay.cli.main import main
from pairplay.schemas import journal as j


def _game(data, pid: str, n: int = 0):
    return [g for g in data.games_of(pid) if g.ended is not None and g.ended.policy][n]


def _copies(data) -> list[j.CopyWritten]:
    return [e for e in data.read_journal() if isinstance(e, j.CopyWritten)]


def test_every_verb_that_writes_a_participants_data_elsewhere_journals_it_and_the_deletion_erases_it(
        played, tmp_path, capsys):  # noqa: F811
    """`participant delete STUDY p01 --yes` knew only the exports: a report --out elsewhere, a rebuild, a view, a
    counterfactual, a recover -o, a combine -o of p01's recordings and policies stayed, unnamed, after "deleted".
    Each is journaled now (whose data, the verb, the path, its SHA-256), and the deletion erases each one still
    byte-identical, saying so; nothing of p01 is left in the study folder or where the verbs wrote."""
    data = copy_study(played, tmp_path)
    folder, out = data.folder, tmp_path / "elsewhere"
    g1, g2 = _game(data, "p01", 0), _game(data, "p01", 1)
    rec1, rec2 = folder / g1.recording, folder / g2.recording
    cut = tmp_path / "cut.mcap"  # a cut copy for recover to complete (a complete one it does not copy)
    cut.write_bytes(rec2.read_bytes()[: rec2.stat().st_size * 2 // 3])
    other = _game(data, "p02", 0)
    runs = [["report", str(folder), "--out", str(out / "report")],
            ["rebuild", str(rec1), "--out", str(out / "rebuilt")],
            ["view", "--recording", str(rec1), "--out", str(out / "view.rrd")],
            ["counterfactual", str(rec1), "--fit-only", "--out", str(out / "cf")],
            ["recover", str(rec2), "-o", str(out / "recovered.mcap")],
            ["combine", *(str(folder / g.ended.policy) for g in (g1, _game(data, "p01", 1), other,
                                                                 _game(data, "p02", 1))), "-o",
             str(out / "merged.json")]]  # two policies a participant: a merge weighs each by its profile
    for argv in runs:
        assert main([*argv, "--quiet"]) == 0, (argv, capsys.readouterr())
    journaled = {e.path: e for e in _copies(data)}
    written = sorted(str(f.resolve()) for f in out.rglob("*") if f.is_file() and ".pairplay-" not in f.name)
    assert sorted(journaled) == written, (sorted(journaled), written)
    assert all("p01" in e.participants for e in journaled.values())
    assert journaled[str((out / "merged.json").resolve())].participants == ["p01", "p02"]
    assert journaled[str((out / "view.rrd").resolve())].verb == "view"
    capsys.readouterr()
    assert main(["participant", "delete", str(folder), "p01", "--yes"]) == 0
    said = capsys.readouterr()
    assert "NOT erased" not in said.err, said.err
    for path in written:
        assert not Path(path).exists(), path
        assert [x for x in said.out.splitlines() if x.startswith("erased") and path in x], (path, said.out)
    assert not names_anywhere(folder, "p01") and not names_anywhere(out, "p01")
    last = json.loads((folder / "journal.jsonl").read_text().splitlines()[-1])
    assert last["copies_erased"] == len(written)


def test_a_copy_changed_since_pairplay_wrote_it_or_moved_is_named_not_erased(played, tmp_path, capsys):  # noqa: F811
    """The journal's SHA-256 of an export was written and never read. An export (or a verb's copy) still
    byte-identical is pairplay's own file: erased, its line says so; one changed since is named as changed and
    kept; one gone from there is named as not there now. A copy of two participants' data that stays keeps its
    journal line for the other one, without the deleted id."""
    data = copy_study(played, tmp_path)
    folder, out = data.folder, tmp_path / "elsewhere"
    same, edited, moved = out / "same.zip", out / "edited.zip", out / "moved.zip"
    for path in (same, edited, moved):
        assert main(["participant", "export", str(folder), "p01", "-o", str(path), "--quiet"]) == 0
    edited.write_bytes(edited.read_bytes() + b"a researcher's note")
    moved.rename(out / "handed-on.zip")
    assert main(["report", str(folder), "--out", str(out / "report"), "--quiet"]) == 0
    notes = out / "report" / "report.md"
    notes.write_text(notes.read_text() + "\nseen with the supervisor\n")
    capsys.readouterr()
    assert main(["participant", "delete", str(folder), "p01", "--yes", "--quiet"]) == 0
    said = capsys.readouterr()
    assert not same.exists() and edited.is_file() and notes.is_file()
    assert not (out / "report" / "games.png").exists()  # the report's unchanged files go
    lines = said.err.splitlines()
    [e] = [x for x in lines if str(edited) in x]
    assert e.startswith("NOT erased") and "changed since pairplay wrote it" in e and "export of p01" in e, e
    [m] = [x for x in lines if str(moved) in x]
    assert m.startswith("NOT erased") and "not there now" in m, m
    [r] = [x for x in lines if str(notes) in x]
    assert "`pairplay report`" in r and "changed since" in r, r
    assert not [x for x in lines if str(same) in x]
    kept = [e for e in _copies(data) if e.path == str(notes.resolve())]
    assert kept and all("p01" not in e.participants and "p02" in e.participants for e in kept)
    capsys.readouterr()
    assert main(["participant", "delete", str(folder), "p02", "--yes"]) == 0
    assert [x for x in capsys.readouterr().err.splitlines() if str(notes) in x and "NOT erased" in x]


def test_a_copy_into_the_folders_own_places_is_not_journaled(played, tmp_path, capsys):  # noqa: F811
    """What the deletion erases by itself needs no line: the report in report/, a view or a recover beside the
    recording (named after its game)."""
    data = copy_study(played, tmp_path)
    folder = data.folder
    rec = folder / _game(data, "p01").recording
    assert main(["report", str(folder), "--quiet"]) == 0
    assert main(["view", "--recording", str(rec), "--quiet"]) == 0
    assert rec.with_suffix(".rrd").is_file()
    assert _copies(data) == []


def test_no_other_verbs_folder_output_takes_a_file_of_a_study_folder(played, tmp_path, capsys):  # noqa: F811
    """A people's study folder kept no manifest, so the cross-verb check (pairplay/outputs.py check_theirs) did
    not cover it: `rebuild REC --out STUDY/policies --force` replaced the game's policy in the study (and left
    a curve beside it), and `study --out STUDY --force` was let into the folder. The study folder's manifest
    (.pairplay-protocol.manifest, written from the journal at each of its lines) lists its files; a writer's
    output that one of its patterns names is refused, in the folder or below it, --force or not."""
    from pairplay.outputs import OutputError, check_output_folder, check_theirs, manifest_name
    from pairplay.report.study import STUDY_MANIFEST, STUDY_OUTPUTS

    data = copy_study(played, tmp_path)
    folder = data.folder
    data.append(j.GamePaused(session="none", participant="p01"))  # a folder made before: its manifest comes
    g = _game(data, "p01")  # at its next journal line
    policy = folder / g.ended.policy
    before = policy.read_bytes()
    capsys.readouterr()
    assert main(["rebuild", str(folder / g.recording), "--out", str(folder / "policies"), "--force",
                 "--no-plot"]) == 2
    err = capsys.readouterr().err.strip()
    # refused sooner now, as any output inside a people's study folder (tests/test_study_folder_outputs.py)
    assert len(err.splitlines()) == 1 and "only `pairplay protocol` writes" in err and str(folder / "policies") in err, err
    assert policy.read_bytes() == before and not list((folder / "policies").glob("*.curve.csv"))
    with pytest.raises(OutputError, match=r"merged/phase2-bias.policy.json.*|was written by `pairplay protocol`"):
        check_output_folder(folder, True, STUDY_OUTPUTS, STUDY_MANIFEST)  # what `study --out STUDY --force` checks
    # a made-up writer of one of the study's tables: refused, naming it
    with pytest.raises(OutputError, match="was written by `pairplay protocol`") as info:
        check_theirs(folder, ("sessions.csv",), manifest_name("made-up"))
    assert str(folder / "sessions.csv") in str(info.value)
    data.delete_participant("p01")  # the manifest follows the journal: their games are listed no more
    listed = json.loads((folder / ".pairplay-protocol.manifest").read_text())["files"]
    assert g.recording not in listed and "journal.jsonl" in listed and not names_anywhere(folder, "p01")


@pytest.mark.skipif(not (os.geteuid() == 0 and shutil.which("unshare")), reason="needs root and unshare")
def test_a_copy_whose_study_journal_cannot_take_its_line_is_not_made(played, tmp_path):  # noqa: F811
    """A study folder on a read-only mount: `rebuild` of its recording elsewhere would be a copy their deletion
    never knew. Refused before any work, one line naming the journal as typed; nothing written."""
    data = copy_study(played, tmp_path)
    rec = Path(_game(data, "p01").recording)
    mount = 'mount --bind "$0" "$0" && mount -o remount,ro,bind "$0" && exec "$@"'
    r = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", mount, "study",
                        sys.executable, "-m", "pairplay", "rebuild", str("study" / rec), "--out", "rebuilt"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "(study/journal.jsonl)" in r.stderr and "Read-only file system" in r.stderr, r.stderr
    assert not (tmp_path / "rebuilt").exists()


def test_a_copy_is_journaled_after_the_verb_itself_wrote_the_journal_and_refused_while_another_writes_the_folder(
        played, tmp_path, capsys):  # noqa: F811
    """Two branches met here (copies, studyguard): a verb's copy line was appended through the StudyData read when
    the verb began, so a journal written since (report's own PolicyBuilt lines; the merge's test) was refused as
    a stale copy after the copy was made; and a copy made while a server held the folder could not take its line
    at all. Now the line is written through the journal read afresh under the folder's writer lock, and a folder
    another pairplay writes is refused before the copy is made, in one line naming who holds it."""
    from pairplay import folderlock
    from pairplay.replay.copies import Copies
    from pairplay.replay.studydata import StudyData

    data = copy_study(played, tmp_path)
    folder, out = data.folder, tmp_path / "elsewhere"
    rec1 = folder / _game(data, "p01", 0).recording
    copies = Copies("rebuild", [rec1])
    with StudyData(folder, writer="test") as other:  # the verb's own journal line meanwhile
        other.append(j.ParticipantRegistered(participant="p09", joins=other.study.phase[0].id))
    out.mkdir()
    (out / "policy.json").write_bytes(b"{}")
    copies.journal([out / "policy.json"])
    assert [e.path for e in _copies(StudyData(folder))] == [str((out / "policy.json").resolve())]
    held = folderlock.take(folder, "protocol serve")  # a running server's hold, in this process
    try:
        before = (folder / "journal.jsonl").read_bytes()
        capsys.readouterr()
        assert main(["rebuild", str(rec1), "--out", str(out / "rebuilt")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "another pairplay writes this study folder: protocol serve" in err, err
        assert not (out / "rebuilt").exists() and (folder / "journal.jsonl").read_bytes() == before
    finally:
        folderlock.release(held)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_a_stopped_view_waits_for_its_busy_study_folder_exits_at_once_and_keeps_no_copy(
        played, tmp_path, sig):  # noqa: F811
    """A view of a study's game stopped by a signal journals its partial copy; a short holder of the folder (an
    export) made it wait the folder lock's whole 8 s after the signal (its handler only sets the stop event:
    services/bus.py stop_on_signals), then exit 2 saying the folder was busy, its partial .rrd left unjournaled.
    Now the wait ends on the signal (pairplay/folderlock.py), the copy is not kept, and the exit is the signal's."""
    from pairplay import folderlock
    from pairplay.replay.studydata import StudyData

    data = copy_study(played, tmp_path)
    rec = data.folder / _game(data, "p01", 0).recording
    rrd = tmp_path / "out" / "view.rrd"
    view = subprocess.Popen([sys.executable, "-m", "pairplay", "view", "-v", "--recording", str(rec), "--speed", "1",
                             "--out", str(rrd)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    held = None
    try:
        line = view.stderr.readline()  # past its check (the folder free then): it draws
        assert "drawing" in line, line + view.stderr.read()
        held = folderlock.take(data.folder, "participant export")  # a short holder, as the signal comes
        before = (data.folder / "journal.jsonl").read_bytes()
        sent = time.monotonic()
        view.send_signal(sig)
        out, err = view.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        view.kill()
        folderlock.release(held)
    lines = [x for x in err.splitlines() if not x.startswith("INFO ")]
    assert view.returncode == 128 + sig and took < folderlock.WAIT_S / 2, (view.returncode, took, err)
    said = "Ctrl-C" if sig == signal.SIGINT else signal.Signals(sig).name  # every line's word (pairplay/signals.py said)
    assert len(lines) == 1 and lines[0].startswith(f"pairplay view: interrupted ({said}) after ")
    assert "nothing saved" in lines[0] and "study folder is busy" in lines[0], lines
    assert not list(rrd.parent.glob("*")), list(rrd.parent.glob("*"))  # no copy the deletion would not know
    assert (data.folder / "journal.jsonl").read_bytes() == before and not _copies(StudyData(data.folder))


@pytest.mark.parametrize("how", ["busy", "signal"])
def test_a_copy_whose_journal_line_cannot_be_written_once_it_is_made_is_removed_and_said(
        played, tmp_path, capsys, monkeypatch, how):  # noqa: F811
    """Each verb's outputs are renamed into place before their journal line, which takes the study folder's
    writer lock again: a short holder (a register, an export) that held it past the wait, or a signal during the
    wait, left the copy there, unjournaled, a copy its participants' deletion would never know (exit 2 saying the
    folder was busy, or 130 saying "nothing more was written"). Now every output still waiting for its line is
    removed and the one line says so; a report's line is written under the lock its report was written under."""
    from pairplay import folderlock
    from pairplay.replay import copies
    from pairplay.replay.studydata import StudyData

    data = copy_study(played, tmp_path)
    folder, out = data.folder, tmp_path / "elsewhere"
    g1, other = _game(data, "p01", 0), _game(data, "p02", 0)
    rec1, cut = folder / g1.recording, folder / _game(data, "p01", 1).recording  # a game's recording cut: recover copies it
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size * 2 // 3])
    runs = {"rebuild": ["rebuild", rec1, "--out", out / "rebuilt"],
            "view": ["view", "--recording", rec1, "--out", out / "view.rrd"],
            "counterfactual": ["counterfactual", rec1, "--fit-only", "--out", out / "cf"],
            "recover": ["recover", cut, "-o", out / "recovered.mcap"],
            "combine": ["combine", *(folder / g.ended.policy for g in (g1, _game(data, "p01", 1), other,
                                                                       _game(data, "p02", 1))), "-o", out / "merged.json"],
            "report": ["report", folder, "--out", out / "report"]}
    monkeypatch.setattr(folderlock, "WAIT_S", 0.3)
    real, held = copies.StudyData, []

    def busy_meanwhile(*args, **kw):  # the journal line's StudyData (a writer): another holds the folder now
        if kw.get("writer"):
            if how == "signal":
                raise KeyboardInterrupt  # as a signal during the wait (pairplay/folderlock.py)
            held.append(folderlock.take(folder, "participant export"))
        return real(*args, **kw)

    monkeypatch.setattr(copies, "StudyData", busy_meanwhile)
    before = (folder / "journal.jsonl").read_bytes()
    try:
        for verb, argv in runs.items():
            code = main([str(a) for a in [*argv, "--quiet"]])
            while held:
                folderlock.release(held.pop())
            err = [x for x in capsys.readouterr().err.strip().splitlines() if "waiting up to" not in x]
            left = sorted(str(f) for f in out.rglob("*") if f.is_file() and ".pairplay-" not in f.name)
            if verb == "report":  # journaled under its own lock: nobody came between
                assert code == 0 and len(_copies(StudyData(folder))) == len(left) > 0, (code, err)
                continue
            assert code == (2 if how == "busy" else 130), (verb, code, err)
            assert len(err) == 1 and "Traceback" not in err[0], (verb, err)
            assert left == [], (verb, left)  # no copy the deletion would not know
            said = "another pairplay writes this study folder: participant export" if how == "busy" else "interrupted"
            assert err[0].startswith(f"pairplay {verb}: {said}") and "; removed " in err[0], (verb, err)
            assert "whose line could not be written in their study's journal" in err[0], (verb, err)
            assert (folder / "journal.jsonl").read_bytes() == before, verb
    finally:
        for fd in held:
            folderlock.release(fd)
