"""A game marked invalid after a bias policy took it: said, combined again into a new file, flagged everywhere.

A new user's trial (trial29 F6): a phase-1 game marked invalid after the combination stayed in the bias policy.
`protocol mark-invalid` said only "marked invalid", `protocol status` showed the game open and "[done] combine",
`pilot` played the game again and said "plan complete", the bias policy's `merged_from` still named the invalid
game's policy, and `report` listed the game as left out yet said the bias policy was combined from 4 files, the
invalid one among them. Now (replay/biases.py): the mark says which bias policy took the game and which games were
played on it; the plan asks for the game again, then the combination again, into a new file (the old one kept);
a game not yet played on the flawed one waits for the new one; the games played on it stay valid, and status,
the console, pilot and report say which bias policy each used and flag the flawed one. Real CLI runs of a study
of 2-round games (tests/data/pilot-study.toml), personas playing.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from pairplay.replay.copies import holders
from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.schemas import journal as j
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.app import Console
from pairplay.services.protocol import StudyRunner, scripted_players

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
INVALID = "pilot-p01-phase1-g2"  # p01's second phase-1 game, which the bias policy took
PHASE2 = ["pilot-p01-phase2-g1", "pilot-p02-phase2-g1"]
V1, V2 = "merged/phase2-bias.policy.json", "merged/phase2-bias-v2.policy.json"


@pytest.fixture(scope="module")
def played(tmp_path_factory, pairplay_cli):
    """A study of 2 played to its end by `protocol pilot`: 4 phase-1 games, the bias policy, 2 phase-2 games."""
    root = tmp_path_factory.mktemp("reinvalid")
    for args in (["init", "s", "--study", STUDY], ["register", "s", "--count", "2"],
                 ["pilot", "s", "--personas", "blind,deaf"]):
        ran = pairplay_cli("protocol", *args, cwd=root)
        assert ran.returncode == 0, ran.stderr
    assert "plan complete" in ran.stdout
    return root / "s"


@pytest.fixture(scope="module")
def pairplay_cli():
    from cli_zygote import shared

    zygote = shared()
    return lambda *args, cwd: zygote.run([str(a) for a in args], Path(cwd), timeout=300)


def marked(played, tmp_path, pairplay_cli):
    """A copy of the played study with INVALID marked invalid by the CLI: (folder, the mark's run)."""
    shutil.copytree(played, tmp_path / "s")
    return tmp_path / "s", pairplay_cli("protocol", "mark-invalid", "s", INVALID, "--reason", "wrong instructions",
                                        cwd=tmp_path)


def test_the_mark_names_the_bias_policy_it_took_and_the_games_played_on_it(played, tmp_path, pairplay_cli):
    """It said only "<session> marked invalid: <reason>"."""
    _, ran = marked(played, tmp_path, pairplay_cli)
    assert ran.returncode == 0 and ran.stderr == ""
    line, = ran.stdout.splitlines()
    assert line.startswith(f"{INVALID} marked invalid: wrong instructions; the bias policy of phase2 ({V1}) was "
                           "combined from it: the plan asks for the game again, then the combination again, into a "
                           "new file (this one kept for the record); 2 games played on it")
    assert all(s in line for s in PHASE2) and "stay valid" in line and "mark them invalid too" in line
    # a game no combination took: the line is what it was
    ran = pairplay_cli("protocol", "mark-invalid", "s", PHASE2[0], "--reason", "fire alarm", cwd=tmp_path)
    assert ran.stdout == f"{PHASE2[0]} marked invalid: fire alarm\n"


def test_status_and_the_console_ask_for_the_game_and_the_combination_again(played, tmp_path, pairplay_cli):
    """Status showed "[open] p01: phase1 game 2" and "[done] combine ...", the console the same, no word of the
    bias policy made with the game."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout.splitlines()
    combine = next(line for line in status if "combine" in line)
    assert combine.startswith("[blocked] combine") and "the games of phase1 are not all played" in combine
    assert f"{V1} was made with {INVALID} (marked invalid since: wrong instructions)" in combine
    for session in PHASE2:  # played honestly on it: they stay done, and say what they were played on
        line = next(x for x in status if f"{session.split('-')[1]} (scripted:" in x and "phase2" in x)
        assert line.startswith("[done   ]") and f"played on {V1}, made with {INVALID}" in line
    state = Console(StudyRunner(StudyData(folder), None), "token").state()
    steps = {s["label"]: s for s in state["plan"]}
    step = next(s for s in state["plan"] if s["kind"] == "combine")
    assert not step["done"] and step["note"] in combine
    assert state["next"]["participant"] == "p01" and state["next"]["phase"] == "phase1"
    assert state["combined"]["phase2"]["flawed"] == f"made with {INVALID} (marked invalid since: wrong instructions)"
    games = {g["session"]: g for g in state["games"]}
    assert all(games[s]["bias"] == V1 and games[s]["bias_flawed"] for s in PHASE2) and len(steps) == 7
    with open(folder / "sessions.csv") as f:
        rows = {r["session"]: r for r in csv.DictReader(f)}
    assert all(rows[s]["bias_flawed"].startswith(f"made with {INVALID}") for s in PHASE2)


def test_pilot_plays_the_game_again_and_combines_into_a_new_file_keeping_the_old(played, tmp_path, pairplay_cli):
    """Pilot played the game again and said "plan complete" on the bias policy made with the invalid game."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    old = (folder / V1).read_bytes()
    ran = pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    lines = ran.stdout.splitlines()
    assert len(lines) == 3 and "p01 (scripted: blind): phase1 game 2: completed" in lines[0]
    assert lines[1].endswith(f"2 users combined into {V2} (in place of {V1}, made with {INVALID} (marked invalid "
                             "since: wrong instructions); kept for the record)")
    assert lines[2].startswith("plan complete")
    assert (folder / V1).read_bytes() == old  # the record of what the phase-2 games were played on
    merged = json.loads((folder / V2).read_text())["merged_from"]
    assert f"policies/{INVALID}.policy.json" not in merged and f"policies/{INVALID}-r1.policy.json" in merged
    data = StudyData(folder)
    assert [c.output for c in data.state.combinations] == [V1, V2] and data.next_step() is None
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout
    assert "[done   ] combine" in status and "[open" not in status and "[blocked" not in status
    manifest = (folder / ".pairplay-protocol.manifest").read_text()
    assert V1 in manifest and V2 in manifest  # no other verb's output takes either
    assert holders(data, V1) == holders(data, V2) == {"p01", "p02"}  # a copy of either is journaled as theirs
    # the report names the bias policy each game used and flags the one made with the invalid game
    ran = pairplay_cli("report", "s", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert f"left out: {INVALID} (invalid: wrong instructions)" in ran.stdout
    assert f"played on a bias policy made with a game marked invalid since: {PHASE2[0]} ({V1}), {PHASE2[1]} ({V1})" \
        in ran.stdout
    text = (folder / "report" / "report.md").read_text()
    assert f"## The bias policy of phase2, `{V1}`" in text and f"## The bias policy of phase2, `{V2}`" in text
    assert (f"**Made with a game marked invalid since**: {INVALID} (marked invalid since: wrong instructions); "
            f"replaced by `{V2}`") in text
    assert f"Games played on it: {', '.join(PHASE2)}." in text
    with open(folder / "report" / "picks.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["phase"] == "phase2"]
    assert rows and all(r["bias"] == V1 and r["bias_flawed"].startswith(f"made with {INVALID}") for r in rows)


def test_a_game_not_yet_played_waits_for_the_new_bias_policy_and_is_played_on_it(tmp_path, pairplay_cli):
    """The phase-2 games still to play started on the bias policy made with the invalid game."""
    data = StudyData.create(tmp_path / "s", STUDY)
    ids = [data.register("phase1"), data.register("phase1")]
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        runner.rehearsal = True
        players = scripted_players(runner, dict(zip(ids, ["blind", "deaf"])))
        for step in data.plan()[:4]:
            runner.run_game(step.participant, step.phase, step.game, players(step.participant, step.phase, step.game))
        runner.combine("phase2")
    ran = pairplay_cli("protocol", "mark-invalid", "s", INVALID, "--reason", "x", cwd=tmp_path)
    assert ran.stdout.endswith("no game was played on it\n")
    data = StudyData(tmp_path / "s")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        with pytest.raises(StudyDataError, match=rf"was made with {INVALID} .*: combine it again first"):
            runner.run_game("p01", "phase2", 0)
    ran = pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    started = [e for e in StudyData(tmp_path / "s").read_journal() if isinstance(e, j.GameStarted)
               and e.phase == "phase2"]
    assert [e.bias for e in started] == [V2, V2]
    with Bus(BusOptions()) as bus:  # made once, and again only when a game it took is marked invalid (it was
        # "the combiner refused: OutputError: exists (<path>)")
        with pytest.raises(StudyDataError, match=rf"the bias policy of phase2 is combined already \({V2}\)"):
            StudyRunner(StudyData(tmp_path / "s"), bus).combine("phase2")


def test_a_deletion_erases_the_participant_from_every_bias_policy_kept(played, tmp_path, pairplay_cli):
    """The earlier bias policy is kept: a participant's deletion knows it as it knows the current one."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    assert pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path).returncode == 0
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    gone = [e for e in StudyData(folder).read_journal() if isinstance(e, j.ParticipantDeleted)][-1]
    assert gone.merged_policies_using_them == [V1, V2]
    for output in (V1, V2):
        assert "p01" not in (folder / output).read_text()


def test_the_console_s_mark_answers_what_the_command_line_says(played, tmp_path):
    """The console's mark answered {"ok": "invalid"} and the page said "<session> marked invalid"."""
    from test_console_api import call
    from pairplay.services.console.server import ConsoleServer

    shutil.copytree(played, tmp_path / "s")
    data = StudyData(tmp_path / "s")
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        try:
            status, answer = call(f"{server.url}/api/console/control/invalid?token={server.token}",
                                  {"session": INVALID, "reason": "wrong instructions"})
            _, state = call(f"{server.url}/api/console/state?token={server.token}")
        finally:
            server.close()
    assert status == 200 and answer["said"].startswith(f"{INVALID} marked invalid: wrong instructions; the bias "
                                                       f"policy of phase2 ({V1}) was combined from it")
    assert state["next"]["label"] == "p01: phase1 game 2" and state["combined"]["phase2"]["flawed"]


def sessions_csv(folder: Path) -> dict[str, dict[str, str]]:
    with open(folder / "sessions.csv") as f:
        return {r["session"]: r for r in csv.DictReader(f)}


def test_a_deletion_keeps_the_flaw_without_the_id(played, tmp_path, pairplay_cli):
    """Deleting p01, whose game the bias policy took and was marked invalid since, removed the mark with them: status
    showed "[done] combine" and p02's phase-2 game plain done, sessions.csv `bias_flawed` was empty, the report
    flagged nothing, and the plan would play new games on the flawed file (a new user's trial, trial32 A)."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert f"merged policy made with their game marked invalid since: {V1} (kept flagged without their id, reason withheld: its participant was deleted" \
        in ran.stdout
    journal = (folder / "journal.jsonl").read_text()
    assert "p01" not in journal and "wrong instructions" not in journal  # kept without the id, nor their words
    kept = "made with a game of a deleted participant (marked invalid since: reason withheld: its participant was deleted)"
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout.splitlines()
    combine = next(line for line in status if "combine" in line)
    assert not combine.startswith("[done") and f"{V1} was {kept}" in combine
    p02 = next(x for x in status if "p02 (scripted:" in x and "phase2" in x)
    assert p02.startswith("[done   ]") and f"played on {V1}, {kept}" in p02
    assert sessions_csv(folder)[PHASE2[1]]["bias_flawed"] == kept
    state = Console(StudyRunner(StudyData(folder), None), "token").state()
    assert state["combined"]["phase2"]["flawed"] == kept
    ran = pairplay_cli("report", "s", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert f"played on a bias policy made with a game marked invalid since: {PHASE2[1]} ({V1})" in ran.stdout
    assert ("**Made with a game marked invalid since**: a game of a deleted participant (marked invalid since: "
            "reason withheld: its participant was deleted); not combined again yet") in (folder / "report" / "report.md").read_text()


def test_a_deletion_after_the_combination_again_keeps_the_earlier_one_flagged(played, tmp_path, pairplay_cli):
    """After the combination again (V2), p01's deletion left V1 "Replaced by V2." with no reason, and p02's game
    played on it unflagged in status, sessions.csv and the report."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    assert pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path).returncode == 0
    assert pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path).returncode == 0
    kept = "made with a game of a deleted participant (marked invalid since: reason withheld: its participant was deleted)"
    assert sessions_csv(folder)[PHASE2[1]]["bias_flawed"] == kept
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout
    assert "[done   ] combine" in status and f"played on {V1}, {kept}" in status  # V2 is sound: done
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    assert (f"**Made with a game marked invalid since**: a game of a deleted participant (marked invalid since: "
            f"reason withheld: its participant was deleted); replaced by `{V2}`") in (folder / "report" / "report.md").read_text()


def test_a_second_mark_is_refused_naming_the_first(played, tmp_path, pairplay_cli):
    """A second mark of the same game was accepted and its reason replaced the first in every reader."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    journal = (folder / "journal.jsonl").read_bytes()
    ran = pairplay_cli("protocol", "mark-invalid", "s", INVALID, "--reason", "again", cwd=tmp_path)
    assert ran.returncode == 2 and ran.stdout == ""
    line, = ran.stderr.splitlines()
    assert f"{INVALID} is marked invalid already (wrong instructions, 20" in line and line.endswith("nothing written")
    assert (folder / "journal.jsonl").read_bytes() == journal
    assert sessions_csv(folder)[INVALID]["invalid"] == "wrong instructions"


def test_one_game_on_the_flawed_policy_is_said_in_the_singular_and_a_marked_one_is_said_marked(played, tmp_path,
                                                                                               pairplay_cli):
    """"1 game played on it (...) stay valid ...: mark them invalid", the game marked already counted among those
    that "stay valid", and the report's "Games played on it" listed a game marked invalid as if counted."""
    shutil.copytree(played, tmp_path / "s")
    assert pairplay_cli("protocol", "mark-invalid", "s", PHASE2[0], "--reason", "fire alarm",
                        cwd=tmp_path).returncode == 0
    ran = pairplay_cli("protocol", "mark-invalid", "s", INVALID, "--reason", "wrong instructions", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert (f"; 1 game played on it ({PHASE2[1]}) stays valid, played honestly on the bias policy of their time (the "
            "report names it and flags it): mark it invalid too to have it played again on the new one\n") in ran.stdout
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    assert (f"Games played on it: {PHASE2[0]} (marked invalid: fire alarm), {PHASE2[1]}."
            in (tmp_path / "s" / "report" / "report.md").read_text())


def test_pilot_refuses_a_file_of_the_researcher_where_the_new_bias_policy_goes(played, tmp_path, pairplay_cli):
    """trial32 J: the file the docs name as the next bias policy, put there by the researcher (`pairplay combine
    ... -o s/merged/phase2-bias-v2.policy.json`), was removed and replaced by the combination, rc 0, no word.
    Now the combination refuses in one line naming it, and the file stays (tests/test_combine_place.py)."""
    folder, _ = marked(played, tmp_path, pairplay_cli)
    (folder / V2).write_text('{"mine": true}\n')
    ran = pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path)
    assert ran.returncode == 2, (ran.stdout, ran.stderr)
    assert ran.stderr.endswith(f"exists, not a combination of this study: move it away (s/{V2})\n"), ran.stderr
    assert len(ran.stderr.splitlines()) == 1, ran.stderr
    assert (folder / V2).read_text() == '{"mine": true}\n'
    assert [e.output for e in StudyData(folder).read_journal() if isinstance(e, j.BiasCombined)] == [V1]


def test_a_pilot_killed_as_it_combined_leaves_what_the_next_pilot_removes(played, tmp_path, pairplay_cli):
    """A real SIGKILL of `protocol pilot` once the combiner has written the new bias policy (its hidden name,
    before the link and the line): the next pilot removes it and combines into the same place; no other file
    of merged/ is touched."""
    import os
    import signal
    import subprocess
    import sys

    folder, _ = marked(played, tmp_path, pairplay_cli)
    env = dict(os.environ, PAIRPLAY_TEST_PAUSE=f"bias-written:{tmp_path / 'never'}")
    pilot = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "pilot", "s", "--personas", "blind,deaf"],
                             cwd=tmp_path, env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        for line in pilot.stderr:  # until it is held there (pairplay/testpause.py)
            if line.startswith("pairplay-test: paused at bias-written"):
                break
        hidden = [p.name for p in (folder / "merged").glob(".*.combining")]
        assert len(hidden) == 1 and hidden[0].startswith(".phase2-bias-v2.policy.json."), hidden
    finally:
        pilot.send_signal(signal.SIGKILL)
        pilot.wait()
        pilot.stderr.close()
    ran = pairplay_cli("protocol", "pilot", "s", "--personas", "blind,deaf", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert sorted(p.name for p in (folder / "merged").iterdir()) == sorted([Path(V1).name, Path(V2).name])
    assert [e.output for e in StudyData(folder).read_journal() if isinstance(e, j.BiasCombined)] == [V1, V2]
