"""Every option or command a line tells a user to type exists where they read it (tests/hints.py).

A new user's trial, 2026-12-01: `pairplay run recorder` of a session whose recording was gone but
whose journal was left said "choose another --session, or --force to replace its recordings", and
`run` has no --force (the hint was `pairplay session`'s). The same kind anywhere: a hint of code
below the command line (pairplay/outputs.py's "--force replaces it") is shown only by a verb that
has the option (errors.UserError `fix`); every option a verb's module names is one of that verb's;
every `pairplay ...` command the code and the docs name parses. The mistakes table
(tests/test_cli_mistakes.py) checks the same of each of its lines."""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

import pytest

from pairplay.cli.main import VERBS, build_parser, main
from pairplay.errors import OutputError

from hints import COMMAND, OPTION, bad_command, bad_options, verb_options

ROOT = Path(__file__).resolve().parents[1]
CODE = ("cli", "services", "replay", "report", "pairplay", "core", "schemas", "bench", "gym")


def strings(path: Path) -> list[tuple[int, str]]:
    """The string constants of a module a user may read (not docstrings, not argparse's own help)."""
    tree = ast.parse(path.read_text())
    skip = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and \
                isinstance(body[0].value, ast.Constant):
            skip.add(id(body[0].value))
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") in ("add_argument", "add_parser"):
            skip.update(id(sub) for sub in ast.walk(node))
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in skip]


def test_run_recorder_beside_a_journal_whose_recording_is_gone_names_no_option_run_lacks(tmp_path, pairplay_cli):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "s.mcap.journal").write_bytes(b"")  # its recording removed, its journal left
    r = pairplay_cli("run", "recorder", "--session", "s", "--out", "d", cwd=tmp_path)
    [line] = r.stderr.strip().splitlines()
    assert r.returncode == 2 and line.startswith("pairplay run: session s has a recorder's journal already"), r.stderr
    assert "--force" not in line and bad_options(["run", "recorder"], line) == [], line
    assert line.endswith("(d/s.mcap.journal)"), line


def test_a_fix_naming_an_option_is_shown_only_by_a_verb_that_has_it(tmp_path, capsys):
    err = OutputError("exists", tmp_path / "m.json", fix="--force replaces it", option="--force")
    assert err.line({"--force"}) == f"exists; --force replaces it ({tmp_path / 'm.json'})"
    assert err.line({"--out"}) == str(err) == f"exists ({tmp_path / 'm.json'})"  # a log, a web page, a bus event
    from pairplay.replay.mcapscan import scan
    sample = ROOT / "recordings" / "samples" / "sim-ashley.mcap"
    last = scan(sample).chunks[-1]  # cut: recover has a file to write (a complete one writes none)
    (tmp_path / "r.mcap").write_bytes(sample.read_bytes()[:last.offset + last.length])
    (tmp_path / "mine.mcap").write_bytes(b"the user's")
    assert main(["recover", str(tmp_path / "r.mcap"), "-o", str(tmp_path / "mine.mcap")]) == 2
    line = capsys.readouterr().err.strip()
    assert "exists; --force replaces it" in line and bad_options(["recover"], line) == [], line


@pytest.mark.parametrize("verb", list(VERBS))
def test_every_option_a_verbs_module_names_is_one_of_that_verb(verb):
    module = ROOT / "cli" / f"{VERBS[verb][0].rsplit('.', 1)[1]}.py"
    known = verb_options([verb])
    _, chosen = build_parser([verb])
    for action in chosen._actions:  # and every action's (a message of `protocol init` names its options)
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                known |= {o for a in sub._actions for o in a.option_strings}
    named = {(line, o) for line, text in strings(module) for o in OPTION.findall(COMMAND.sub("", text))}
    assert sorted((line, o) for line, o in named if o not in known) == [], f"{module.name} names options {verb} lacks"


def _functions(path: Path) -> dict[str, ast.FunctionDef]:
    return {n.name: n for n in ast.parse(path.read_text()).body if isinstance(n, ast.FunctionDef)}


@pytest.mark.parametrize("verb", list(VERBS))
def test_every_option_a_function_another_verb_borrows_names_is_one_of_that_verb_too(verb):
    """`lab` prints `session`'s interrupted line (cli/session.py print_interrupted): an option that line
    names must be one of lab's as well (it said "--force reuses it"; lab has no --force)."""
    module = ROOT / "cli" / f"{VERBS[verb][0].rsplit('.', 1)[1]}.py"
    known = verb_options([verb])
    _, chosen = build_parser([verb])
    for action in chosen._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                known |= {o for a in sub._actions for o in a.option_strings}
    wrong = []
    for node in ast.walk(ast.parse(module.read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pairplay.cli."):
            lender = ROOT / "cli" / f"{node.module.rsplit('.', 1)[1]}.py"
            if lender == module or not lender.exists():
                continue
            functions = _functions(lender)
            for alias in node.names:
                fn = functions.get(alias.name)
                if fn is None or alias.name.startswith("add_"):  # add_*: argparse declarations, its own options
                    continue
                body = ast.Module(body=fn.body[1:] if ast.get_docstring(fn) else fn.body, type_ignores=[])
                for n in ast.walk(body):
                    if isinstance(n, ast.Constant) and isinstance(n.value, str):
                        wrong += [f"{lender.name}:{n.lineno} {alias.name}: {o}"
                                  for o in OPTION.findall(COMMAND.sub("", n.value)) if o not in known]
    assert wrong == [], f"{verb} shows lines naming options it lacks"


def test_every_pairplay_command_the_code_names_parses():
    wrong = []
    for folder in CODE:
        for path in sorted((ROOT / folder).rglob("*.py")):
            for line, text in strings(path):
                wrong += [f"{path.relative_to(ROOT)}:{line}: `{c}`: {why}"
                          for c in COMMAND.findall(text) if (why := bad_command(c))]
    assert wrong == []


SHOWN_AS_MISTAKES = {"pairplay --out x study", "pairplay verify x.mcap", "pairplay study --fo"}  # the README shows what the command line says of them


def test_every_pairplay_command_the_docs_name_parses():
    wrong = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for c in COMMAND.findall(path.read_text()):
            if "\n" not in c and c not in SHOWN_AS_MISTAKES and (why := bad_command(c)):
                wrong.append(f"{path.name}: `{c}`: {why}")
    assert wrong == []


def test_the_checker_finds_an_option_the_verb_lacks():
    line = "session s has a recording already; choose another --session, or --force to replace its recordings"
    assert bad_options(["run", "recorder"], line) == ["--force"]
    assert bad_options(["session"], line) == []
    assert bad_command("pairplay recover x.mcap --discard-journal") == ""
    assert bad_command("pairplay run recorder --force") == "run has no --force"
    assert bad_command("pairplay nosuchverb") == "no verb 'nosuchverb'"
