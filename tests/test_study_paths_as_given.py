"""What a verb says of a study folder names its paths as the user typed them (a new user's trial, 2026-12-01:
`pairplay report st` of a folder with a malformed settings.json said "/tmp/.../st/settings.json: not the study's
settings", `protocol pilot st` named the resolved path of a recording the journal does not list, and `protocol
status` and `pilot` told to run `pairplay protocol register /tmp/.../st`). The folder is resolved only to be
read (replay/studydata.py StudyData.given). Real parts: study folders made by `protocol init`, played by a
scripted persona over a real loopback bus (test_no_session's fixture), the real verbs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from test_no_session import STUDY, study  # noqa: F401 (the played study folder fixture)

from pairplay.cli.main import main

SETTINGS_WORDS = 'not the study\'s settings: must be a table, got a list; it is {"key_file": "<path or empty>"}'


@pytest.mark.parametrize("argv", [["report", "st"], ["participant", "export", "st", "p01"], ["protocol", "status", "st"],
                                  ["protocol", "pilot", "st", "--personas", "blind"]], ids=" ".join)
def test_a_malformed_settings_file_is_named_as_typed(study, tmp_path, monkeypatch, capsys, argv):  # noqa: F811
    monkeypatch.chdir(tmp_path)
    shutil.copytree(study, "st")
    Path("st/settings.json").write_text("[1]")
    capsys.readouterr()
    assert main(argv) == 2
    out, err = capsys.readouterr()
    who = " ".join(argv[:2] if argv[0] in ("participant", "protocol") else argv[:1])
    assert (out, err) == ("", f"pairplay {who}: {SETTINGS_WORDS} (st/settings.json)\n")


def test_pilot_names_a_recording_the_journal_does_not_list_and_the_next_steps_as_typed(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    text = STUDY.read_text()
    text = text[:text.index("# Phase 2")] + text[text.index("# The questions behind"):]  # phase 1 alone
    Path("one.toml").write_text(text.replace("games = 2\nrounds = 2", "games = 1\nrounds = 1", 1))
    capsys.readouterr()
    assert main(["protocol", "init", "st", "--study", "one.toml"]) == 0
    assert capsys.readouterr().out.startswith("study folder st (pilot); key file: none\n")
    assert main(["protocol", "status", "st"]) == 0
    assert "nobody is registered: `pairplay protocol register st` first" in capsys.readouterr().out
    assert main(["protocol", "register", "st", "-q"]) == 0
    Path("st/recordings/pilot-p01-phase1-g1.mcap").write_bytes(b"x")  # a copied folder's file, not journaled
    capsys.readouterr()
    assert main(["protocol", "pilot", "st", "--personas", "blind"]) == 2
    err = capsys.readouterr().err
    assert err.endswith("; the journal does not list it; move it away (st/recordings/pilot-p01-phase1-g1.mcap)\n"), err
    Path("st/recordings/pilot-p01-phase1-g1.mcap").unlink()
    assert main(["protocol", "pilot", "st", "--personas", "blind"]) == 0
    assert "plan complete; `pairplay report st` writes the report" in capsys.readouterr().out
