"""Every refusal of an output names the file or folder it is about, whatever the output is called.

Before: a refusal's path was left out when its name happened to occur inside the message
(`pairplay study --out here` said "exists and is not empty; --force replaces the files written
there": `here` is in "there"); `sweep` wrote into a folder of other files and refused an --out
that is a file only after the whole sweep (as "File exists"). The outputs here are called `e`
and `f`, letters every message holds."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
GRID = "[study]\ngames = 1\nrounds = 5\n[grid]\ntrained_updates = [50, 40]\n"

# verb's arguments -> the path the one line must name (relative to the case's folder)
CASES = {
    "study": (["study", "--quiet", "--out", "e"], "e"),
    "counterfactual": (["counterfactual", "rec.mcap", "--out", "e"], "e"),
    "sweep into a folder of other files": (["sweep", "g.toml", "--quiet", "--out", "e"], "e"),
    "sweep into a file": (["sweep", "g.toml", "--quiet", "--out", "f"], "f"),
    "rebuild": (["rebuild", "rec.mcap", "--out", "e"], "e/rec.policy.json"),
    "combine": (["combine", "policies", "-o", "f"], "f"),
    "recover": (["recover", "cut.mcap", "-o", "f"], "f"),  # a cut file: a complete one writes nothing
    "view": (["view", "--recording", "rec.mcap", "--out", "f"], "f"),
    "session into a file": (["session", "--participant", "sim:ashley", "--out", "f"], "f"),
    "session over a recording": (["session", "--participant", "sim:ashley", "--session", "e", "--out", "e"],
                                 "e/e.mcap"),
    "report": (["report", "study", "--out", "e"], "e"),
}


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("paths")
    shutil.copy(SAMPLE, root / "rec.mcap")
    last = scan(SAMPLE).chunks[-1]
    (root / "cut.mcap").write_bytes(SAMPLE.read_bytes()[:last.offset + last.length])
    assert main(["study", "--quiet", "--train-only", "--personas", "blind,deaf", "--games", "2", "--rounds", "5",
                 "--out", str(root / "st")]) == 0
    shutil.move(root / "st" / "policies", root / "policies")
    shutil.rmtree(root / "st")
    (root / "e").mkdir()
    for name in ("x", "rec.policy.json", "e.mcap"):
        (root / "e" / name).write_bytes(b"the user's file")
    (root / "f").write_bytes(b"the user's file")
    (root / "g.toml").write_text(GRID)
    return root


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_a_refused_output_is_named_in_the_one_line(case, template, tmp_path, monkeypatch, capsys):
    args, named = CASES[case]
    root = tmp_path / "w"
    shutil.copytree(template, root)
    _, line = refused_in_one_line(args, root, monkeypatch, capsys)
    path = re.escape(named)
    assert re.search(rf"(?<![\w./-])(\S*/)?{path}(?![\w/-]|\.\w)", line), line


def refused_in_one_line(args: list[str], root, monkeypatch, capsys) -> tuple[str, str]:
    """Run `pairplay <args>` in `root`: exit 2, ONE line on stderr that starts with the verb, nothing written
    or renamed under `root`; (stdout, the line)."""
    monkeypatch.chdir(root)
    before = sorted(p.relative_to(root) for p in root.rglob("*"))
    assert main(args) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"pairplay {args[0]}: "), err
    assert "Traceback" not in err, err
    assert sorted(p.relative_to(root) for p in root.rglob("*")) == before  # nothing written, nothing renamed
    return out, lines[0]


# verb's arguments, given relative -> the path as given, which the one line must name (and nothing absolute)
AS_GIVEN = {
    "rebuild": (["rebuild", "rec.mcap", "--out", "f/x"], "(f)"),
    "rebuild over an output": (["rebuild", "rec.mcap", "--out", "e"], "exists; --force replaces it (e/rec.policy.json)"),
    "recover": (["recover", "cut.mcap", "-o", "f/x/r.mcap"], "(f)"),
    "study": (["study", "--quiet", "--out", "f/s"], "(f)"),
    "combine": (["combine", "policies", "-o", "f/m.json"], "(f)"),
    "view": (["view", "--recording", "rec.mcap", "--out", "f/v.rrd"], "(f)"),
    "counterfactual": (["counterfactual", "rec.mcap", "--out", "f/c"], "(f)"),
    "protocol status": (["protocol", "status", "nostudy"], ": nostudy: not a study folder"),
    "report": (["report", "nostudy"], ": nostudy: not a study folder"),
    "participant export": (["participant", "export", "nostudy", "P1"], ": nostudy: not a study folder"),
}


@pytest.mark.parametrize("case", AS_GIVEN, ids=list(AS_GIVEN))
def test_a_refusal_names_the_path_as_the_user_gave_it(case, template, tmp_path, monkeypatch, capsys):
    """A new user's trial: `rebuild --out afile/x` said "a file stands where a folder is needed
    (/tmp/.../afile)" and `protocol status nosuch` "/tmp/.../nosuch: not a study folder": paths the user
    never typed (outputs._existing_ancestor and StudyData resolved them). Now the path as given."""
    args, said = AS_GIVEN[case]
    root = tmp_path / "w"
    shutil.copytree(template, root)
    monkeypatch.chdir(root)
    assert main(args) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert said in line and str(root) not in line and str(tmp_path) not in line, line


# verb's arguments, with --force: a folder stands where the verb writes a file (or a file where it needs a folder)
# in `d` -> the path the one line must name. Before: the verb did its work and failed moving it in (`study`: "Is a
# directory (.d.<pid>.tmp/report.md -> d/report.md)"), or `session --force` played the whole session, renamed
# the folder <id>.mcap.replaced and exited 2; now each is refused before any work, nothing renamed or written.
IN_THE_WAY = {
    "study: a folder for its report.md": (["study", "--quiet", "--out", "d", "--force"], "d/report.md"),
    "study: a file for its policies/": (["study", "--quiet", "--out", "p", "--force"], "p/policies"),
    "counterfactual": (["counterfactual", "rec.mcap", "--fit-only", "--out", "d", "--force"], "d/counterfactual.md"),
    "rebuild": (["rebuild", "rec.mcap", "--out", "d", "--force"], "d/rec.policy.json"),
    "sweep: a folder for its sweep.md": (["sweep", "g.toml", "--quiet", "--out", "d", "--force"], "d/sweep.md"),
    "sweep: a file for its figures/": (["sweep", "g.toml", "--quiet", "--out", "p", "--force"], "p/figures"),
    "session --force": (["session", "--participant", "sim:ashley", "--rounds", "1", "--session", "m", "--out", "d",
                         "--force"], "d/m.mcap"),
    "session": (["session", "--participant", "sim:ashley", "--rounds", "1", "--session", "m", "--out", "d"],
                "d/m.mcap"),
    "session --force: a folder for a later part": (["session", "--participant", "sim:ashley", "--rounds", "1",
                                                     "--session", "n", "--out", "d", "--force"], "d/n.2.mcap"),
    "recover": (["recover", "cut.mcap", "-o", "d", "--force"], "d"),
    "combine": (["combine", "policies", "-o", "d", "--force"], "d"),
    "view": (["view", "--recording", "rec.mcap", "--out", "d", "--force"], "d"),
}


@pytest.mark.parametrize("case", IN_THE_WAY, ids=list(IN_THE_WAY))
def test_a_folder_where_a_file_goes_is_refused_before_any_work(case, template, tmp_path, monkeypatch, capsys):
    args, named = IN_THE_WAY[case]
    root = tmp_path / "w"
    shutil.copytree(template, root)
    for folder in ("d/report.md", "d/counterfactual.md", "d/rec.policy.json", "d/sweep.md", "d/m.mcap", "d/n.2.mcap"):
        (root / folder).mkdir(parents=True)
        (root / folder / "the user's").write_text("kept")
    (root / "p").mkdir()
    for name in ("policies", "figures"):
        (root / "p" / name).write_text("the user's file")
    out, line = refused_in_one_line(args, root, monkeypatch, capsys)
    assert line.endswith(f"({named})"), line
    assert not re.search("--force (to )?replace", line), line  # (`session` offered it; --force renamed it)
    assert out == "", out  # refused before any work: a session printed its bus line, then played


def test_a_sweep_cell_file_that_is_a_folder_is_refused_naming_the_cell_before_any_cell_runs(template, tmp_path,
                                                                                             monkeypatch, capsys):
    """A resumed sweep whose last cell's file had become a folder computed every other cell and then that one,
    and failed storing it: "is a folder; give a file name", its work lost. A folder is not the sweep's to
    remove, so it is not taken for a damaged cell (which is computed again): it is refused before any cell
    runs, one line naming the cell, its setting and seed."""
    from pairplay.report.sweep import read_grid

    root = tmp_path / "w"
    shutil.copytree(template, root)
    monkeypatch.chdir(root)
    cells = read_grid(Path("g.toml")).cells()
    (root / "s" / "cells" / f"{cells[-1].id}.json").mkdir(parents=True)
    shutil.copy(root / "g.toml", root / "s" / "grid.toml")  # a sweep of this grid, to resume
    assert main(["sweep", "g.toml", "--quiet", "--out", "s"]) == 2
    out, err = capsys.readouterr()
    [line] = err.strip().splitlines()
    assert f"cell {cells[-1].id}'s result" in line and f"seed {cells[-1].seed}" in line, line
    assert line.endswith(f"(s/cells/{cells[-1].id}.json)"), line
    assert sorted(p.name for p in (root / "s" / "cells").iterdir()) == [f"{cells[-1].id}.json"]  # no cell ran


# Every output argument of every verb, typed with a trailing slash (a new user's trials: `participant export -o out/`,
# `recover -o out/`, `view --out x/`, `combine -o cmb/` each wrote a FILE named after the folder: argparse's
# `type=Path` drops the slash). An output file's option given as a folder puts the file in it under the verb's
# default name, or, where the verb has none, is refused naming the option; a folder's option is a folder.
# (prog, option) -> the arguments typed and: ("into", the file written) or ("refused", the option the line names)
TRAILING_SLASH = {
    ("pairplay recover", "-o/--out/--output"): (["recover", "cut.mcap", "-o", "o/"], ("into", "o/cut.recovered.mcap")),
    ("pairplay view", "--out"): (["view", "--recording", "rec.mcap", "--out", "o/"], ("into", "o/rec.rrd")),
    ("pairplay participant export", "-o/--out"): (["participant", "export", "study", "p01", "-o", "o/."],
                                                  ("into", "o/p01.zip")),
    ("pairplay combine", "--out/-o"): (["combine", "policies", "-o", "o/"], ("refused", "--out/-o")),
    ("pairplay protocol init", "--key-file"): (["protocol", "init", "s", "--study", "thesis-ch7", "--key-file", "o/"],
                                               ("refused", "--key-file")),
    ("pairplay bench", "--readme"): (["bench", "--readme", "o/"], ("refused", "--readme")),
}
# the folder outputs: a trailing slash names the folder they are anyway
FOLDERS = {("pairplay study", "--out"), ("pairplay session", "--out"), ("pairplay lab", "--out"),
           ("pairplay run", "--out"), ("pairplay rebuild", "--out"), ("pairplay counterfactual", "--out"),
           ("pairplay sweep", "--out"), ("pairplay report", "--out"), ("pairplay protocol init", "folder")}
# an argument called so names a place the verb writes (an input is never called so)
OUTPUT_NAMES = {"-o", "--out", "--output", "--key-file", "--readme"}


def _output_arguments() -> dict[tuple[str, str], object]:
    """(prog, option) -> argparse type, for every argument of every verb (and action) that is declared with
    an output type of cli/args.py or is called like an output (OUTPUT_NAMES, `--*-out`)."""
    import argparse

    from pairplay.cli import args as options
    from pairplay.cli.main import VERBS, build_parser

    def parsers(parser):
        yield parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for nested in action.choices.values():
                    yield from parsers(nested)

    found = {}
    for verb in VERBS:
        for p in parsers(build_parser([verb])[1]):
            for a in p._actions:
                typed = a.type is options.output_folder or getattr(a.type, "__name__", "") == "output file"
                named = any(o in OUTPUT_NAMES or o.endswith("-out") for o in a.option_strings)
                if typed or named:
                    found[(p.prog, "/".join(a.option_strings) or a.dest)] = a.type
    return found


def test_every_output_argument_is_declared_a_file_or_a_folder_and_tested_with_a_trailing_slash():
    from pairplay.cli import args as options

    found = _output_arguments()
    assert set(found) == set(TRAILING_SLASH) | FOLDERS, "an output argument without its row here (or a row of none)"
    for key, kind in found.items():
        if key in FOLDERS:
            assert kind is options.output_folder, key
        else:  # a file: into a folder where the verb has a default name, else refused
            assert getattr(kind, "__name__", "") == "output file", key
            assert kind.into == (TRAILING_SLASH[key][1][0] == "into"), key


@pytest.fixture(scope="module")
def with_study(template, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("paths-study")
    shutil.copytree(template, root, dirs_exist_ok=True)
    assert main(["protocol", "init", str(root / "study"), "--study", "thesis-ch7", "--quiet"]) == 0
    assert main(["protocol", "register", str(root / "study"), "--quiet"]) == 0  # p01
    return root


@pytest.mark.parametrize("key", TRAILING_SLASH, ids=[" ".join(k) for k in TRAILING_SLASH])
def test_an_output_file_given_with_a_trailing_slash_goes_into_that_folder_or_is_refused(key, with_study, tmp_path,
                                                                                          monkeypatch, capsys):
    args, (then, what) = TRAILING_SLASH[key]
    root = tmp_path / "w"
    shutil.copytree(with_study, root)
    monkeypatch.chdir(root)
    before = sorted(p.relative_to(root) for p in root.rglob("*"))
    try:
        code = main(args)
    except SystemExit as refused:  # argparse's refusal, before the verb runs
        code = refused.code
    out, err = capsys.readouterr()
    assert not (root / "o").is_file(), "a file named after the folder"
    if then == "into":
        assert code == 0, err
        assert (root / what).is_file(), sorted(p.name for p in (root / "o").iterdir())
        assert what in out, out  # the line says where it went
    else:
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and lines[0].startswith(f"{key[0]}: "), err
        assert f"argument {what}: 'o/' names a folder" in lines[0], lines[0]
        assert sorted(p.relative_to(root) for p in root.rglob("*")) == before  # nothing written


@pytest.mark.parametrize("key", sorted(FOLDERS), ids=[" ".join(k) for k in sorted(FOLDERS)])
def test_an_output_folder_given_with_a_trailing_slash_is_that_folder(key):
    from pairplay.cli.main import build_parser

    verb = key[0].split()[1:]
    parser, _ = build_parser(verb)
    option = key[1].split("/")[-1]
    given = {"pairplay session": ["--participant", "sim:blind"], "pairplay lab": ["--participant", "human:p1"],
             "pairplay run": ["recorder"], "pairplay rebuild": ["r.mcap"], "pairplay counterfactual": ["r.mcap"],
             "pairplay sweep": ["g.toml"], "pairplay report": ["st"], "pairplay protocol init": ["--study", "x"]}
    rest = given.get(key[0], [])
    args = parser.parse_args([*verb, *rest, "x/"] if option == "folder" else [*verb, *rest, option, "x/"])
    assert Path(getattr(args, "folder" if option == "folder" else "out")) == Path("x")

# a folder (or a file) where a study folder's journal and files, or `session --force`'s set-aside copy, are
# written: the one line names it and says which it stands for. Before: `protocol init` with journal.jsonl a
# folder said "already a study folder", `protocol status` "not a study folder (no journal.jsonl ...)", init with
# recordings a file the OS's "File exists", a folder <id>.mcap.replaced "where the session's recording (or its
# journal) is written" (trial; the lead's hint list)
IN_THE_WAY_NAMED = {
    "protocol init: a folder for journal.jsonl": (["protocol", "init", "s", "--study", "study.toml"], "s/journal.jsonl",
                                                  "is a folder where a file is written"),
    "protocol init: a folder for study.toml": (["protocol", "init", "t", "--study", "study.toml"], "t/study.toml",
                                               "is a folder where a file is written"),
    "protocol init: a file for recordings/": (["protocol", "init", "u", "--study", "study.toml"], "u/recordings",
                                              "is a file where a folder is needed"),
    "protocol status: a folder for journal.jsonl": (["protocol", "status", "s"], "s/journal.jsonl",
                                                    "is a folder where the study's journal is written"),
    "session: a folder for the set-aside copy": (["session", "--participant", "sim:ashley", "--rounds", "1",
                                                  "--session", "m", "--out", "d"], "d/m.mcap.replaced",
                                                 "is a folder where `session --force` keeps the earlier recording"),
}


@pytest.mark.parametrize("case", IN_THE_WAY_NAMED, ids=list(IN_THE_WAY_NAMED))
def test_a_folder_where_a_study_file_or_a_set_aside_copy_goes_is_named_for_what_it_stands_for(
        case, template, tmp_path, monkeypatch, capsys):
    from pairplay.schemas.study import example_text

    args, named, said = IN_THE_WAY_NAMED[case]
    root = tmp_path / "w"
    shutil.copytree(template, root)
    (root / "study.toml").write_text(example_text())
    for folder in ("s/journal.jsonl", "t/study.toml", "d/m.mcap.replaced"):
        (root / folder).mkdir(parents=True)
    (root / "u").mkdir()
    (root / "u" / "recordings").write_text("the user's file")
    monkeypatch.chdir(root)
    before = sorted(p.relative_to(root) for p in root.rglob("*"))
    assert main(args) == 2
    out, err = capsys.readouterr()
    [line] = err.strip().splitlines()
    verb = " ".join(args[:2] if args[0] == "protocol" else args[:1])
    assert line.startswith(f"pairplay {verb}: ") and out == "", err
    assert sorted(p.relative_to(root) for p in root.rglob("*")) == before  # nothing written, nothing renamed
    assert said in line and named in line and "already a study folder" not in line, line
    assert "not a study folder" not in line and "File exists" not in line and "(or its journal)" not in line, line


def test_init_with_a_bundled_study_keeps_a_file_of_its_copy_s_name_beside_the_folder(tmp_path):
    """`protocol init F --study thesis-ch7` wrote the bundled study to `.thesis-ch7.toml` beside F and removed
    it: a file of that name there was replaced and deleted without a word. Its copy takes a name of its own now."""
    (tmp_path / ".thesis-ch7.toml").write_text("mine\n")
    assert main(["protocol", "init", str(tmp_path / "study"), "--study", "thesis-ch7", "--quiet"]) == 0
    assert (tmp_path / ".thesis-ch7.toml").read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".thesis-ch7.toml", "study"]
    assert "thesis-ch7" in (tmp_path / "study" / "study.toml").read_text()
