"""The study with people, without a browser: plan, scripted participants on a real bus, export, delete, report.

The whole two-phase protocol (2 phase-1 participants x 2 games, the combination
through the combiner service, 4 participants in phase 2) runs with 2-round games
on a loopback Zenoh bus; every recording is then verified (fresh services, same
inputs) and the report, export and deletion are checked on the files.
"""

from __future__ import annotations

import csv
import json
import shutil
import threading
import zipfile
from pathlib import Path

import pytest

from damageutil import damage, damaged_when_written

from pairplay.replay.reader import read_log
from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.outputs import output_folder
from pairplay.report.human import HUMAN_MANIFEST, HUMAN_OUTPUTS, human_report
from pairplay.schemas import journal as j
from pairplay.schemas.policy import read_policy
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner, scripted_players
from pairplay.services.scripted import ScriptedPlayer
from pairplay.services.verify import verify_recording

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
PERSONAS = ["tatiana", "blind", "deaf", "vincent"]


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    root = tmp_path_factory.mktemp("protocol")
    data = StudyData.create(root / "study", STUDY, key_file=root / "keys.csv")
    ids = [data.register("phase1", "First Person"), data.register("phase1"), data.register("phase2"),
           data.register("phase2")]
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        runner.run_plan(scripted_players(runner, dict(zip(ids, PERSONAS))))
    return root, ids


def test_every_json_and_toml_file_a_study_writes_reads_back_under_its_strict_reader(played):
    """A study folder's files (the games' policies, the combiner's bias policy, settings.json, study.toml) read
    back through the readers that refuse a key they do not declare (tests/test_unknown_keys.py): the study
    never writes a key its reader does not know."""
    from pairplay.replay.studydata import _settings
    from pairplay.schemas.study import load_study

    root, _ = played
    folder = root / "study"
    policies = sorted(folder.rglob("*.policy.json"))
    assert [read_policy(p).format for p in policies] and any(p.parent.name == "merged" for p in policies)
    assert {p.name for p in folder.rglob("*.json")} - {p.name for p in policies} == {"settings.json"}
    assert _settings(folder / "settings.json")["key_file"]
    assert load_study(folder / "study.toml").study.id == "pilot"


def copy_study(played, tmp_path) -> StudyData:
    root, _ = played
    shutil.copytree(root / "study", tmp_path / "study")
    settings = tmp_path / "study" / "settings.json"
    shutil.copy(root / "keys.csv", tmp_path / "keys.csv")
    settings.write_text(json.dumps({"key_file": str(tmp_path / "keys.csv")}))
    return StudyData(tmp_path / "study")


def test_the_plan_runs_to_the_end_and_every_recording_verifies(played):
    root, ids = played
    data = StudyData(root / "study")
    assert data.next_step() is None
    games = list(data.state.games.values())
    assert len(games) == 2 * 2 + 4 and all(g.valid_complete for g in games)
    bias = data.state.combined["phase2"]
    assert bias.users == ["human:p01", "human:p02"] and len(bias.actions) == 24 and len(bias.decided_by) == 24
    assert set(bias.profiles) == {"human:p01", "human:p02"}
    assert (data.folder / bias.output).is_file()
    for g in games:
        log = read_log(data.folder / g.recording)
        config = log.of("SessionStarted")[0].config
        assert config.participant == f"human:{g.participant}" and config.observed_source == "first-pick"
        assert config.ignore_rule == "time"
        if g.phase == "phase2":
            assert config.algorithm == "pi-reuse" and config.policy_actions == bias.actions
        answered = log.of("QuestionnaireAnswered")
        assert len(answered) == 1 and answered[0].source == "board"
        assert ("best-round" in answered[0].answers) == (g.phase == "phase2" and g.participant in ids[:2])
        result = verify_recording(data.folder / g.recording)
        assert result.ok, (g.session, result.error, [c.mismatches[:2] for c in result.checks])
        assert (data.folder / g.ended.policy).is_file()
    chosen = [e.chosen_by for g in games if g.phase == "phase2" for e in read_log(data.folder / g.recording).of("SuggestionMade")]
    assert "bias" in chosen  # pi-reuse took suggestions from the combined policy
    # the data folder is plain files: CSV tables beside the MCAP and JSON
    with open(data.folder / "sessions.csv") as f:
        assert len(list(csv.DictReader(f))) == 8
    with open(data.folder / "participants.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["participant"] for r in rows] == ids and "First Person" not in (data.folder / "participants.csv").read_text()


def test_names_stay_in_the_key_file_outside_the_study(played, tmp_path):
    root, ids = played
    assert (root / "keys.csv").read_text().splitlines()[1].rsplit(",", 1)[0] == "p01,First Person"  # and its study (3rd cell)
    for f in (root / "study").rglob("*"):
        if f.is_file():
            assert b"First Person" not in f.read_bytes(), f
    plain = StudyData.create(tmp_path / "s", STUDY)
    with pytest.raises(StudyDataError, match="no key file"):
        plain.register("phase1", "Somebody")
    with pytest.raises(StudyDataError, match="outside the study folder"):
        StudyData.create(tmp_path / "t", STUDY, key_file=tmp_path / "t" / "keys.csv")


def test_the_plan_refuses_steps_out_of_order(tmp_path):
    data = StudyData.create(tmp_path / "s", STUDY)
    a, _b = data.register("phase1"), data.register("phase1")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        with pytest.raises(StudyDataError, match="not all played"):
            runner.combine("phase2")
        with pytest.raises(StudyDataError, match="not combined yet"):
            runner.run_game(a, "phase2", 0)
        with pytest.raises(StudyDataError, match="does not play game 3"):
            runner.run_game(a, "phase1", 2)
        with pytest.raises(StudyDataError, match="no participant"):
            runner.run_game("p09", "phase1", 0)


class Stopping(ScriptedPlayer):
    """Plays round 1 only. (An abort that crosses a touch in flight may be recorded before the touch the
    game took first: verify ends the game where its recorded SessionEnded says, test below.)"""

    def handle(self, e):
        if getattr(e, "round", 0) >= 1:
            return []
        return super().handle(e)


def aborted_in_round(tmp_path, player, round_: int, reason: str, grace_s: float = 5.0):
    """A phase-1 game of `player` that the experimenter aborts (from another thread, as the console does) when
    its round `round_` starts: (study data, participant id, the game's journaled state, the runner)."""
    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)

        def watch(e):
            if type(e).__name__ == "RoundStarted" and e.round == round_:
                threading.Thread(target=runner.abort, args=(reason, grace_s)).start()
        game = runner.run_game(pid, "phase1", 0, player, on_event=watch)
    return data, pid, game, runner


def test_an_aborted_game_is_journaled_with_its_reason_and_stays_open(tmp_path):
    # leaves the board after round 1, as a person who feels unwell
    data, pid, game, runner = aborted_in_round(tmp_path, Stopping("tatiana"), 1, "participant felt unwell")
    with pytest.raises(StudyDataError, match="needs a reason"):
        runner.abort(" ")
    assert game.ended.outcome == "aborted" and game.ended.reason == "aborted: participant felt unwell"
    assert not game.valid_complete
    step = data.next_step()
    assert (step.participant, step.phase, step.game, step.done) == (pid, "phase1", 0, False)
    assert data.session_id(pid, "phase1", 0).endswith("-r1")  # a retry gets a new recording
    result = verify_recording(data.folder / game.recording)
    assert result.ok, result


def test_an_abort_recorded_before_inputs_the_game_took_first_verifies_in_any_order_a_recorder_can_hold(tmp_path):
    """A recorder writes each source in its own order, but the sources among each other as they reach it: under
    load the experimenter's SessionAborted was written before board picks the game had taken first, and verify
    fed it there: the game ended a turn early and the recording FAILed (1 of 4 lowest-deps runs at load 60). The
    game's recorded SessionEnded says where the abort was taken; verify ends the game there, whatever the file's
    order of the abort among the other sources' events."""
    from pairplay.services.verify import verify_events

    data, _, game, _ = aborted_in_round(tmp_path, Stopping("tatiana"), 1, "participant felt unwell")
    events = [r.event for r in read_log(data.folder / game.recording).events]
    abort = next(i for i, e in enumerate(events) if type(e).__name__ == "SessionAborted")
    others = events[:abort] + events[abort + 1:]
    assert verify_events(events).ok
    moved = [i for i in range(1, abort) if others[i - 1].source == "board"]  # before board picks taken first
    assert moved, "no board input before the abort: nothing to move it ahead of"
    for at in moved[-6:]:
        held = others[:at] + [events[abort]] + others[at:]
        assert verify_events(held).ok, (at, verify_events(held))


def test_an_abort_the_game_takes_after_its_grace_still_ends_with_the_experimenters_reason(tmp_path, monkeypatch):
    """The abort's grace (5 s) is wall time, and a loaded machine can outlast it before the game takes the abort:
    the session was then stopped and its end said "aborted: stopped by the experimenter", the reason given lost
    (the one wait found that could have failed the test above, once in a suite). Here the game does not take
    the abort (it waits, NotYet)."""
    from pairplay.services.game import GameLogic
    from pairplay.services.node import NotYet

    takes = GameLogic._control

    def late(self, e):
        if type(e).__name__ == "SessionAborted":
            raise NotYet
        return takes(self, e)
    monkeypatch.setattr(GameLogic, "_control", late)
    data, _, game, _ = aborted_in_round(tmp_path, Stopping("tatiana"), 1, "participant felt unwell", grace_s=0.2)
    assert game.ended.outcome == "aborted" and game.ended.reason == "aborted: participant felt unwell"
    assert verify_recording(data.folder / game.recording).ok


class Idle(ScriptedPlayer):
    """Picks nothing: the game is aborted in its first round."""

    def handle(self, e):
        return []


def test_a_game_aborted_in_its_first_round_gets_no_policy_of_0_rounds(tmp_path):
    """Before: its recording was rebuilt into policies/ as a policy of 0 rounds (replay/check.py
    no_whole_round: an input that yields nothing gives no output)."""
    data, _, game, _ = aborted_in_round(tmp_path, Idle("tatiana"), 0, "the participant had to leave")
    assert game.ended.outcome == "aborted" and game.ended.rounds_played == 0
    assert game.ended.policy == "" and not list((data.folder / "policies").rglob("*.json"))
    assert verify_recording(data.folder / game.recording).ok  # its whole (short) life verifies


@pytest.mark.parametrize("how", ["chunk", "undecodable"])
def test_a_game_whose_recording_is_damaged_when_read_back_gets_no_policy_and_says_why(tmp_path, monkeypatch, caplog,
                                                                                     how):
    """The study's runner read each game's fresh recording back (game_end) with no damage check: a recording
    that lost a chunk, or whose Q update does not decode, was rebuilt into a partial policy journaled as the
    game's, its GameEnded saying nothing. Now no policy is built from it (as build_missing_policies refuses
    one), its GameEnded's reason says why in the reader's words, and the runner says it (a warning)."""
    import pairplay.services.protocol as protocol

    # the real game's recording, finished and closed, loses its first Q update (the chunk that holds it, or its
    # bytes): its game's end is kept (the middle chunk may hold it, as chunks' sizes vary with time)
    damaged_when_written(monkeypatch, protocol, how, tag="QUpdated")
    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus, questionnaire_timeout_s=60.0)
        game = runner.run_game(pid, "phase1", 0, scripted_players(runner, {pid: "tatiana"})(pid, "phase1", 0))
    words = {"chunk": "recording damaged: chunk ",
             "undecodable": "recording damaged: 1 message in it does not decode ("}
    assert game.ended.outcome == "completed" and game.ended.policy == "", game.ended
    assert not list((data.folder / "policies").rglob("*.json"))
    assert words[how] in game.ended.reason and game.ended.reason.endswith(": no policy built"), game.ended.reason
    assert any(game.session in r.getMessage() and "no policy built" in r.getMessage()
               for r in caplog.records if r.levelname == "WARNING"), caplog.text
    [line] = StudyData(data.folder).build_missing_policies()  # the next start says it again: no policy from it
    assert line.startswith(f"{game.session}: completed, but no policy built: its recording ") and "partial" in line


def test_export_holds_everything_of_one_participant_with_a_readme(played, tmp_path):
    data = copy_study(played, tmp_path)
    from pairplay.replay.wal import JournalWriter
    killed = data.games_of("p02")[0]  # a recorder killed in that game left its journal: their data too
    JournalWriter(data.folder / killed.recording, killed.session).close()
    path = data.export_participant("p02")
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        readme = z.read("README.txt").decode()
        answers = list(csv.DictReader(z.read("answers.csv").decode().splitlines()))
        lines = [json.loads(x) for x in z.read("journal.jsonl").decode().splitlines()]
    sessions = [g.session for g in data.games_of("p02")]
    assert {f"recordings/{s}.mcap" for s in sessions} | {f"policies/{s}.policy.json" for s in sessions} <= names
    assert not any("p01" in n or "p03" in n for n in names)
    assert {a["participant"] for a in answers} == {"p02"} and len(answers) > 10
    assert all(x["participant"] == "p02" for x in lines if "participant" in x)
    assert all(s in readme for s in sessions) and "answers.csv" in readme and "merged/phase2-bias" in readme
    assert f"{killed.recording}.journal" in names and "write-ahead journal" in readme
    with pytest.raises(StudyDataError, match="exists"):
        data.export_participant("p02")


def test_an_export_never_replaces_a_file_of_the_study_folder(played, tmp_path):
    """`participant export -o STUDY/journal.jsonl --force` replaced the study's journal with the zip (its output
    can be one of its inputs: every file of the study folder is one); refused, --force or not. exports/ is its own."""
    data = copy_study(played, tmp_path)
    recording = data.folder / data.games_of("p02")[0].recording
    for target in (data.folder / "journal.jsonl", recording):
        before = target.read_bytes()
        with pytest.raises(StudyDataError, match="a file of the study folder; an export never replaces one"):
            data.export_participant("p02", target, force=True)
        assert target.read_bytes() == before
    path = data.export_participant("p02")
    assert data.export_participant("p02", path, force=True) == path
    # a folder as -o: said "exists (use --force to replace it)", and --force then said it is a folder (a trial)
    (tmp_path / "dd").mkdir()
    for force in (False, True):
        with pytest.raises(StudyDataError, match=r"is a folder; give a file name \(.*dd\)") as info:
            data.export_participant("p02", tmp_path / "dd", force=force)
        assert "use --force" not in str(info.value)


def test_an_export_never_replaces_a_file_put_at_its_output_while_it_zipped_unless_forced(tmp_path, monkeypatch):
    """Checked before the zip was made, then written with force whatever --force said: a file put at -o
    meanwhile (a second export, the user's) was replaced without a word."""
    from pairplay.outputs import OutputError
    from pairplay.replay import studydata

    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1")
    out = tmp_path / "p.zip"
    readme = studydata._export_readme

    def meanwhile(*args, **kw):  # the README is the zip's last part: the file appears as the zip is made
        out.write_text("mine\n")
        return readme(*args, **kw)
    monkeypatch.setattr(studydata, "_export_readme", meanwhile)
    with pytest.raises(OutputError, match=r"^exists \(.*p\.zip\)$"):
        data.export_participant(pid, out)
    assert out.read_text() == "mine\n"
    assert data.export_participant(pid, out, force=True) == out and zipfile.is_zipfile(out)


def test_the_key_file_is_its_owners_alone_from_init_to_deletion(tmp_path):
    """The key file is the one file that links ids to names: it was written 0644 (its folder too), made
    only at the first registration with a name (a researcher's trial)."""
    import stat
    key = tmp_path / "private" / "keys.csv"
    data = StudyData.create(tmp_path / "study", STUDY, key_file=key)
    assert key.is_file() and key.read_text().startswith("id,name,study pilot@")  # made at init: a path that cannot hold it is said there

    def mode(p: Path) -> int:
        return stat.S_IMODE(p.stat().st_mode)
    assert (mode(key), mode(key.parent)) == (0o600, 0o700)
    data.register("phase1", "Zoë Müller")
    data.register("phase1", "Someone Else")
    assert mode(key) == 0o600 and "Zoë Müller" in key.read_text(encoding="utf-8")
    data.delete_participant("p01")  # rewritten without their line: still owner-only
    assert mode(key) == 0o600 and "Zoë" not in key.read_text(encoding="utf-8")
    key.chmod(0o644)  # one written by an older pairplay, or by hand: tightened at the next name
    data.register("phase1", "A Third")
    assert mode(key) == 0o600
    with pytest.raises(StudyDataError, match="key file .*nothere"):  # "cannot write the key file there: ... (<path>)"
        StudyData.create(tmp_path / "study2", STUDY, key_file=tmp_path / "study" / "study.toml" / "nothere" / "k.csv")


def test_a_deletion_whose_key_file_is_away_or_whose_settings_are_not_the_studys_deletes_nothing(tmp_path):
    """A new user's trial: with the key file away (an unmounted drive) `participant delete` exited 0, the name
    left in it for good (the id gone, a retry refused); with settings.json of another shape it crashed halfway,
    the files gone, the journal and the key file still naming them. Both are refused before anything goes."""
    key = tmp_path / "private" / "keys.csv"
    data = StudyData.create(tmp_path / "study", STUDY, key_file=key)
    data.register("phase1", "Bob Jones")
    key.rename(key.with_suffix(".away"))
    with pytest.raises(StudyDataError, match="the key file .*keys.csv is not there"):
        data.delete_participant("p01")
    key.with_suffix(".away").rename(key)
    assert data.participant("p01") and "Bob Jones" in key.read_text(encoding="utf-8")
    (tmp_path / "study" / "settings.json").write_text("[1, 2]")
    with pytest.raises(StudyDataError, match=r"not the study's settings: .*\(.*study/settings.json\)$"):
        StudyData(tmp_path / "study")


def names_anywhere(folder: Path, pid: str) -> list[str]:
    """The files of `folder` that hold `pid`: a recording's records read decompressed (its zstd bytes held
    "p02" by chance once: a flaky failure), a figure's pixels not at all, any other file as its bytes."""
    from mcap.stream_reader import StreamReader

    from pairplay.schemas.jsonfile import MCAP_MAGIC

    def holds(f: Path) -> bool:
        data = f.read_bytes()
        if data.startswith(MCAP_MAGIC):
            with f.open("rb") as stream:
                return any(pid in repr(record) for record in StreamReader(stream).records)
        return f.suffix != ".png" and pid.encode() in data
    return [str(f) for f in folder.rglob("*") if f.is_file() and holds(f)]


@pytest.mark.parametrize("pid", ["p02"])
def test_a_deleted_participant_is_named_in_no_rule_combination_or_new_report(played, tmp_path, pid):
    """The merged policy's per-state rules and the journal's BiasCombined decided_by name the users
    whose games decided a state ("fewer-errors(human:p01+human:p02)"); they kept the id, and a report
    made after the deletion wrote it again (a researcher's trial: 24 rules, report.md 24 times)."""
    data = copy_study(played, tmp_path)
    merged = data.folder / "merged" / "phase2-bias.policy.json"
    assert f"human:{pid}" in " ".join(read_policy(merged).rules)  # the case: the id decided states
    data.delete_participant(pid)
    assert not names_anywhere(data.folder, pid)
    assert all("deleted" in r or f"human:{pid}" not in r for r in read_policy(merged).rules)
    human_report(data.folder)
    assert (data.folder / "report" / "report.md").is_file()
    assert not names_anywhere(data.folder, pid)


def test_delete_erases_a_participant_everywhere_and_keeps_an_anonymous_event(played, tmp_path):
    data = copy_study(played, tmp_path)
    with output_folder(data.folder / "report", owned=HUMAN_OUTPUTS, manifest=HUMAN_MANIFEST) as tmp:
        human_report(data.folder, tmp)  # as `pairplay report` writes it: with its manifest
    data.export_participant("p01")
    before = [g.session for g in data.games_of("p01")]
    erased = data.delete_participant("p01")
    gone = erased.event
    assert erased.left == [] and erased.elsewhere == []
    folder = data.folder
    assert not names_anywhere(folder, "p01")
    assert not any((folder / "recordings" / f"{s}.mcap").exists() for s in before)
    assert not (folder / "exports" / "p01.zip").exists() and not (folder / "report").exists()
    assert "First Person" not in (tmp_path / "keys.csv").read_text()
    assert gone.merged_policies_using_them == ["merged/phase2-bias.policy.json"]
    assert gone.sessions_removed == 3 and gone.key_file_line_removed
    last = (folder / "journal.jsonl").read_text().splitlines()[-1]
    assert json.loads(last)["event"] == "ParticipantDeleted" and "p01" not in last
    fresh = StudyData(folder)  # the journal still folds, and ids are never reused
    assert "p01" not in fresh.state.participants and fresh.register("phase2") == "p05"  # p01..p04 given: no reuse, no skip
    with pytest.raises(StudyDataError, match="no participant"):
        fresh.export_participant("p01")


def test_an_export_inside_the_study_folder_goes_only_to_exports_and_one_outside_is_erased_or_named_by_the_deletion(
        played, tmp_path, capsys):
    """A new user's trial: `participant export STUDY p01 -o STUDY/recordings/` (or STUDY/, STUDY/merged/) wrote a
    zip of all their data there, and `participant delete` said "deleted" with two full copies left. Inside the
    study folder an export goes only to exports/<id>.zip (which the deletion erases); one outside it is journaled
    with its SHA-256, and the deletion erases it while it is that file unchanged, and names it in a line of its
    own otherwise."""
    from pairplay.cli.main import main
    data = copy_study(played, tmp_path)
    folder = data.folder
    for target in (folder / "recordings", folder, folder / "merged", folder / "policies" / "p01.zip",
                   folder / "exports" / "other.zip"):
        assert main(["participant", "export", str(folder), "p01", "-o", f"{target}/" if target.suffix == "" else
                     str(target), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert "inside the study folder an export goes only to" in err and "exports/p01.zip" in err, err
        assert len(err.strip().splitlines()) == 1
    assert not list(folder.rglob("*.zip"))
    assert main(["participant", "export", str(folder), "p01", "--quiet"]) == 0  # the default: exports/p01.zip
    outside, kept = tmp_path / "handed" / "p01.zip", tmp_path / "handed" / "p01-annotated.zip"
    for path in (outside, kept):
        assert main(["participant", "export", str(folder), "p01", "-o", str(path), "--quiet"]) == 0
    kept.write_bytes(kept.read_bytes() + b"annotated")  # no longer the bytes pairplay wrote: named, not erased
    capsys.readouterr()
    assert main(["participant", "delete", str(folder), "p01", "--yes", "--quiet"]) == 0  # -q hides no copy left
    out = capsys.readouterr().err
    assert not names_anywhere(folder, "p01") and not list(folder.rglob("*.zip"))
    [line] = [x for x in out.splitlines() if "NOT erased" in x]
    assert str(kept) in line and "outside the study folder" in line and kept.is_file()
    assert not outside.exists()  # pairplay's own export, unchanged: erased (replay/copies.py)


def test_a_deletion_removes_only_what_the_report_wrote_and_names_what_it_kept(played, tmp_path, capsys):
    """`participant delete` removed the whole report/ folder, the researcher's notes.md and figures in it. It
    removes the files the report's manifest lists (stale without the participant) and keeps the others, each
    named in a line, saying whether it names the participant."""
    from pairplay.cli.main import main
    data = copy_study(played, tmp_path)
    folder = data.folder
    assert main(["report", str(folder), "--quiet"]) == 0
    written = set(json.loads((folder / "report" / HUMAN_MANIFEST).read_text())["files"])
    (folder / "report" / "notes.md").write_text("p01 was tired; p02 fine\n")
    (folder / "report" / "mine").mkdir()
    (folder / "report" / "mine" / "figure.svg").write_text("<svg/>")
    capsys.readouterr()
    assert main(["participant", "delete", str(folder), "p01", "--yes"]) == 0
    out = capsys.readouterr().err
    assert not any((folder / "report" / f).exists() for f in written)
    assert not (folder / "report" / HUMAN_MANIFEST).exists()
    assert (folder / "report" / "notes.md").read_text() == "p01 was tired; p02 fine\n"
    assert (folder / "report" / "mine" / "figure.svg").is_file()
    notes = [x for x in out.splitlines() if "notes.md" in x]
    figure = [x for x in out.splitlines() if "figure.svg" in x]
    assert len(notes) == 1 and "kept" in notes[0] and "names p01" in notes[0], out
    assert len(figure) == 1 and "kept" in figure[0] and "names p01" not in figure[0], out
    data = copy_study(played, tmp_path / "again")  # a report and nothing else: the folder goes with it
    assert main(["report", str(data.folder), "--quiet"]) == 0
    assert main(["participant", "delete", str(data.folder), "p01", "--yes"]) == 0
    assert not (data.folder / "report").exists() and "not written by the report" not in capsys.readouterr().err


def test_the_human_world_report(played, tmp_path):
    data = copy_study(played, tmp_path)
    StudyData(data.folder).append(j.SessionMarkedInvalid(session="pilot-p04-phase2-g1", participant="p04",
                                                         reason="played with the sound off"))
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    for name in ("games.png", "phases.png", "users-phase2.png", "merged.png", "picks.csv", "attention.csv",
                 "questionnaire.csv"):
        assert (report.out / name).stat().st_size > 0, name
    assert "pilot-p04-phase2-g1 (invalid: played with the sound off)" in text
    assert {"phase1 game 1", "phase1 game 2", "phase1 (all games)", "phase2 (all games)"} <= set(report.curves)
    assert all(18 <= x <= 200 for c in report.curves.values() for x in c)
    with open(report.out / "picks.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 7 * 2 and "p04" not in {r["participant"] for r in rows}
    q = {(r[1], r[2], r[3]): r for r in report.questionnaire[1:]}
    assert q[("best-round", "phase2", "returning")][4] == "2"
    assert "mean" in q[("followed", "phase1", "new")][5]
    att = {(r[0], r[1]): r for r in report.attention[1:]}
    assert int(att[("p01", "phase1")][8]) >= 0 and att[("all (phase1)", "phase1")][4] != "0"
    assert "ignored" in text and "wrong-suggestion presses" in text and "Profiles (algorithm 3)" in text


def test_the_game_obeys_the_experimenter_and_only_the_experimenter():
    from pairplay.schemas import events as ev
    from pairplay.schemas.session import SessionConfig
    from pairplay.services.game import GameLogic
    from pairplay.services.node import Driver

    config = SessionConfig(session="s", participant="human:p01", seed=0, rounds=2, observed_source="first-pick",
                           ignore_rule="time")
    game = Driver(GameLogic(config), "s", clock=lambda: 0)
    game.start()
    seq = {"board": 0, "experimenter": 0}

    def send(e, source):
        seq[source] += 1
        e = __import__("msgspec").structs.replace(e, session="s", source=source, seq=seq[source], time_ns=1)
        return [type(x).__name__ + ":" + getattr(x, "reason", "") for x in
                game.receive(f"pairplay/s/{source}/{type(e).__name__}", ev.encode_event(e))]

    assert send(ev.SessionPaused(reason="fire alarm"), "board")[0].startswith("MessageRejected")  # not the board's
    assert send(ev.SessionPaused(reason="fire alarm"), "experimenter") == ["ControlTaken:"]  # where it took it
    assert send(ev.SessionPaused(reason="again"), "experimenter") == ["MessageRejected:the session is already paused"]
    assert send(ev.CardPicked(round=0, turn=0, card=3), "board") == ["PickRejected:the session is paused"]
    assert send(ev.SessionResumed(), "experimenter") == ["ControlTaken:"]
    assert send(ev.CardPicked(round=0, turn=0, card=3), "board")[0] == "CardRevealed:"
    assert send(ev.SessionAborted(reason="tired"), "experimenter") == ["SessionEnded:aborted"]
    assert game.logic.done
    assert send(ev.CardPicked(round=0, turn=0, card=4), "board")[0].startswith("MessageRejected")


def test_report_force_keeps_the_folders_other_files_and_a_failure_leaves_no_temporary_folder(played, tmp_path, capsys):
    """Before: `pairplay report STUDY --out DIR --force` removed DIR whole (a user's notes in it
    included) before renaming its temporary folder there; `--out FILE --force` failed with "Not a
    directory" and left `.FILE.<pid>.tmp` beside it (found by the trial of issue-free main)."""
    from pairplay.cli.main import main

    data = copy_study(played, tmp_path)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("the user's notes")
    assert main(["report", str(data.folder), "--out", str(mine)]) == 2  # not empty: refused without --force
    assert "--force" in capsys.readouterr().err
    (mine / "users-phase9.png").write_bytes(b"the user's figure, named like a report's figure 7.6")
    assert main(["report", str(data.folder), "--out", str(mine), "--force"]) == 0
    assert (mine / "notes.txt").read_text() == "the user's notes" and (mine / "report.md").is_file()
    assert (mine / "users-phase9.png").is_file()  # the report's name, but no report wrote it (its manifest): kept
    assert "left 1 file" in capsys.readouterr().err  # and said
    listed = json.loads((mine / HUMAN_MANIFEST).read_text())  # as if an earlier report had written it
    (mine / HUMAN_MANIFEST).write_text(json.dumps({**listed, "files": [*listed["files"], "users-phase9.png"]}))
    assert main(["report", str(data.folder), "--out", str(mine), "--force"]) == 0
    assert not (mine / "users-phase9.png").exists()  # the report's own, not written now: stale, removed
    capsys.readouterr()
    (tmp_path / "afile").write_text("a file")
    assert main(["report", str(data.folder), "--out", str(tmp_path / "afile"), "--force"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "afile" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "keys.csv", "mine", "study"]


def test_atomic_write_leaves_no_temporary_file_when_the_write_fails(tmp_path):
    """Before: a write that failed (a full disk: `participant export -o` on a full tmpfs) left
    `.NAME.<pid>.tmp` beside the target."""
    from pairplay.replay.studydata import atomic_write

    with pytest.raises(TypeError):
        atomic_write(tmp_path / "t.csv", "not bytes")  # the write itself fails, as on a full disk
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ['=HYPERLINK("http://x","click")', "+1+cmd|' /C calc'!A0", "-2+3", "@SUM(A1)",
                                  "'quoted", "Zoë Müller", "-3", "O'Brien"])
def test_a_name_is_never_a_formula_in_the_key_file_and_reads_back_the_same(tmp_path, pairplay_cli, name):
    """CSV injection (OWASP): `protocol register --name '=HYPERLINK(...)'` was written as is, a formula
    once the key file is opened in a spreadsheet. A cell starting with = + - @ tab or CR (or a quote)
    gets one quote before it (pairplay/csvcell.py); `csvcell.value` reads back the very name."""
    import csv

    from pairplay import csvcell
    key = tmp_path / "private" / "keys.csv"
    assert pairplay_cli("protocol", "init", tmp_path / "study", "--study", "thesis-ch7", "--key-file", key,
                        "--quiet").returncode == 0
    r = pairplay_cli("protocol", "register", tmp_path / "study", f"--name={name}")
    assert r.returncode == 0, r.stderr
    with open(key, encoding="utf-8", newline="") as f:
        [_header, [pid, written, _study]] = list(csv.reader(f))  # its study in the third cell (tests/test_key_file_owner.py)
    assert pid == r.stdout.strip()
    assert not written.startswith(("=", "+", "@")) and written in (name, "'" + name)
    assert not written.startswith("-") or written == "-3"  # a plain number stays a number
    assert csvcell.value(written) == name


@pytest.mark.parametrize("name, shown", [('Bob\n,evil"', r"'\n' at 3"), ("\tTab", r"'\t' at 0"),
                                         ("\rCR", r"'\r' at 0"), ("a\x00b", r"'\x00' at 1")])
def test_a_name_with_a_control_character_is_refused_in_one_line(tmp_path, pairplay_cli, name, shown):
    """A new user's trial: `--name "Bob<newline>,evil\""` was written with its newline made a space, without a
    word (the key file's name was not the one typed). Refused, as the console's register is (one rule,
    StudyData.register_many): one line, exit 2, nothing registered, the key file as it was."""
    key = tmp_path / "private" / "keys.csv"
    assert pairplay_cli("protocol", "init", tmp_path / "study", "--study", "thesis-ch7", "--key-file", key,
                        "--quiet").returncode == 0
    journal, keys = (tmp_path / "study" / "journal.jsonl").read_bytes(), key.read_bytes()
    r = pairplay_cli("protocol", "register", tmp_path / "study", f"--name={name}")
    assert r.returncode == 2 and r.stdout == "", (r.stdout, r.stderr)
    assert r.stderr == (f"pairplay protocol register: --name holds a control character ({shown}): give the name "
                        f"as one line of text, without tabs\n"), r.stderr
    assert key.read_bytes() == keys and (tmp_path / "study" / "journal.jsonl").read_bytes() == journal


def test_every_table_of_what_people_typed_is_written_formula_free(tmp_path):
    """The study's own tables and a participant's export go through the same rule (the answers are free text)."""
    import io

    from pairplay import csvcell
    buf = io.StringIO()
    csvcell.writer(buf).writerows([["=1+1", -1, 2.5, "-x", "ok"]])
    assert buf.getvalue() == "'=1+1,-1,2.5,'-x,ok\r\n"


def test_a_scripted_game_is_marked_where_it_is_recorded_and_the_report_says_a_rehearsal(played, tmp_path):
    """Before: a persona's game was recorded as a person's (participant human:p01, persona "", no mark in
    the journal, sessions.csv or participants.csv) and the report pooled it with people's games as "the
    human-world report" (a new user's trial)."""
    root, ids = played
    data = StudyData(root / "study")
    personas = dict(zip(ids, PERSONAS))
    for g in data.state.games.values():
        assert g.scripted == personas[g.participant], g
        config = read_log(data.folder / g.recording).of("SessionStarted")[0].config
        assert config.scripted == personas[g.participant] and config.participant == f"human:{g.participant}"
    journal = [json.loads(line) for line in (data.folder / "journal.jsonl").read_text().splitlines()]
    assert all(e["scripted"] == personas[e["participant"]] for e in journal if e["event"] == "GameStarted")
    with open(data.folder / "sessions.csv") as f:
        assert {r["scripted"] for r in csv.DictReader(f)} == set(PERSONAS)
    with open(data.folder / "participants.csv") as f:
        assert {r["participant"]: r["scripted"] for r in csv.DictReader(f)} == personas
    with open(data.folder / "answers.csv") as f:  # a persona's answers say so too (a trial joined on sessions.csv)
        answers = list(csv.DictReader(f))
    assert answers and all(r["scripted"] == personas[r["participant"]] for r in answers)
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    assert report.rehearsal and len(report.games) == 8
    assert "a rehearsal of 8 scripted games" in text.splitlines()[0] and "No person played" in text
    assert "Combined from scripted games" in text


def test_a_persona_is_named_a_persona_wherever_the_report_console_or_tables_name_a_participant(played, tmp_path):
    """A new user's trial: the report's bias section named the personas' users `human:p01` (the sessions
    of a rehearsal run as the plan's participant), in its list of users, its profiles and every state's
    rule; so did the console's combination, and picks.csv and attention.csv did not say a row was a
    persona's. Now: `sim:<persona> as <id>`, a `scripted` column, and a person stays `human:<id>`."""
    from pairplay.services.console.app import Console

    root, ids = played
    personas = dict(zip(ids, PERSONAS))
    data = StudyData(root / "study")
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    assert "human:" not in text
    combined = data.state.combined["phase2"]
    users = [f"sim:{personas[u.split(':')[1]]} as {u.split(':')[1]}" for u in combined.users]
    assert f"policy files of {', '.join(users)} (" in text
    assert all(f"| {u} |" in text for u in users)  # the profiles
    for name in ("picks.csv", "attention.csv"):
        with open(report.out / name) as f:
            rows = [r for r in csv.DictReader(f) if not r["participant"].startswith("all")]
        assert rows and all(r["scripted"] == personas[r["participant"]] for r in rows), name
    state = Console(StudyRunner(data, None), "token").state()
    assert "human:" not in json.dumps(state["combined"])
    assert state["combined"]["phase2"]["users"] == users
    assert {p["id"]: p["scripted"] for p in state["participants"]} == personas
    assert all(f"{s['participant']} (scripted: {personas[s['participant']]}):" in s["label"]
               for s in state["plan"] if s["kind"] == "play")  # `protocol status` and the pilot's lines too
    # a person stays what they are: p01's games played by a person (journal lines without `scripted`)
    mixed = copy_study(played, tmp_path / "mixed")
    lines = [json.loads(line) for line in (mixed.folder / "journal.jsonl").read_text().splitlines()]
    for e in lines:
        if e["event"] == "GameStarted" and e["participant"] == ids[0]:
            del e["scripted"]
    (mixed.folder / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in lines))
    names = StudyData(mixed.folder).user_names(combined)
    assert f"human:{ids[0]}" not in names and names[f"human:{ids[1]}"] == f"sim:{personas[ids[1]]} as {ids[1]}"


def test_people_s_games_are_reported_and_combined_without_the_scripted_ones(played, tmp_path):
    """A folder where people played p01's and p03's games (journal lines without `scripted`, as every
    journal before the field) and personas the others': the report and the combination leave the
    personas' games out unless asked. Before: pooled, unmarked."""
    data = copy_study(played, tmp_path)
    people = {"p01", "p03"}
    lines = []
    for line in (data.folder / "journal.jsonl").read_text().splitlines():
        e = json.loads(line)
        if e["event"] == "GameStarted" and e["participant"] in people:
            del e["scripted"]
        lines.append(json.dumps(e))
    (data.folder / "journal.jsonl").write_text("\n".join(lines) + "\n")
    data = StudyData(data.folder)
    assert [g.participant for g in data.combined_games("phase1")] == ["p01", "p01"]
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    assert not report.rehearsal and {s.participant for s in report.games} == people
    assert "the human-world report" in text.splitlines()[0]
    assert "4 games played by scripted personas (blind, vincent) are left out" in text
    assert "pilot-p02-phase1-g1 (scripted: blind)" in text
    with open(report.out / "picks.csv") as f:
        assert {r["participant"] for r in csv.DictReader(f)} == people
    assert {r[0] for r in report.attention[1:] if not r[0].startswith("all")} == people
    pooled = human_report(data.folder, tmp_path / "pooled", include_scripted=True)
    assert len(pooled.games) == 8 and "with scripted games" in (pooled.out / "report.md").read_text()


def test_every_csv_pairplay_writes_goes_through_csvcell():
    """The simulated study's, the sweep's and the counterfactual's tables were written by csv.writer
    itself: a name in them that a spreadsheet takes for a formula went out raw. Every CSV writer in
    pairplay's code is csvcell's, but for the two whose cells are known safe (said beside each)."""
    import re

    root = Path(__file__).resolve().parents[1]
    allowed = {
        ("replay/studydata.py", "csv.writer(buf).writerows(kept)"),  # the rows as read: written by csvcell already
        ("replay/rebuild.py", "csv.DictWriter(f, fieldnames=CURVE_COLUMNS)"),  # a curve's counts only
    }
    raw = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel.startswith((".venv/", "tests/", "build/")) or rel == "pairplay/csvcell.py":
            continue
        for line in path.read_text(encoding="utf-8").splitlines():
            m = re.search(r"\bcsv\.(writer|DictWriter)\(.*", line)
            if m and not any(rel == a and text in line for a, text in allowed):
                raw.append(f"{rel}: {line.strip()}")
    assert raw == [], raw


def test_the_report_leaves_out_a_game_whose_recording_holds_messages_that_do_not_decode(played, tmp_path):
    """A new user's trial: a recording whose TurnResolved and RoundEnded messages did not decode was reported
    with its intact rounds only, as if the game were whole, with no word. The report leaves it out and says
    why (reader.EventLog.lost: the loss rebuild refuses without --partial)."""
    from pairplay.replay.writer import EventLogWriter

    data = copy_study(played, tmp_path)
    game = next(g for g in data.state.games.values() if g.valid_complete and g.participant == "p03")
    path = data.folder / game.recording
    records = read_log(path).events
    w = EventLogWriter(path, chunk_size=4096)
    for r in records:
        broken = type(r.event).__name__ == "RoundEnded"
        w.write(r.key, b'{"type":"broken"' if broken else r.payload, log_time_ns=r.log_time_ns, sequence=r.event.seq)
    w.close()
    report = human_report(data.folder, tmp_path / "report")
    assert game.session not in {s.session for s in report.games}
    [left] = [e for e in report.excluded if e.startswith(game.session)]
    assert "recording damaged: 2 messages in it do not decode (" in left, left
    assert left in (report.out / "report.md").read_text()


def _rewrite(path: Path, keep=lambda tag: True, change=None) -> None:
    """Write the recording at `path` again with only the events whose tag `keep` takes, each SessionStarted's
    JSON passed through `change` (a new user's trial: an interrupted `session --force`, another session)."""
    from pairplay.replay.writer import EventLogWriter

    records = read_log(path).events
    w = EventLogWriter(path, chunk_size=4096)
    for r in records:
        tag = type(r.event).__name__
        if not keep(tag):
            continue
        payload = r.payload
        if tag == "SessionStarted" and change is not None:
            payload = json.dumps(change(json.loads(payload))).encode()
        w.write(r.key, payload, log_time_ns=r.log_time_ns, sequence=r.event.seq)
    w.close()


def test_the_report_leaves_out_a_game_whose_recording_holds_no_session_or_no_whole_round(played, tmp_path):
    """A new user's trial: a 0-byte recording, and the file an interrupted `session --force` leaves (no
    SessionStarted), were counted as valid games ("18 valid games", exit 0) and their data vanished from
    picks.csv without a word. Each is left out and named with the reader's words, as a missing one is;
    so is a recording whose session ended before its first round."""
    from pairplay.replay.writer import EventLogWriter

    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete and not g.invalid]
    empty, header, unstarted, no_round = games[:4]
    (data.folder / empty.recording).write_bytes(b"")
    EventLogWriter(data.folder / header.recording).close()  # a recorder that wrote nothing but MCAP's frame
    _rewrite(data.folder / unstarted.recording, keep=lambda tag: tag != "SessionStarted")
    _rewrite(data.folder / no_round.recording, keep=lambda tag: tag != "RoundEnded")
    report = human_report(data.folder, tmp_path / "report")
    reported = {s.session for s in report.games}
    text = (report.out / "report.md").read_text()
    words = [(empty, "recording holds no session: the file is empty (0 bytes)"),
             (header, "recording holds no session: an MCAP file with no"),
             (unstarted, "recording holds no session: "),
             # (its RoundEnded removed: the game's seq skips their numbers, said as events missing: trial28 F3)
             (no_round, "recording damaged: 2 events of 'game' missing: its seq jumps from ")]
    for g, why in words:
        assert g.session not in reported, g.session
        [left] = [e for e in report.excluded if e.startswith(g.session + " (")]
        assert left.startswith(f"{g.session} ({why}"), left
        assert left in text
    assert f"{len(games) - 4} valid games" in text
    with open(report.out / "picks.csv") as f:
        assert len(list(csv.DictReader(f))) == (len(games) - 4) * 2


def test_the_report_leaves_out_a_recording_that_is_not_its_games(played, tmp_path):
    """A new user's trial: `session --force --session <a study game's id> --out STUDY/recordings` replaced a
    study game's recording with an unrelated session (another persona, 1 round) and the report used it
    without a word. Each game's recording is checked against the journal (its session id, participant,
    the plan's rounds, the persona of a scripted game) and left out, named with why, if it is not that game's.
    The four ways are four games of one copy (two of each phase), reported once (each paid a report)."""
    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete]
    donor = games[1]
    whys = {}
    for other, game in zip(["another-game", "participant", "rounds", "persona"], games[0::2]):
        path = data.folder / game.recording
        if other == "another-game":
            shutil.copy(data.folder / donor.recording, path)
            whys[game.session] = f"session {donor.session}"
            continue
        change = {"participant": ("participant", "sim:vincent"), "rounds": ("rounds", 1),
                  "persona": ("scripted", "deaf" if game.scripted != "deaf" else "blind")}[other]

        def swap(e, field=change[0], value=change[1]):
            e["config"][field] = value
            return e
        _rewrite(path, change=swap)
        whys[game.session] = {"participant": "sim:vincent", "rounds": "1 round", "persona": change[1]}[other]
    assert len(whys) == 4 and donor.session not in whys
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    for session, why in whys.items():
        assert session not in {s.session for s in report.games}
        [left] = [e for e in report.excluded if e.startswith(session + " (")]
        assert left.startswith(f"{session} (recording is not this game's: "), left
        assert why in left, left
        assert left in text
    assert donor.session in {s.session for s in report.games}  # the game whose recording was copied stays


def test_the_answers_table_takes_no_answer_from_a_recording_that_is_not_its_games(played, tmp_path):
    """answers.csv gave the answers a replacing session's recording holds (another game's, copied over) to the
    journal's game and participant: the tables read a game's answers only from a recording that is that game's."""
    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete]
    game, donor = games[0], next(g for g in games if g.participant != games[0].participant)
    assert any(a["session"] == game.session for a in data.answers())
    shutil.copy(data.folder / donor.recording, data.folder / game.recording)
    assert not any(a["session"] == game.session for a in StudyData(data.folder).answers())


@pytest.mark.parametrize("how", ["undecodable", "chunk"])
def test_an_answer_its_recording_lost_is_a_row_saying_so_in_answers_csv_and_the_export(played, tmp_path, how):
    """answers.csv silently left out a game's answers when its QuestionnaireAnswered message did not decode (or
    the chunk that held it was damaged): the game looked unanswered, with no word. The lost answers are one row
    (the phase's questionnaire, item and answer empty) whose `lost` column says why in the reader's words, in the
    tables and in the participant's export; the report's questionnaire table counts no answer from it."""
    data = copy_study(played, tmp_path)
    game = next(g for g in data.state.games.values() if g.valid_complete and g.ended.questionnaire)
    before = [a for a in data.answers() if a["session"] == game.session]
    assert before and all(not a.get("lost") for a in before)
    damage(data.folder / game.recording, how, tag="QuestionnaireAnswered")
    data = StudyData(data.folder)
    data.write_tables()
    with open(data.folder / "answers.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    [lost] = [r for r in rows if r["session"] == game.session]
    assert lost["item"] == lost["answer"] == "" and lost["questionnaire"] == before[0]["questionnaire"], lost
    words = {"undecodable": "the answers do not decode (", "chunk": "not in the recording: damaged: chunk "}[how]
    assert words in lost["lost"], lost
    assert all(r["lost"] == "" and r["item"] for r in rows if r["session"] != game.session)
    with zipfile.ZipFile(data.export_participant(game.participant, tmp_path / "p.zip")) as z:
        exported = list(csv.DictReader(z.read("answers.csv").decode().splitlines()))
        readme = z.read("README.txt").decode()
    assert [r["lost"] for r in exported if r["session"] == game.session] == [lost["lost"]]
    assert "1 row for answers a damaged recording lost" in readme, readme
    from pairplay.report.human import questionnaire_rows
    assert all(r[4] != "0" for r in questionnaire_rows(data, {game.session})[1:])


def test_no_policy_is_built_for_a_game_from_a_recording_that_is_not_its_games(played, tmp_path):
    """build_missing_policies rebuilt a completed game's missing policy from whatever its recording path held:
    another session copied over it (`session --force`) became the game's policy, journaled. It is refused, said."""
    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete]
    game, donor = games[0], games[1]
    (data.folder / game.ended.policy).unlink()
    shutil.copy(data.folder / donor.recording, data.folder / game.recording)
    [line] = StudyData(data.folder).build_missing_policies()
    assert line.startswith(f"{game.session}: completed, but its policy {game.ended.policy} is missing; no policy "
                           f"built: its recording {game.recording} is not this game's: it holds session "
                           f"{donor.session}"), line
    assert not (data.folder / game.ended.policy).exists()


def test_the_console_offers_the_board_link_only_once_the_board_has_a_url(tmp_path):
    """The console's state had "board_url": null while the lab's board for the game was not up yet; a client
    that waited for the key (test_protocol_interrupted's) read null and failed. Now the key comes with a URL."""
    from pairplay.services.console.app import Console
    from pairplay.services.protocol import Live

    data = StudyData.create(tmp_path / "s", STUDY)
    runner = StudyRunner(data, None)
    runner.live = Live(session="s-1", state="playing")
    assert "board_url" not in Console(runner, "token", board_url=lambda session: None).state()["live"]
    assert Console(runner, "token", board_url=lambda session: f"/board?session={session}").state()["live"][
        "board_url"] == "/board?session=s-1"


def test_the_report_and_answers_leave_out_what_a_recovered_recording_s_source_lost(played, tmp_path):
    """A new user's trial: a study game's recording replaced by what `pairplay recover` made of it after it lost
    a chunk (a whole file whose metadata says where its source lost parts) was counted as a valid game, its
    answers as answered. The reader carries the source's losses (EventLog.lost): the game is left out and named
    with them, as a damaged recording is, and the answers it lost are a row saying so in answers.csv."""
    from pairplay.replay.recover import recover

    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete]
    game = next(g for g in games if g.ended.questionnaire)
    path = data.folder / game.recording
    damage(path, "chunk", tag="QuestionnaireAnswered")
    recovered = recover(path, tmp_path / "r.mcap").output
    shutil.copy(recovered, path)
    assert read_log(path).whole
    said = f"recovered from a damaged file ({path.name}): chunk "
    data = StudyData(data.folder)
    report = human_report(data.folder, tmp_path / "report")
    assert game.session not in {s.session for s in report.games}
    [left] = [e for e in report.excluded if e.startswith(game.session + " (")]
    assert left.startswith(f"{game.session} (recording damaged: {said}"), left
    assert left in (report.out / "report.md").read_text()
    assert f"{len(games) - 1} valid games" in (report.out / "report.md").read_text()
    [lost] = [a for a in data.answers() if a["session"] == game.session]
    assert lost["item"] == "" and f"not in the recording: damaged: {said}" in lost["lost"], lost


def test_the_report_leaves_out_a_game_whose_recording_is_cut(played, tmp_path):
    """A new user's trial: a study game's recording cut short (its last rounds and its SessionEnded gone) was
    counted as a valid game ("5 valid games") and its partial rounds went into the figures: a part passed off as
    the game. It is left out and named, the cut in the reader's words, as a damaged one is."""
    data = copy_study(played, tmp_path)
    games = [g for g in data.state.games.values() if g.valid_complete]
    game = games[0]
    path = data.folder / game.recording
    from pairplay.replay.mcapscan import scan
    from pairplay.replay.writer import EventLogWriter

    events = read_log(path).events  # written again in 4 KB chunks, cut in the one after the last round's start
    w = EventLogWriter(path, chunk_size=4096)
    for i, r in enumerate(events):  # each log time unique (+ its index, in ns): events may share one (damageutil)
        w.write(r.key, r.payload, log_time_ns=r.log_time_ns + i, sequence=r.event.seq)
    w.close()
    last = [r.log_time_ns + i for i, r in enumerate(events) if type(r.event).__name__ == "RoundStarted"][-1]
    chunks = scan(path).chunks
    [at] = [i for i, c in enumerate(chunks) if any(t == last for _, _, t in c.messages)]
    path.write_bytes(path.read_bytes()[:chunks[at + 1].offset + chunks[at + 1].length // 2])
    cut = read_log(path)
    assert cut.truncated and not cut.of("SessionEnded") and cut.of("RoundEnded")  # a whole round is left
    report = human_report(data.folder, tmp_path / "report")
    text = (report.out / "report.md").read_text()
    assert game.session not in {s.session for s in report.games}
    [left] = [e for e in report.excluded if e.startswith(game.session + " (")]
    assert left.startswith(f"{game.session} (recording truncated: file end: cut at byte "), left
    assert "no SessionEnded: its rounds are a part of the game" in left and left in text
    assert f"{len(games) - 1} valid games" in text
    with open(report.out / "picks.csv") as f:
        assert len(list(csv.DictReader(f))) == (len(games) - 1) * 2  # its 1 whole round is in no row


@pytest.mark.parametrize("which", ["merged", "policies"])
def test_a_cited_policy_file_that_cannot_be_read_is_said(played, tmp_path, capsys, which):
    """The report cites the bias policy and the games' policies it was combined from (from the journal); one
    cut short (a copy that did not finish) was cited as if whole: no word in report.md, none on the command
    line, exit 0 (a new user's trial). Now each is named with why, in report.md and on stderr (one line). A report
    missing what it cites is not a whole report: exit 1 (README's exit status table: "done, and the answer is no";
    it was exit 0 with a warning), the partial report still written, as `replay --verify` of a partial recording."""
    from pairplay.cli.main import main

    data = copy_study(played, tmp_path)
    combined = next(iter(data.state.combined.values()))
    cited = combined.output if which == "merged" else combined.inputs[0]
    path = data.folder / cited
    path.write_bytes(path.read_bytes()[:200])
    assert main(["report", str(data.folder)]) == 1
    out, err = capsys.readouterr()
    err = err.strip().splitlines()
    said = [line for line in err if "unreadable" in line]
    assert len(said) == 1 and f"{cited} (corrupt or not a policy file: cut short" in said[0], err
    assert said[0].startswith("pairplay report: not a whole report: unreadable policy files, cited from the journal: ")
    assert out.strip().splitlines()[-1] == f"report: {data.folder / 'report' / 'report.md'}", out
    md = (data.folder / "report" / "report.md").read_text()
    assert f"**unreadable policy files, cited from the journal**: {cited} (" in md
    assert (f"`{cited}`, its file unreadable now" in md) == (which == "merged")


def _unregistered_by_hand(folder: Path, pid: str) -> None:
    """What a hand edit leaves: `pid`'s registration line gone from the journal (their games' lines stay)."""
    journal = folder / "journal.jsonl"
    journal.write_bytes(b"".join(line for line in journal.read_bytes().splitlines(keepends=True)
                                 if not (b'"ParticipantRegistered"' in line and f'"{pid}"'.encode() in line)))


def _files(folder: Path) -> dict[str, bytes]:
    return {f.relative_to(folder).as_posix(): f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file()}


def test_a_journal_that_does_not_fold_is_refused_by_every_writing_verb_before_it_writes(played, tmp_path, capsys):
    """A new user's trial: p02 played, then their registration line was removed from the journal by hand; `protocol
    register` journaled a new id, then its tables failed ("no participant 'p02'", exit 2), participants.csv stayed
    stale, and a retry registered yet another id. Every verb that writes the folder (a journal line, a table, a copy
    journaled there) now checks first that the journal folds into consistent tables, and refuses in one line naming
    the journal, the lines and what to do, before any write; `protocol status` lists what does not fold."""
    from pairplay.cli.main import main

    data = copy_study(played, tmp_path)
    folder, key = data.folder, tmp_path / "keys.csv"
    p01 = data.games_of("p01")
    lines = [n for n, line in enumerate((folder / "journal.jsonl").read_bytes().splitlines(), 1)
             if b'"GameStarted"' not in line and any(f'"{g.session}"'.encode() in line for g in data.games_of("p02"))]
    _unregistered_by_hand(folder, "p02")
    before, keys = _files(folder), key.read_bytes()
    verbs = [["protocol", "register", folder], ["protocol", "register", folder, "--count", "3"],
             ["protocol", "mark-invalid", folder, p01[0].session, "--reason", "a test"],
             ["protocol", "pilot", folder, "--personas", "tatiana,deaf,vincent"],
             ["protocol", "serve", folder, "--listen", "127.0.0.1:0"],
             ["participant", "export", folder, "p01"], ["participant", "delete", folder, "p01", "--yes"],
             ["report", folder], ["report", folder, "--out", tmp_path / "elsewhere"],
             ["rebuild", folder / p01[0].recording, "--out", tmp_path / "rebuilt", "--no-plot"],
             ["combine", *(folder / g.ended.policy for g in p01[:2]), "-o", tmp_path / "merged.json"]]
    for argv in verbs:
        assert main([str(a) for a in argv]) == 2, argv
        out, err = capsys.readouterr()
        said = err.strip().splitlines()
        assert len(said) == 1 and "Traceback" not in err, (argv, err)
        assert (f"{folder / 'journal.jsonl'}" in said[0] and "does not fold into consistent tables: p02 has" in said[0]
                and "and no registration line (removed by hand?)" in said[0] and "nothing was written" in said[0]
                and "put back the line" in said[0]), (argv, said)
        assert _files(folder) == before and key.read_bytes() == keys, argv  # no id journaled, no table, no key line
        assert not [p for p in ("elsewhere", "rebuilt", "merged.json") if (tmp_path / p).exists()], argv
    # the status says what does not fold (it only reads), and the ids it shows
    assert main(["protocol", "status", str(folder)]) == 0
    out, err = capsys.readouterr()
    [problem] = [line for line in out.splitlines() if "does not fold" in line]
    assert problem.startswith(f"{folder / 'journal.jsonl'}: does not fold into consistent tables: p02 has "), problem
    assert f"({'lines ' if len(lines) > 1 else 'line '}" in problem and err == "", (out, err)


def test_an_export_whose_journal_line_cannot_be_written_is_removed_and_said(played, tmp_path, capsys, monkeypatch):
    """`participant export -o` wrote the zip, then its journal line (ParticipantExported, what their deletion erases
    it by): a line that could not be written (a full disk) left the zip there, a copy of all their data the
    deletion would never know. Now the zip is removed, and the one line says so."""
    import errno

    from pairplay.cli.main import main

    data = copy_study(played, tmp_path)
    real = StudyData.append

    def full_disk(self, event):
        if isinstance(event, j.ParticipantExported):
            raise OSError(errno.ENOSPC, "No space left on device", str(self.folder / "journal.jsonl"))
        return real(self, event)

    monkeypatch.setattr(StudyData, "append", full_disk)
    before = (data.folder / "journal.jsonl").read_bytes()
    for out in (tmp_path / "handed" / "p01.zip", None):
        assert main(["participant", "export", str(data.folder), "p01", *(["-o", str(out)] if out else [])]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        zip_ = out or data.folder / "exports" / "p01.zip"
        assert len(err) == 1 and "No space left on device" in err[0], err
        assert f"the export {zip_} was removed: its journal line could not be written" in err[0], err
        assert not zip_.exists() and (data.folder / "journal.jsonl").read_bytes() == before
