"""A path in a line is the path: escaped in what the line says, a shell word in a command it suggests.

Trial32 F: `protocol status 'a b;touch X.toml'` (a study's .toml given for its folder) suggested
"`pairplay protocol init FOLDER --study a b;touch X.toml`": typed back into bash, it ran `touch X.toml`
(replay/studydata.py formatted the path bare, not through pairplay/errors.py `command_word`). And a path in
the `what` part of an error line lost its tabs and newlines to spaces (UserError.line folded `what`'s
whitespace): `protocol status $'/tmp/no\\tsu\\nch'` said "/tmp/no su ch: not a study folder", another path;
recover's "its journal is here (...)" alike. Trial32 D: a sweep whose cluster had no worker said "0 of 4 cells
finished, kept in X/cells" of a folder it had removed, its path and address not escaped.

The whole kind: `test_every_suggested_command_gives_its_fields_as_shell_words` reads every f-string of the
code for a backticked command (`pairplay ...`, `touch ...`, `dask worker ...`) and refuses a field not made a
shell word by `command_word`.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from pairplay.errors import UserError, command_word, escaped

ROOT = Path(__file__).resolve().parents[1]
# the words a backticked command of a line begins with: pairplay's verbs, and the shell's a hint may name
COMMAND = re.compile(r"(pairplay|touch|mv|cp|rm|mkdir|cd|ls|cat|chmod|chown|kill|dask|python3?|pip|git)\b")
# fields in a backticked command that are our own words, never a user's: a verb's name (`pairplay {verb}`)
OWN_WORDS = {"verb", "self.verb", "c.verb"}
ODD = "n\to\nw"  # a tab and a newline: what a folded line showed as spaces


def code_files() -> list[Path]:
    """The project's Python files: every package folder, not the tests (their f-strings build the lines they
    expect) nor a virtual environment."""
    return [p for p in sorted(ROOT.rglob("*.py"))
            if not {".venv", "tests", "build"} & set(p.relative_to(ROOT).parts) and not p.name.startswith(".")]


def suggested_commands(path: Path):
    """(line, the backticked command, the source of each field in it) of each f-string of `path` (adjacent
    literals, over several lines, are one f-string to the parser) whose backticked part begins with COMMAND.
    The command is given with each field's source in braces, as it is written."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if not isinstance(node, ast.JoinedStr):
            continue
        fields, text = [], ""
        for part in node.values:
            if isinstance(part, ast.Constant):
                text += part.value
            else:
                text += f"\x00{len(fields)}\x00"
                fields.append(ast.unparse(part.value))
        for m in re.finditer(r"`([^`]*)`", text):
            if COMMAND.match(m.group(1)):
                shown = re.sub(r"\x00(\d+)\x00", lambda f: "{" + fields[int(f.group(1))] + "}", m.group(1))
                yield node.lineno, shown, [fields[int(i)] for i in re.findall(r"\x00(\d+)\x00", m.group(1))]


def test_every_suggested_command_gives_its_fields_as_shell_words():
    bare = []
    for path in code_files():
        for line, command, fields in suggested_commands(path):
            bare += [f"{path.relative_to(ROOT)}:{line}: `{command}`: {{{field}}}" for field in fields
                     if field not in OWN_WORDS and not re.fullmatch(r"command_word\(.*\)", field)]
    assert not bare, "a field of a suggested command not through errors.command_word:\n" + "\n".join(bare)


def test_shell_quoting_is_command_word_alone():
    """shlex.quote keeps a newline raw (the command split over two lines): command_word is the one way."""
    used = [str(p.relative_to(ROOT)) for p in code_files() if "shlex.quote(" in p.read_text(encoding="utf-8")]
    assert used == ["pairplay/errors.py"], used


def test_the_scan_sees_a_bare_field_over_two_literals(tmp_path):
    """The scan's own check: a command split over adjacent literals, as the code wraps them, is one f-string."""
    sample = tmp_path / "sample.py"
    sample.write_text('x = (f"run `pairplay protocol "\n     f"repair {folder}` now")\n'
                      'y = f"`pairplay report {command_word(folder)}`"\n')
    assert [(c, f) for _, c, f in suggested_commands(sample)] == [
        ("pairplay protocol repair {folder}", ["folder"]), ("pairplay report {command_word(folder)}", ["command_word(folder)"])]


def test_a_path_in_what_keeps_its_tab_newline_and_spaces():
    assert UserError(f"/tmp/{ODD}  x: not a study folder").line() == "/tmp/n\\to\\nw  x: not a study folder"
    assert "\n" not in UserError(f"{ODD}\x1b[2J").line()


def typed(word: str) -> bytes:
    """What bash makes of `word` typed as one argument."""
    return subprocess.run(["bash", "-c", f"printf %s {word}"], capture_output=True, check=True).stdout


@pytest.mark.parametrize("name", ["a b;touch X.toml", f"my st{ODD}udy.toml"])
@pytest.mark.parametrize("verb", [("protocol", "status"), ("report",)])
def test_a_toml_given_for_the_folder_suggests_init_with_the_path_as_one_word(pairplay_cli, tmp_path, name, verb):
    study = tmp_path / name
    shutil.copy(ROOT / "tests" / "data" / "pilot-study.toml", study)
    done = pairplay_cli(*verb, study.name, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    m = re.search(r"`pairplay protocol init FOLDER --study (.*)` makes one of it", done.stderr)
    assert m and m.group(1) == command_word(name), done.stderr
    assert typed(m.group(1)) == os.fsencode(name)  # typed back: the file, and nothing run
    assert done.stderr.startswith(f"pairplay {' '.join(verb)}: {escaped(name)}: a file, not a study folder")
    assert not (tmp_path / "X.toml").exists()


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
