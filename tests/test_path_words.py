"""A path in an error line is the path: escaped in what the line says, never folded into a space.

Trial32 F: a path in the `what` part of an error line lost its tabs and newlines to spaces (UserError.line
folded `what`'s whitespace): `protocol status $'/tmp/no\\tsu\\nch'` said "/tmp/no su ch: not a study folder",
another path; pilot, register, report alike, and recover's "its journal is here (...)".
"""

from __future__ import annotations

import pytest

from pairplay.errors import UserError, command_word, escaped

ODD = "n\to\nw"  # a tab and a newline: what a folded line showed as spaces


def test_a_path_in_what_keeps_its_tab_newline_and_spaces():
    assert UserError(f"/tmp/{ODD}  x: not a study folder").line() == "/tmp/n\\to\\nw  x: not a study folder"
    assert "\n" not in UserError(f"{ODD}\x1b[2J").line()


@pytest.mark.parametrize("verb", [("protocol", "status"), ("protocol", "register"),
                                  ("protocol", "pilot", "--personas", "blind"), ("report",)])
def test_a_missing_folder_is_named_escaped_not_folded(pairplay_cli, tmp_path, verb):
    folder = tmp_path / f"no{ODD}such"
    done = pairplay_cli(*verb[:2], folder, *verb[2:])
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"pairplay {' '.join(verb[:2])}: {escaped(folder)}: not a study folder"), \
        done.stderr


def test_recovers_hint_names_the_journal_escaped_and_the_commands_as_words(pairplay_cli, tmp_path):
    name = f"n{ODD}q'$x.mcap"
    (tmp_path / f"{name}.journal").write_bytes(b"")  # what a recorder left, its recording gone
    done = pairplay_cli("recover", name, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert f"its journal is here ({escaped(name)}.journal: what its recorder received)" in done.stderr
    assert f"`touch {command_word(name)}`" in done.stderr and f"`pairplay recover {command_word(name)}`" in done.stderr
