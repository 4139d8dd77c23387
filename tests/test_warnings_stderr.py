"""A warning about a verb's result is one line on stderr, -q or not (cli/main.py `warn`; a new user's trial,
2026-12-01: `replay` printed its "not whole" note on stdout, -q or not; counterfactual's, rebuild's and view's notes
of a damaged input went with their summary under -q: the damage hidden).

Real parts: a real recording (the recorder's writer, small chunks) damaged on disk as a disk would (a middle chunk
overwritten: events lost; the summary's tail zeroed: no event lost), a study folder played over a real loopback bus,
the real verbs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from damageutil import small_chunked_session
from test_no_session import study  # noqa: F401 (the study folder fixture)

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    return small_chunked_session(tmp_path_factory.mktemp("warn") / "whole.mcap", "warn")


def _damaged(whole: Path, kind: str, path: Path) -> Path:
    data = bytearray(whole.read_bytes())
    if kind == "events lost":  # a middle chunk overwritten: its events are lost
        c = scan(whole).chunks[len(scan(whole).chunks) // 2]
        data[c.offset + c.length // 2:c.offset + c.length // 2 + 16] = b"\xff" * 16
    else:  # the summary's tail zeroed: every event read, the file damaged
        data[-100:] = bytes(100)
    path.write_bytes(bytes(data))
    return path


VERBS = {"replay": ["replay", "rec.mcap", "--speed", "max"],
         "counterfactual": ["counterfactual", "rec.mcap", "--fit-only", "--out", "cf"],
         "rebuild": ["rebuild", "rec.mcap", "--partial", "--no-plot", "--out", "rb"],
         "view": ["view", "--recording", "rec.mcap", "--out", "v.rrd"]}


@pytest.mark.parametrize("quiet", [False, True], ids=["", "-q"])
@pytest.mark.parametrize("kind", ["events lost", "no event lost"])
@pytest.mark.parametrize("verb", list(VERBS))
def test_a_verb_says_its_input_is_not_whole_on_stderr_quiet_or_not(whole, tmp_path, monkeypatch, capsys, verb, kind,
                                                                   quiet):
    monkeypatch.chdir(tmp_path)
    log = read_log(_damaged(whole, kind, tmp_path / "rec.mcap"))
    capsys.readouterr()
    assert main(VERBS[verb] + (["-q"] if quiet else [])) == 0
    out, err = capsys.readouterr()
    if kind == "no event lost":
        said = f"pairplay {verb}: rec.mcap: {log.loss_free}"
    else:
        said = {"replay": f"pairplay replay: rec.mcap: not whole ({log.missing}); replaying the ",
                "counterfactual": f"pairplay counterfactual: rec.mcap: not whole ({log.missing}); fitting the ",
                "rebuild": f"pairplay rebuild: rec.mcap: PARTIAL session: {log.missing}",
                "view": f"pairplay view: rec.mcap is damaged ({log.lost}); the view is partial"}[verb]
    assert said in err, err
    brief = log.brief.split(" (")[0]  # the damaged part: on stderr only, never on stdout
    assert brief not in out, out
    if quiet:
        assert out == "" or verb == "replay" and out.startswith("replaying session "), out


def test_the_report_says_a_recording_read_whole_from_a_damaged_file_on_stderr_quiet_or_not(
        study, tmp_path, monkeypatch, capsys):  # noqa: F811
    monkeypatch.chdir(tmp_path)
    shutil.copytree(study, "st")
    [rec] = list(Path("st/recordings").glob("*.mcap"))
    data = bytearray(rec.read_bytes())
    data[-100:] = bytes(100)  # the summary's tail: no event lost, the file damaged
    rec.write_bytes(bytes(data))
    assert read_log(rec).loss_free
    capsys.readouterr()
    for quiet in ([], ["-q"]):
        assert main(["report", "st", "--force", *quiet]) == 0
        out, err = capsys.readouterr()
        assert err.startswith(f"pairplay report: read whole from a damaged file: {rec.stem} (the file is damaged, "
                              "no event lost"), err
        assert "damaged" not in out, out
