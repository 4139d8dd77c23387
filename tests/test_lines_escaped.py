"""A path or a value with a newline (or another control character) is shown escaped: one line stays one line.

Trial28 F10: `rebuild`, `view` and `recover` of `x<newline>y.mcap` printed their result lines split at the
newline, and `session --participant $'sim:ash\\nley'` ended its refusal "(--participant sim:ash" NEWLINE
"ley)": two lines on stderr. The shared helper is pairplay/errors.py `escaped`, used by every error line
(UserError.line, cli/main.py) and by the result lines of those verbs.
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
