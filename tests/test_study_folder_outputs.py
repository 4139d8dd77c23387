"""No verb but `pairplay protocol` writes inside a people's study folder, but the places the study's own verbs own
(cli/args.py `check_study_folders`; a new user's trial: `report pk --out pk --force`, `--out pk/recordings`,
`study --out dr/policies` all wrote there, exit 0).

Real study folders (`pairplay protocol init`), the verbs run as a researcher runs them (`python -m pairplay`).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pairplay.cli.args import check_study_folders
from pairplay.cli.main import build_parser
from pairplay.errors import UserError


@pytest.fixture(scope="module")
def studies(tmp_path_factory, pairplay_cli):
    """Two people's study folders, pk and dr, in one folder (the cwd of the commands), and files of no study."""
    here = tmp_path_factory.mktemp("inside")
    for name in ("pk", "dr"):
        r = pairplay_cli("protocol", "init", here / name, "--study", "thesis-ch7", "--key-file",
                         here / "private" / f"{name}.csv", "--quiet")
        assert r.returncode == 0, r.stderr
    grid = here / "grid.toml"
    grid.write_text((Path(__file__).parents[1] / "examples" / "sweep-50.toml").read_text())
    return here


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


REFUSED = {
    "report at the study's top": (["report", "pk", "--out", "pk", "--force"], "--out", "pk"),
    "report into recordings": (["report", "pk", "--out", "pk/recordings", "--force"], "--out", "pk/recordings"),
    "report into policies": (["report", "pk", "--out", "pk/policies"], "--out", "pk/policies"),
    "report into merged": (["report", "pk", "--out", "pk/merged", "--force"], "--out", "pk/merged"),
    "report into another study": (["report", "pk", "--out", "dr/recordings"], "--out", "dr/recordings"),
    "report of one into another's report": (["report", "pk", "--out", "dr/report"], "--out", "dr/report"),
    "a simulated study": (["study", "--personas", "blind", "--games", "1", "--rounds", "20", "--out",
                           "dr/policies"], "--out", "dr/policies"),
    "rebuild": (["rebuild", "nosuch.mcap", "--out", "pk/policies"], "--out", "pk/policies"),
    "combine": (["combine", "a.json", "b.json", "-o", "pk/merged/x.json"], "--out", "pk/merged/x.json"),
    "counterfactual": (["counterfactual", "nosuch.mcap", "--out", "pk/cf"], "--out", "pk/cf"),
    "sweep": (["sweep", "grid.toml", "--out", "pk/sweep"], "--out", "pk/sweep"),
    "session": (["session", "--participant", "P1", "--out", "pk/recordings"], "--out", "pk/recordings"),
    "view elsewhere in the study": (["view", "--recording", "x.mcap", "--out", "pk/x.rrd"], "--out", "pk/x.rrd"),
    "recover into exports": (["recover", "x.mcap", "-o", "pk/exports/x.mcap"], "--output", "pk/exports/x.mcap"),
}


@pytest.mark.parametrize("key", sorted(REFUSED))
def test_an_output_inside_a_peoples_study_folder_is_refused_before_any_work(studies, pairplay_cli, key):
    argv, option, typed = REFUSED[key]
    before = _listing(studies)
    r = pairplay_cli(*argv, cwd=studies)
    lines = r.stderr.splitlines()
    assert r.returncode == 2 and len(lines) == 1, (r.returncode, r.stderr)
    assert option in lines[0] and repr(typed) in lines[0] and "only `pairplay protocol` writes" in lines[0], lines
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert _listing(studies) == before  # nothing written


def _checked(argv: list[str]) -> None:
    parser, chosen = build_parser(argv)
    args = parser.parse_args(argv)
    check_study_folders(args.verb, chosen, args)


def test_the_places_the_studys_own_verbs_own_stay_theirs(studies, pairplay_cli, monkeypatch):
    """report's STUDY/report (its default, and given), participant export's STUDY/exports/<id>.zip, and a view or
    recover beside a game's recording in STUDY/recordings/ (what the deletion erases) pass the check (an export
    inside the study is left to its own, finer check: tests/test_protocol.py)."""
    monkeypatch.chdir(studies)
    (studies / "pk" / "recordings").mkdir(exist_ok=True)
    (studies / "pk" / "recordings" / "s1.mcap").write_bytes(b"")  # a game's recording, by name
    try:
        for argv in (["report", "pk"], ["report", "pk", "--out", "pk/report"],
                     ["participant", "export", "pk", "P1"], ["participant", "export", "pk", "P1", "-o", "pk/exports/"],
                     ["participant", "export", "pk", "P1", "-o", "pk/exports/P1.zip"],
                     ["view", "--recording", "pk/recordings/s1.mcap", "--out", "pk/recordings/s1.rrd"],
                     ["recover", "pk/recordings/s1.mcap", "-o", "pk/recordings/s1.recovered.mcap"],
                     ["recover", "pk/recordings/s1.mcap", "-o", "pk/recordings/"],
                     ["report", "pk", "--out", "elsewhere"], ["study", "--out", "out/study"]):
            _checked(argv)  # no UserError
        with pytest.raises(UserError):
            _checked(["view", "--recording", "pk/recordings/s1.mcap", "--out", "pk/recordings/s2.rrd"])
    finally:
        (studies / "pk" / "recordings" / "s1.mcap").unlink()
    r = pairplay_cli("protocol", "status", "pk", cwd=studies)
    assert r.returncode == 0, r.stderr
