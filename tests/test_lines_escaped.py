"""A path or a value with a newline (or another control character) is shown escaped: one line stays one line.

Trial28 F10: `rebuild`, `view` and `recover` of `x<newline>y.mcap` printed their result lines split at the
newline, and `session --participant $'sim:ash\\nley'` ended its refusal "(--participant sim:ash" NEWLINE
"ley)": two lines on stderr. The shared helper is pairplay/errors.py `escaped`, used by every error line
(UserError.line, cli/main.py) and by the result lines of every verb. Trial29 F4: `protocol init`, `protocol
pilot`'s last line and `participant export` (and the result lines of the other protocol verbs and `sweep`) still
printed a path raw; a command a line suggests (`pairplay report <folder>`) now gives the path as a shell word
(`command_word`), which typed into bash is the path.
"""

from __future__ import annotations

import shutil

import pytest

from pairplay.errors import UserError, escaped

ODD = "x\ny"


@pytest.fixture(scope="module")
def odd_recording(tmp_path_factory, pairplay_cli):
    """A real recording, copied to a path whose folder and name hold a newline."""
    root = tmp_path_factory.mktemp("odd")
    done = pairplay_cli("session", "--participant", "sim:ashley", "--session", "s1", "--rounds", "2",
                        "--out", str(root / "rec"), "--quiet")
    assert done.returncode == 0, done.stderr
    folder = root / f"dir {ODD}"
    folder.mkdir()
    path = folder / f"nl{ODD}name.mcap"
    shutil.copy(root / "rec" / "s1.mcap", path)
    return path


def test_a_refused_value_with_a_newline_is_one_line(pairplay_cli, tmp_path):
    done = pairplay_cli("session", "--participant", f"sim:ash{ODD}", "--rounds", "1", "--out", str(tmp_path))
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.rstrip("\n").endswith("(--participant sim:ashx\\ny)"), done.stderr


def test_rebuild_view_and_recover_say_an_odd_path_on_its_own_lines(pairplay_cli, odd_recording):
    shown = escaped(odd_recording)
    assert "\\n" in shown and "\n" not in shown
    out = odd_recording.parent / "out"
    done = pairplay_cli("rebuild", str(odd_recording), "--out", str(out))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 3 and lines[0].startswith(f"{shown}: ") and escaped(out) in lines[1], done.stdout

    done = pairplay_cli("recover", str(odd_recording), "-o", str(odd_recording.parent / "r.mcap"))
    assert done.returncode == 0 and done.stdout.count("\n") == 1 and done.stdout.startswith(f"{shown}: "), done.stdout

    rrd = odd_recording.parent / f"v{ODD}.rrd"
    done = pairplay_cli("view", "--recording", str(odd_recording), "--out", str(rrd))
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("\n") == 1 and done.stdout.startswith(f"saved {escaped(rrd)}: "), done.stdout

    done = pairplay_cli("view", "--recording", str(odd_recording), "--out", str(rrd))  # exists: refused, one line
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and escaped(rrd) in done.stderr, done.stderr


def test_escaped_shows_each_control_character_and_leaves_the_rest():
    assert escaped("a\nb\tc\x1b[2J\u2028\udcff é") == "a\\nb\\tc\\x1b[2J\\u2028\\udcff é"
    assert escaped("plain/path.mcap") == "plain/path.mcap"
    assert UserError("no such recording", "x\ny.mcap").line() == "no such recording (x\\ny.mcap)"


def test_a_sessions_result_line_names_its_odd_folder_escaped(pairplay_cli, tmp_path):
    out = tmp_path / f"o{ODD}ut"
    done = pairplay_cli("session", "--participant", "sim:ashley", "--session", "s9", "--rounds", "1", "--out", str(out))
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stdout.splitlines() if line.startswith("recorded ")]
    assert said and said[0].endswith(f" to {escaped(out / 's9.mcap')}"), done.stdout


# trial29 F4, the whole kind: every result line that names a path the user gave, escaped, and a command it suggests
# typeable (pairplay/errors.py `command_word`). A newline, a tab and an escape in the folders' names.
CONTROL = "n\nt\te\x1b["
GRID_TEXT = ('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\neval_rounds = 5\n'
             '[grid]\nreward_bonus = ["correct", "consistent"]\n')


@pytest.fixture(scope="module")
def said(tmp_path_factory, pairplay_cli):
    """Each verb's run on the odd folders, in the order a user would: {case: (CompletedProcess, the line expected)}."""
    from pathlib import Path

    from pairplay.errors import command_word

    root = tmp_path_factory.mktemp("odd") / f"we ird {CONTROL}"
    root.mkdir()
    folder, key = root / f"st{CONTROL}udy", root / f"k{CONTROL}ey.csv"
    study = Path(__file__).parent / "data" / "pilot-study.toml"
    out = {}
    done = pairplay_cli("protocol", "init", folder, "--study", study, "--key-file", key)
    out["protocol init"] = done, escaped(f"study folder {folder} (pilot); key file: {key}")
    done = pairplay_cli("protocol", "status", folder)
    out["protocol status"] = done, f"nobody is registered: `pairplay protocol register {command_word(folder)}` first"
    assert pairplay_cli("protocol", "register", folder, "--count", "2").returncode == 0
    done = pairplay_cli("protocol", "pilot", folder, "--personas", "blind,deaf")
    out["protocol pilot"] = done, f"plan complete; `pairplay report {command_word(folder)}` writes the report"
    export = root / f"ex{CONTROL}p.zip"
    done = pairplay_cli("participant", "export", folder, "p01", "-o", export)
    out["participant export"] = done, escaped(f"p01: {export}")
    done = pairplay_cli("protocol", "repair", folder)
    out["protocol repair"] = done, escaped(f"{folder / 'journal.jsonl'}: nothing to repair: every line is whole")
    grid, sweep = root / "grid.toml", root / f"sw{CONTROL}eep"
    grid.write_text(GRID_TEXT)
    done = pairplay_cli("sweep", grid, "--out", sweep)
    out["sweep"] = done, f"; {escaped(sweep / 'sweep.md')}"
    done = pairplay_cli("sweep", grid, "--out", sweep)
    out["sweep again"] = done, f"; {escaped(sweep / 'sweep.md')} is as it was"
    return out


@pytest.mark.parametrize("case", ["protocol init", "protocol status", "protocol pilot", "participant export",
                                  "protocol repair", "sweep", "sweep again"])
def test_every_result_line_naming_an_odd_path_is_one_line_and_a_suggested_command_types_as_the_path(said, case):
    done, expected = said[case]
    assert done.returncode == 0, done.stderr
    for stream in (done.stdout, done.stderr):  # no control character printed raw, on either stream
        assert "\t" not in stream and "\x1b" not in stream, stream
    assert any(expected in line for line in done.stdout.splitlines()), (expected, done.stdout)


def test_a_suggested_command_word_is_the_path_when_typed_into_bash():
    import os
    import subprocess

    from pairplay.errors import command_word

    for path in ("plain/path.mcap", "we ird/st'udy $HOME", f"st{CONTROL}udy", os.fsdecode(b"caf\xe9"), "a\u2028\x85b"):
        typed = subprocess.run(["bash", "-c", f"printf %s {command_word(path)}"], capture_output=True, check=True)
        assert typed.stdout == os.fsencode(path), (path, command_word(path))
        assert "\n" not in command_word(path)
