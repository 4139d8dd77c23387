"""Every usage mistake names its verb (and action): `pairplay session: unknown option --bogus`.

Before: argparse reported arguments no parser took from the top parser, as `pairplay: unrecognized
arguments: --bogus`, whatever the verb; then (a new user's trial) in argparse's words with no hint of the
option meant (`--forse`), and a word that is not a verb but another verb's option (`pairplay verify`) with none."""

from __future__ import annotations

import pytest

from pairplay.cli.main import VERBS, main

# the least each verb (and action) parses without complaint, before --bogus
MINIMAL = {
    "study": [], "sweep": ["g.toml"], "bench": [], "profile": ["p.json"], "combine": ["p.json"], "view": [],
    "run": ["learner"], "session": ["--participant", "sim:ashley"], "lab": ["--participant", "human:p1"],
    "rebuild": ["r.mcap"], "replay": ["r.mcap"], "recover": ["r.mcap"], "counterfactual": ["r.mcap"],
    "protocol": ["check", "s.toml"], "participant": ["delete", "folder", "p1"], "report": ["folder"], "robot": [], "router": [],
}


def test_every_verb_has_its_case():
    assert set(MINIMAL) == set(VERBS)


@pytest.mark.parametrize("verb", list(VERBS))
def test_an_unknown_option_is_refused_in_one_line_naming_the_verb(verb, capsys):
    with pytest.raises(SystemExit) as end:
        main([verb, *MINIMAL[verb], "--bogus", "1"])
    assert end.value.code == 2
    out, err = capsys.readouterr()
    prog = " ".join(["pairplay", verb] + MINIMAL[verb][:1] * (verb in ("protocol", "participant")))
    assert out == "" and err.strip().splitlines() == [
        f"{prog}: unknown option --bogus (see {prog} --help)"], err


def test_a_missing_argument_and_a_stray_one_at_the_top_still_say_who(capsys):
    with pytest.raises(SystemExit):
        main(["session"])
    assert capsys.readouterr().err.startswith("pairplay session: the following arguments are required: --participant")
    with pytest.raises(SystemExit):
        main(["--bogus"])
    assert capsys.readouterr().err.startswith("pairplay: unknown option --bogus")


@pytest.mark.parametrize("argv", [["-v", "session", "--participant", "sim:blind"], ["-q", "--verbose", "study"],
                                  ["--out", "x", "study"], ["--seed", "3", "-v", "session", "--participant", "sim:b"]])
def test_an_option_before_the_verb_is_one_line_saying_it_goes_after_it(argv, capsys):
    """Before: `pairplay -v session --participant sim:blind` said "pairplay session: unrecognized
    arguments: -v --participant sim:blind": the verb's own options were never added to its parser;
    an option with a value (`pairplay --out x study`) said "invalid choice: 'x'"."""
    from pairplay.cli.main import VERBS
    assert main(argv) == 2
    err = capsys.readouterr().err
    verb = next(a for a in argv if a in VERBS)
    assert err.count("\n") == 1 and err.startswith("pairplay: ") and f"after the verb: pairplay {verb} " in err, err
    assert "unrecognized" not in err and "--participant" not in err


def test_the_system_refusing_an_actions_output_names_the_action(tmp_path, capsys):
    """Before: an OSError of `participant export` said "pairplay participant: ...", without its action."""
    folder = tmp_path / "study"
    assert main(["protocol", "init", str(folder), "--study", "thesis-ch7", "-q"]) == 0
    assert main(["protocol", "register", str(folder), "-q"]) == 0
    (tmp_path / "afile").write_text("a file")
    capsys.readouterr()
    assert main(["participant", "export", str(folder), "p01", "-o", str(tmp_path / "afile" / "p01.zip")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pairplay participant export: "), err


def _multi_level() -> list[str]:
    """The verbs that take a word naming what to do (an action, `run`'s service): read from their parsers."""
    from pairplay.cli.main import build_parser
    found = []
    for verb in VERBS:
        _, p = build_parser([verb])
        if any(not a.option_strings and a.choices and a.required for a in p._actions):
            found.append(verb)
    return found


def test_the_multi_level_verbs_are_found():
    assert {"protocol", "participant", "run"} <= set(_multi_level())


def test_no_verb_is_a_mistake_in_one_line_and_help_is_asked_for_on_stdout(capsys):
    """A new user's trial, 2026-12-01: bare `pairplay` printed the whole help on stdout and exited 2."""
    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines() == [
        f"pairplay: no verb given: one of {', '.join(VERBS)} (see pairplay --help)"], (out, err)
    with pytest.raises(SystemExit) as end:
        main(["--help"])
    out, err = capsys.readouterr()
    assert end.value.code == 0 and err == "" and "usage: pairplay" in out and "rebuild" in out


@pytest.mark.parametrize("verb", _multi_level())
def test_a_verb_without_its_action_is_one_line_naming_the_choices_and_its_help(verb, capsys):
    with pytest.raises(SystemExit) as end:
        main([verb])
    out, err = capsys.readouterr()
    assert end.value.code == 2 and out == "", (out, err)
    [line] = err.splitlines()
    assert line.startswith(f"pairplay {verb}: no ") and " given: one of " in line and \
        line.endswith(f"(see pairplay {verb} --help)"), line
    with pytest.raises(SystemExit) as end:
        main([verb, "--help"])
    out, err = capsys.readouterr()
    assert end.value.code == 0 and err == "" and f"usage: pairplay {verb}" in out


def test_running_out_of_memory_is_one_line_exit_2_not_a_traceback(tmp_path, monkeypatch, capsys):
    """Before (a trial under `ulimit -v 2000000`): `view` ended in a MemoryError traceback while rerun's
    modules loaded. Out of memory is the user's setup, like a full disk: one line, exit 2, nothing left."""
    from pathlib import Path

    from pairplay.replay import rebuild
    sample = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"

    def exhausted(*_a, **_k):
        raise MemoryError
    monkeypatch.setattr(rebuild, "rebuild_recording", exhausted)
    assert main(["rebuild", str(sample), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pairplay rebuild: out of memory"), err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_recording_given_without_its_option_is_told_which_option_takes_it(capsys):
    """Before (a new user's trial): `pairplay view rec.mcap` said only "unrecognized arguments"."""
    from pathlib import Path
    sample = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
    with pytest.raises(SystemExit) as end:
        main(["view", str(sample)])
    assert end.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"a recording is given with --recording {sample}" in err, err


def test_a_value_that_starts_with_a_dash_is_said_how_to_give(capsys, tmp_path):
    """`protocol register --name -2+3`: argparse takes -2+3 for an option and said only "expected one
    argument"; the line says to give it as --name=-2+3 (which registers it: tests/test_protocol.py)."""
    from pairplay.cli.main import main
    with pytest.raises(SystemExit) as exc:
        main(["protocol", "register", str(tmp_path / "study"), "--name", "-2+3"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert "argument --name: expected one argument" in err and "--name=VALUE when the value starts with '-'" in err


def test_a_game_waits_for_a_comma_list_of_services_and_refuses_a_name_that_is_none(capsys):
    """Before (a new user's trial): `run game --wait-for learner,participant,recorder` was one service of
    that name; the game waited 30 s and said none was on the bus, though all three were; `--wait-for foo`
    waited 30 s too."""
    from pairplay.cli.main import build_parser
    parser, _ = build_parser(["run"])
    args = parser.parse_args(["run", "game", "--participant", "sim:ashley", "--wait-for", "learner,participant",
                              "--wait-for", "recorder"])
    assert args.wait_for == ["learner", "participant", "recorder"]
    with pytest.raises(SystemExit) as end:
        main(["run", "game", "--participant", "sim:ashley", "--wait-for", "learner,foo"])
    assert end.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'foo': not a service to wait for" in err, err


def _misspelt(option: str) -> str:
    """`option` with its last two letters swapped (`--force` -> `--forec`): a typo no option begins with."""
    return option[:-2] + option[-1] + option[-2]


def _every_parser(verb: str):
    """(argv that reaches it, its prog, parser) for `verb` and every action of it."""
    import argparse

    from pairplay.cli.main import build_parser
    _, p = build_parser([verb])
    yield [verb, *MINIMAL[verb]], " ".join(["pairplay", verb] + MINIMAL[verb][:1] * (verb in ("protocol", "participant"))), p
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, nested in a.choices.items():
                yield [verb, name], f"pairplay {verb} {name}", nested


@pytest.mark.parametrize("verb", list(VERBS))
def test_a_misspelt_option_of_every_verb_and_action_names_the_one_it_resembles(verb, capsys):
    """A new user's trial: `--forse` was "unrecognized arguments: --forse". Every option of every verb (and
    action) with a letter pair swapped is refused in one line naming the option it resembles, and before a
    required argument that is missing (the actions are given nothing else: `protocol init --studdy`)."""
    from pairplay.nearest import nearest
    checked = 0
    for argv, prog, p in _every_parser(verb):
        known = sorted(o for o in p._option_string_actions if o.startswith("--"))
        for option in (o for o in known if len(o) >= 7):
            typo = _misspelt(option)
            if any(o.startswith(typo) for o in known) or nearest(typo, known) != option:
                continue  # a swap that makes (the beginning of) another option, or resembles another one more
            with pytest.raises(SystemExit) as end:
                main([*argv, typo])
            assert end.value.code == 2
            out, err = capsys.readouterr()
            assert out == "" and err.splitlines() == [
                f"{prog}: unknown option {typo} (did you mean {option}?) (see {prog} --help)"], (argv, err)
            checked += 1
    assert checked, verb


@pytest.mark.parametrize("word, meant", [("verify", "'pairplay replay --verify'"), ("init", "'pairplay protocol init'"),
                                         ("merge", "'pairplay combine'"), ("record", "'pairplay session'"),
                                         ("sesion", "'session'"), ("protocl", "'protocol'")])
def test_a_word_that_is_not_a_verb_names_the_command_meant(word, meant, capsys):
    """A new user's trial: `pairplay verify x.mcap` listed the verbs, no hint (it is `replay --verify`); a
    misspelt verb names the verb it resembles; `record` is `session` (what records), not `recover`."""
    with pytest.raises(SystemExit) as end:
        main([word, "x.mcap"])
    assert end.value.code == 2
    [line] = capsys.readouterr().err.splitlines()
    assert line.startswith(f"pairplay: argument VERB: invalid choice: '{word}' (did you mean {meant}?)"), line


def test_every_word_taken_for_a_verb_stands_for_a_command_that_parses():
    from hints import bad_command

    from pairplay.cli.main import VERB_ALIASES
    assert not set(VERB_ALIASES) & set(VERBS)
    for word, command in VERB_ALIASES.items():
        assert command.startswith("pairplay ") and bad_command(command) == "", (word, command)


@pytest.mark.parametrize("argv, given, meant", [(["study"], "--for", "--force"), (["study"], "--fo", "--force"),
                                                (["report", "x"], "--ou", "--out"),
                                                (["protocol", "init", "st"], "--stu", "--study")])
def test_the_beginning_of_an_option_is_not_taken_for_it(argv, given, meant, capsys):
    """A new user's trial: `pairplay study --fo` replaced a finished study's report (argparse takes any
    unambiguous beginning of an option for it: --fo was --force). An option is given whole."""
    with pytest.raises(SystemExit) as end:
        main([*argv, given])
    assert end.value.code == 2
    err = capsys.readouterr().err
    assert f"unknown option {given} (did you mean {meant}?)" in err and len(err.splitlines()) == 1, err
