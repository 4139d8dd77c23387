"""A combination's bias policy never removes nor replaces a file it cannot prove its own (services/biasfile.py).

Before (trial32 J): every combination first removed whatever stood at its place, meant for a killed
combination's leftover; a researcher's own file there (`pairplay combine ... -o st/merged/phase2-bias-v2...`,
the name the docs give) went without a word, rc 0. Now only what a killed combination provably left is
removed (a hidden name carrying its request id, or the file linked from one that no line names), and any
other file there is refused in one line naming it, left as it was: from the runner, the console's step and
`protocol pilot` (tests/test_protocol_reinvalid.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from test_console_api import call
from test_protocol_interrupted import completed_without_policy

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.schemas import journal as j
from pairplay.services import biasfile
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner

OUT = "merged/phase2-bias.policy.json"
MINE = '{"mine": true}\n'
HIDDEN = ".phase2-bias.policy.json.0123456789ab.combining"  # a name biasfile.temp_name gives


def combine(data: StudyData) -> j.BiasCombined:
    with Bus(BusOptions()) as bus:
        return StudyRunner(data, bus).combine("phase2")


def combinations(folder: Path) -> list[j.BiasCombined]:
    return [e for e in StudyData(folder).read_journal() if isinstance(e, j.BiasCombined)]


def refused(data: StudyData) -> str:
    return f"{biasfile.REFUSED} ({data.given / OUT})"


def test_a_file_of_the_researcher_at_its_place_is_refused_in_one_line_and_kept(tmp_path):
    data = completed_without_policy(tmp_path, stripped=0)
    (data.folder / "merged").mkdir(exist_ok=True)
    (data.folder / OUT).write_text(MINE)
    with pytest.raises(StudyDataError) as err:
        combine(data)
    assert str(err.value) == refused(data)
    assert (data.folder / OUT).read_text() == MINE
    assert sorted(p.name for p in (data.folder / "merged").iterdir()) == ["phase2-bias.policy.json"]
    assert not combinations(data.folder)
    (data.folder / OUT).rename(tmp_path / "mine.json")  # moved away, as the line says: the step goes on
    assert combine(StudyData(data.folder)).output == OUT and len(combinations(data.folder)) == 1


def test_a_file_put_at_its_place_while_it_combines_is_refused_and_kept(tmp_path, monkeypatch):
    """Between the check and the link (the researcher's own `pairplay combine -o` that minute): the link
    refuses it (before, the file was the combiner's own or replaced it)."""
    data = completed_without_policy(tmp_path, stripped=0)
    merged, go = data.folder / "merged", tmp_path / "go"
    monkeypatch.setenv("PAIRPLAY_TEST_PAUSE", f"bias-written:{go}")

    def researcher():  # once the combiner has written (its hidden name, or before, its place)
        while not (list(merged.glob(".*.combining")) or (data.folder / OUT).exists()):
            time.sleep(0.01)
        (data.folder / OUT).write_text(MINE)
        go.touch()
    thread = threading.Thread(target=researcher, daemon=True)
    thread.start()
    with pytest.raises(StudyDataError) as err:
        combine(data)
    thread.join(10)
    assert str(err.value) == refused(data)
    assert (data.folder / OUT).read_text() == MINE
    assert sorted(p.name for p in merged.iterdir()) == ["phase2-bias.policy.json"]  # nor the hidden one left
    assert not combinations(data.folder)


def _dead_pid() -> int:
    ran = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                         check=True)
    return int(ran.stdout)


@pytest.mark.parametrize("killed", ["while the combiner wrote", "before its link", "before its line"])
def test_what_a_killed_combination_left_is_removed_and_the_step_combined_again(tmp_path, killed):
    """The states a SIGKILL leaves (services/biasfile.py rule), made from a combination whose line is then
    taken out of the journal: each goes, nothing else does, and the step is combined into its place."""
    data = completed_without_policy(tmp_path, stripped=0)
    combine(data)
    journal = data.folder / "journal.jsonl"
    journal.write_bytes(b"".join(j.encode_line(e) for e in data.read_journal() if not isinstance(e, j.BiasCombined)))
    merged = data.folder / "merged"
    if killed == "while the combiner wrote":  # pairplay/outputs.py's temporary of the hidden name
        (merged / OUT.split("/")[1]).rename(merged / f".{HIDDEN}.{_dead_pid()}.abcdef.tmp")
    elif killed == "before its link":
        (merged / OUT.split("/")[1]).rename(merged / HIDDEN)
    else:
        os.link(data.folder / OUT, merged / HIDDEN)
    (merged / "notes.txt").write_text("mine\n")  # the researcher's, beside them: never touched
    combined = combine(StudyData(data.folder))
    assert combined.output == OUT and len(combinations(data.folder)) == 1
    assert json.loads((data.folder / OUT).read_text())["merged_from"]
    assert sorted(p.name for p in merged.iterdir()) == ["notes.txt", "phase2-bias.policy.json"]


def test_a_hidden_name_beside_the_file_its_line_names_goes_and_the_file_stays(tmp_path):
    """Killed after the line, before the hidden name's removal: the next combination removes that name only."""
    data = completed_without_policy(tmp_path, stripped=0)
    combine(data)
    os.link(data.folder / OUT, data.folder / "merged" / HIDDEN)
    biasfile.remove_leftovers(data.folder, "merged/phase2-bias-v2.policy.json", {OUT})
    assert sorted(p.name for p in (data.folder / "merged").iterdir()) == ["phase2-bias.policy.json"]
    assert json.loads((data.folder / OUT).read_text())["merged_from"]


def test_a_file_of_its_name_not_linked_from_the_hidden_one_is_refused_not_removed(tmp_path):
    """A hidden name and a file at the place that are not one file: the file is not provably ours."""
    data = completed_without_policy(tmp_path, stripped=0)
    merged = data.folder / "merged"
    merged.mkdir(exist_ok=True)
    (merged / HIDDEN).write_text("{}")
    (data.folder / OUT).write_text(MINE)
    with pytest.raises(StudyDataError) as err:
        combine(data)
    assert str(err.value) == refused(data)
    assert sorted(p.name for p in merged.iterdir()) == ["phase2-bias.policy.json"]
    assert (data.folder / OUT).read_text() == MINE


def test_the_console_s_next_step_says_the_refusal_and_goes_on(tmp_path):
    """The console's "Run the next step" on a combination whose place holds a file: the step says the
    refusal, the file is kept, the console answers on."""
    from pairplay.services.console.server import ConsoleServer

    data = completed_without_policy(tmp_path, stripped=0)
    (data.folder / "merged").mkdir(exist_ok=True)
    (data.folder / OUT).write_text(MINE)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        try:
            t = server.token
            status, answer = call(f"{server.url}/api/console/next?token={t}", {})
            assert status == 200 and answer["started"].startswith("combine"), answer
            while True:  # the step's thread: until it has ended (no deadline asserted)
                status, state = call(f"{server.url}/api/console/state?token={t}")
                if not state["busy"]:
                    break
                time.sleep(0.05)
            status, again = call(f"{server.url}/api/console/state?token={t}")
        finally:
            server.close()
    assert state["last"] == {"step": answer["started"], "ok": False, "message": refused(data)}, state["last"]
    assert status == 200 and again["next"]["kind"] == "combine" and not again["next"]["done"]
    assert (data.folder / OUT).read_text() == MINE and not combinations(data.folder)
