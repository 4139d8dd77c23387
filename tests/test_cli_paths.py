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
GRID = "[study]\ngames = 1\nrounds = 5\n[grid]\npsi = [0.5, 1.0]\n"

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
    monkeypatch.chdir(root)
    before = sorted(p.relative_to(root) for p in root.rglob("*"))
    assert main(args) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"pairplay {args[0]}: "), err
    path = re.escape(named)
    assert re.search(rf"(?<![\w./-])(\S*/)?{path}(?![\w/-]|\.\w)", lines[0]), lines[0]
    assert sorted(p.relative_to(root) for p in root.rglob("*")) == before  # nothing written
