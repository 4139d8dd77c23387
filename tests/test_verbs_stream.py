"""The verbs that read a recording read it as rebuild does (issue 16): streamed (reader.fold_log), not whole.

Before, verify, view, counterfactual and a study's report read every record of a file into a list, then every event
and its bytes (reader.read_any_log): a 5,000-round recording's verify peaked at 1.6 GB. Now each is given the events
a chunk's at a time (reader.stream_log) and keeps what it folds (the report: counts; verify: the events alone, which
it needs all at once); a file a stream cannot judge (a lost part, a message that does not decode, a seq read twice,
no session) is read whole, as before. What each verb makes is the same either way. Real recordings (the samples),
real damage (damageutil); the memory is tracemalloc's peak, no time is asserted.
"""

from __future__ import annotations

import dataclasses
import tracemalloc
from pathlib import Path

import pytest

from pairplay.replay import reader
from pairplay.replay.reader import NotStreamed, read_any_log

from damageutil import copies, lost_part, undecodable
from test_outputs import ONE_GAME_STUDY

SAMPLES = Path(__file__).resolve().parents[1] / "recordings" / "samples"
MANY = SAMPLES / "sim-helmut-fmt2.mcap"  # the samples' longest session


def peak_of(work) -> int:
    """tracemalloc's peak while `work()` runs (run once before: imports and caches are not counted)."""
    work()
    tracemalloc.start()
    try:
        work()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def whole_only(monkeypatch) -> None:
    """Every stream refused: the verbs read each file whole, as before."""
    def refused(path, only, each):
        raise NotStreamed(path)
    monkeypatch.setattr(reader, "stream_log", refused)


def files(tmp_path) -> list[Path]:
    """The samples and files a stream cannot judge (each read whole)."""
    made = []
    for make in (lost_part, undecodable, copies):
        made.append(tmp_path / f"{make.__name__}.mcap")
        make(made[-1])
    return [SAMPLES / n for n in ("sim-helmut-fmt2.mcap", "sim-ashley.mcap", "human-board-fmt2.mcap",
                                  "console-fmt2.mcap")] + made


# -- verify ---------------------------------------------------------------------------------------------------------

def test_verify_holds_the_events_not_the_files_records_and_bytes():
    # verify read the file whole (its records, then every event and its bytes): its peak was above the whole read's
    # (18.5x the file's size here); it keeps the events alone now (8.4x)
    from pairplay.services.verify import verify_recording

    verified = peak_of(lambda: verify_recording(MANY))
    whole = peak_of(lambda: read_any_log(MANY))
    assert verified < 0.7 * whole, (verified, whole)


def test_verify_says_of_a_file_streamed_what_it_says_of_it_read_whole(tmp_path, monkeypatch):
    from pairplay.services.verify import verify_recording

    paths = files(tmp_path)
    streamed = [dataclasses.asdict(verify_recording(p)) for p in paths]
    whole_only(monkeypatch)
    assert streamed == [dataclasses.asdict(verify_recording(p)) for p in paths]



def never_whole(monkeypatch) -> None:
    """A file read whole (the reader's list of every record) fails the test."""
    def whole(path, only=None):
        raise AssertionError(f"{path} read whole")
    monkeypatch.setattr(reader, "_read_log", whole)


def test_replay_verify_reads_a_whole_file_once_as_it_comes(monkeypatch, capsys):
    # `replay --verify` read the file whole to check it holds a session, kept that read, and verify read it again
    from pairplay.cli.main import main

    never_whole(monkeypatch)
    assert main(["replay", str(MANY), "--verify"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "verify: PASS"

# -- a study's report -----------------------------------------------------------------------------------------------

STUDY = ONE_GAME_STUDY.replace("rounds = 1\n", "rounds = 40\n")  # one scripted game of 40 rounds


@pytest.fixture(scope="module")
def study(tmp_path_factory, pairplay_cli) -> Path:
    """A study folder with one scripted game of 40 rounds played over the bus (`protocol pilot`)."""
    where = tmp_path_factory.mktemp("study")
    (where / "one.toml").write_text(STUDY)
    for args in (("protocol", "init", "pf", "--study", "one.toml"), ("protocol", "register", "pf"),
                 ("protocol", "pilot", "pf", "--personas", "blind", "-q")):
        ran = pairplay_cli(*args, cwd=where, timeout=180)
        assert ran.returncode == 0, ran.stderr
    return where / "pf"


def test_a_reports_read_of_a_game_holds_a_chunk_not_the_file(study):
    # every game's recording was read whole (its records, every event and its bytes): 19.6x the file's size here,
    # for each game of a report; its stats are folded as the file is read now (2.5x)
    from pairplay.replay.studydata import StudyData
    from pairplay.report.human import StatsFold

    data = StudyData(study)
    g = next(iter(data.state.games.values()))
    path, _ = data.game_recording(g)
    read = peak_of(lambda: data.recording_of(g, lambda: StatsFold(40)))
    whole = peak_of(lambda: read_any_log(path))
    assert read < 0.3 * whole, (read, whole)


def test_a_report_of_games_streamed_is_the_report_of_them_read_whole(study, tmp_path, monkeypatch):
    from pairplay.report.human import human_report

    streamed = human_report(study, tmp_path / "streamed")
    whole_only(monkeypatch)
    whole = human_report(study, tmp_path / "whole")
    assert [dataclasses.asdict(s) for s in streamed.games] == [dataclasses.asdict(s) for s in whole.games]
    assert streamed.games[0].picks and len(streamed.games[0].picks) == 40
    for name in ("picks.csv", "attention.csv", "report.md"):
        assert (tmp_path / "streamed" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name


def test_a_report_never_reads_a_game_whole(study, tmp_path, monkeypatch):
    from pairplay.report.human import human_report

    never_whole(monkeypatch)
    assert len(human_report(study, tmp_path / "report").games) == 1


# -- counterfactual ---------------------------------------------------------------------------------------------------

def test_a_fits_read_holds_the_events_not_the_files_records_and_bytes():
    # counterfactual's recording and every --fit-also one were read whole (records, events, bytes): 17x the file's size
    from pairplay.replay.turns import read_turns

    fitted = peak_of(lambda: read_turns(MANY))
    whole = peak_of(lambda: read_any_log(MANY))
    assert fitted < 0.7 * whole, (fitted, whole)


def test_turns_read_as_they_come_are_the_turns_read_whole(tmp_path, monkeypatch):
    from pairplay.errors import InputError
    from pairplay.replay.turns import read_turns

    def turns(path):
        try:
            t = read_turns(path)
        except InputError as err:
            return str(err)
        return (t.config, t.picks_per_round, t.note, t.skipped, t.started,
                [a.tolist() for a in t.observations])

    paths = files(tmp_path)
    streamed = [turns(p) for p in paths]
    whole_only(monkeypatch)
    assert streamed == [turns(p) for p in paths]


# -- view -----------------------------------------------------------------------------------------------------------

def test_a_views_read_holds_the_events_not_the_files_records_and_bytes():
    # the view drew from the file read whole (its records, every event and its bytes); it needs every event before
    # it draws (what the file lost names the .rrd), and keeps them alone now
    from pairplay.services.view.sources import recording_items

    drawn = peak_of(lambda: list(recording_items(MANY)))
    whole = peak_of(lambda: read_any_log(MANY))
    assert drawn < 0.7 * whole, (drawn, whole)


def test_view_reads_a_whole_file_once_as_it_comes(monkeypatch, tmp_path, capsys):
    from pairplay.cli.main import main

    never_whole(monkeypatch)
    assert main(["view", "--recording", str(MANY), "--out", str(tmp_path / "v.rrd")]) == 0
    assert (tmp_path / "v.rrd").stat().st_size > 0


def test_a_view_drawn_as_read_is_the_view_of_the_file_read_whole(tmp_path, monkeypatch):
    from pairplay.services.view.sources import recording_items

    paths = files(tmp_path)
    drawn = [list(recording_items(p)) for p in paths]
    whole_only(monkeypatch)
    assert drawn == [list(recording_items(p)) for p in paths]


# -- what a session's end says of its recording ---------------------------------------------------------------------

def test_a_sessions_summary_reads_its_recording_once_as_it_comes(monkeypatch, tmp_path, capsys):
    # `pairplay session` and `pairplay lab` read their recording back whole for their summary (cli/session.py
    # read_back): a 5,000-round session's was 930 MB
    from pairplay.cli.main import main

    never_whole(monkeypatch)
    code = main(["session", "--participant", "sim:blind", "--rounds", "2", "--session", "sum", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    monkeypatch.undo()
    assert code == 0 and f"recorded {len(read_any_log(tmp_path / 'sum.mcap').events)} events" in out, out


def test_a_study_games_end_is_summed_up_as_its_recording_is_read(study, tmp_path, monkeypatch):
    # a study server's game end (studydata.game_end), a cut game's end (cutgame.cut_end), whether a game's file is
    # finished, another game's file and the robot's acts (services/protocol.py) read the recording whole
    from pairplay.replay import studydata
    from pairplay.replay.cutgame import cut_end
    from pairplay.replay.studydata import StudyData, game_end

    data = StudyData(study)
    g = next(iter(data.state.games.values()))
    path, _ = data.game_recording(g)
    said = (game_end(tmp_path, g.session, g.participant, path), cut_end(path, path, g.session),
            studydata._finished_game(path), data._not_this_games_file(g, path))
    never_whole(monkeypatch)
    assert (game_end(tmp_path, g.session, g.participant, path, force=True), cut_end(path, path, g.session),
            studydata._finished_game(path), data._not_this_games_file(g, path)) == said
    assert said[0].outcome == "completed" and said[1].rounds == 40 and said[2] and said[3] == ""
