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
