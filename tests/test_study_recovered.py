"""A study game whose recording was cut, then completed by `pairplay recover`, is read from the recovered copy.

A new user's trial: `pairplay recover` of a cut game's recording writes `<stem>.recovered.mcap` beside it, but the
study kept naming the cut file, so every `protocol serve`, `pilot` and `report` said "not finished ... recover
completes it" after the user had done exactly that. Now the study reads the recovered copy when its game's
recording was not finished (its recorder's journal beside it) or is gone (recover's line says to remove the two
once the copy is kept), says it does (replay/studydata.py `game_recording`), and the line before recover names
the command and what the next verb does then. Real processes: `pairplay report` and `pairplay recover`.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log
from pairplay.replay.studydata import StudyData
from pairplay.replay.wal import JournalWriter, wal_path
from pairplay.schemas import journal as j

from damageutil import _rewritten
from test_protocol_interrupted import completed_without_policy


def cut_by_a_crash(path: Path, session: str) -> None:
    """The game's finished recording made what a killed recorder leaves: the file cut, and its journal
    beside it holding everything the recorder received."""
    events = read_log(path).events
    # written again in 4 KB chunks first: the recorder's chunks follow its flush timing, and a short game may be
    # one chunk, whose cut took round 1 too (the report then said "no whole round": a fresh-clone CI run)
    end = _rewritten(path, "SessionEnded", broken=False)
    [chunk] = [c for c in scan(path).chunks if any(t == end for _, _, t in c.messages)]
    path.write_bytes(path.read_bytes()[:chunk.offset + chunk.length // 2])  # inside the chunk of its end
    journal = JournalWriter(path, session)
    for r in events:
        journal.add((r.key, r.payload))
    journal.close()
    assert not read_log(path).of("SessionEnded")


def test_a_cut_games_recording_recovered_is_built_from_its_recovered_copy_and_said(tmp_path, pairplay_cli):
    data = completed_without_policy(tmp_path, stripped=1)
    games = list(data.state.games.values())
    built, unended = games[0], games[1]  # completed without its policy; its end never journaled
    ends = [e for e in data.read_journal() if not (isinstance(e, j.GameEnded) and e.session == unended.session)]
    (data.folder / "journal.jsonl").write_bytes(b"".join(j.encode_line(e) for e in ends))
    for g in (built, unended):
        cut_by_a_crash(data.folder / g.recording, g.session)
    folder = data.folder
    ran = pairplay_cli("report", folder)
    recording = folder / built.recording
    assert (f"pairplay report: {built.session}: completed, but no policy built: its recording {built.recording} was "
            f"not finished (its recorder's journal is beside it: `pairplay recover {recording}` writes its recovered "
            "copy beside it, which the next serve, pilot or report builds it from)") in ran.stderr.splitlines(), ran
    # the report leaves the cut game out, saying why and where the rest of it is
    [left_out] = [line for line in (folder / "report" / "report.md").read_text().splitlines()
                  if f"{built.session} (recording" in line]
    assert f"no SessionEnded: its rounds are a part of the game; its recorder's journal {recording.name}.journal beside " \
           f"it holds " in left_out and f"`pairplay recover {recording}` adds them" in left_out, left_out
    # cut, its end not journaled: journaled from the end its recorder's journal holds, and said (it was silent, then
    # shown as running until recovered: tests/test_protocol_cut_game.py)
    [line] = [line for line in ran.stderr.splitlines() if unended.session in line]
    unended_path = folder / unended.recording
    assert line == (f"pairplay report: {unended.session}: journaled completed from its cut recording "
                    f"{unended.recording}: it was cut after the game's end (its SessionEnded is in its recorder's "
                    f"journal beside it); its policy: `pairplay recover {unended_path}` writes its recovered copy, "
                    "which the next serve, pilot or report builds it from"), line
    for g in (built, unended):
        ran = pairplay_cli("recover", folder / g.recording)
        assert ran.returncode == 0, ran
    ran = pairplay_cli("report", folder, "--force")
    said = [line for line in ran.stderr.splitlines() if "recovered" in line]
    stem = Path(built.recording).stem
    assert said == [f"pairplay report: {built.session}: policy built from its recovered copy "
                    f"recordings/{stem}.recovered.mcap: policies/{stem}.recovered.policy.json",
                    f"pairplay report: {unended.session}: policy built from its recovered copy "
                    f"recordings/{Path(unended.recording).stem}.recovered.mcap: "
                    f"policies/{Path(unended.recording).stem}.recovered.policy.json"], ran.stderr
    state = StudyData(folder).state
    assert state.games[built.session].ended.policy == f"policies/{stem}.recovered.policy.json"
    assert state.games[unended.session].ended.outcome == "completed" and state.games[unended.session].ended.policy
    assert "recovered" not in pairplay_cli("report", folder, "--force").stderr  # said once
    # the participant's export carries the copy that stands for the game's recording (it held the cut file only)
    ran = pairplay_cli("participant", "export", folder, built.participant)
    assert ran.returncode == 0, ran
    with zipfile.ZipFile(folder / "exports" / f"{built.participant}.zip") as z:
        assert any(n.endswith(f"{stem}.recovered.mcap") for n in z.namelist()), z.namelist()
    # the cut file and its journal removed, as recover's line says once the copy is kept: the copy still stands
    (folder / built.recording).unlink()
    wal_path(folder / built.recording).unlink()
    reread = StudyData(folder)
    path, named = reread.game_recording(reread.state.games[built.session])
    assert path.name == f"{stem}.recovered.mcap" and named.startswith("its recovered copy")
    log, _, why = reread.recording_of(reread.state.games[built.session])
    assert log is not None and why == "", why
