"""`pairplay rebuild` of a batch of recordings (`rebuild recordings/*.mcap`): one recording that holds no whole
round, and one session in two files (X.mcap and the X.recovered.mcap `recover` writes beside it); and the same
session given twice to counterfactual's fit (cli/rebuild.py `rebuilt_each`, replay/onesession.py; trial30 #3, #4).
The files are the frozen sample, written again with the mcap library's own Writer (tests/rewrite_mcap.py)."""

from __future__ import annotations

import json
import shutil

from pairplay.cli.main import main

from rewrite_mcap import SAMPLE, rewritten


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    said = capsys.readouterr()
    return code, said.out + said.err


def _no_whole_round(path):
    """The sample up to its first RoundEnded: a session stopped in round 1, the file whole."""
    cut = [False]

    def each(channel, message):
        cut[0] = cut[0] or channel.topic.endswith("/RoundEnded")
        return [] if cut[0] else [message]
    return rewritten(path, each=each)


def test_a_recording_of_no_whole_round_in_a_batch_says_to_leave_it_out_and_partial_rebuilds_the_others(tmp_path,
                                                                                                       capsys):
    """trial30 #3: `rebuild recordings/*.mcap --out X [--partial]` with one session interrupted at once among them
    refused the whole batch, --partial or not, and the line did not say what to do. Without --partial it is
    still refused (nothing written), saying to leave it out or give --partial; with it, that file is left out and
    said, the others rebuilt; a batch of no whole round at all is still refused."""
    whole = shutil.copy(SAMPLE, tmp_path / "whole.mcap")
    empty = _no_whole_round(tmp_path / "empty.mcap")
    code, out = _run(capsys, "rebuild", whole, empty, "--out", tmp_path / "a")
    [line] = out.splitlines()
    assert code == 2 and "holds no whole round" in line and "leave it out, or --partial rebuilds the others" in line
    assert line.endswith(f"({empty})") and not (tmp_path / "a").exists(), line
    code, out = _run(capsys, "rebuild", whole, empty, "--out", tmp_path / "b", "--partial")
    assert code == 0 and f"{empty}: left out (--partial): holds no whole round" in out, out
    assert sorted(p.name for p in (tmp_path / "b").iterdir() if not p.name.startswith(".")) == \
        ["learning-curves.png", "whole.curve.csv", "whole.policy.json"]
    assert not json.loads((tmp_path / "b" / "whole.policy.json").read_text())["partial"]
    again = shutil.copy(empty, tmp_path / "again.mcap")
    code, out = _run(capsys, "rebuild", empty, again, "--out", tmp_path / "c", "--partial")
    [line] = out.splitlines()
    assert code == 2 and "none of the 2 recordings holds a whole round" in line and not (tmp_path / "c").exists()


def test_one_session_in_two_files_of_a_batch_is_refused_naming_both(tmp_path, capsys):
    """trial30 #4: a recording and the copy `pairplay recover` wrote beside it were rebuilt into two policies of
    one session, exit 0 (profile and combine then refused the folder). Refused in one line naming both, and
    which is the recovered copy; nothing written. A copy under another name is the same session too; so is a
    recording given to counterfactual's fit twice under two names (its turns counted double)."""
    cut = tmp_path / "x.mcap"
    cut.write_bytes(SAMPLE.read_bytes()[:-200])  # cut in its summary: `recover` writes x.recovered.mcap
    assert _run(capsys, "recover", cut)[0] == 0
    copy = tmp_path / "x.recovered.mcap"
    code, out = _run(capsys, "rebuild", cut, copy, "--out", tmp_path / "rb")
    [line] = out.splitlines()
    assert code == 2 and f"{cut} and {copy} hold the same session 'sample-sim-ashley'" in line, line
    assert "x.recovered.mcap was recovered from x.mcap" in line and not (tmp_path / "rb").exists(), line
    other = shutil.copy(SAMPLE, tmp_path / "other.mcap")
    code, out = _run(capsys, "rebuild", SAMPLE, other, "--out", tmp_path / "rb", "--partial")
    assert code == 2 and f"{SAMPLE} and {other} hold the same session" in out and not (tmp_path / "rb").exists()
    code, out = _run(capsys, "counterfactual", SAMPLE, "--fit-also", other, "--fit-only", "--out", tmp_path / "cf")
    assert code == 2 and f"{SAMPLE} and {other} hold the same session" in out and not (tmp_path / "cf").exists()
