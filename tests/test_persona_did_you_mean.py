"""A misspelt persona is refused with the one it resembles (a new user's trial).

`pairplay study --personas ashly` said "unknown persona 'ashly'; known: ashley, ..." and no hint, unlike a
misspelt key of every file (pairplay/nearest.py, one measure for all). Every verb that takes a persona's
name reads it through core/personas.py `persona`, so one place says it: `study --personas`, `protocol
pilot --personas`, `session --participant sim:NAME`.
"""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("args", [
    ["study", "--personas", "blind,ashly", "--games", "1", "--rounds", "1"],
    ["session", "--participant", "sim:ashly", "--rounds", "1"],
])
def test_a_misspelt_persona_names_the_one_it_resembles(pairplay_cli, tmp_path, args):
    r = pairplay_cli(*args, "--out", tmp_path / "out", cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "", r
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown persona 'ashly' (did you mean 'ashley'?); known: ashley, " in lines[0], lines


def test_a_name_like_none_has_no_hint_and_the_list(pairplay_cli, tmp_path):
    r = pairplay_cli("study", "--personas", "nobody", "--out", tmp_path / "out", cwd=tmp_path)
    assert r.returncode == 2 and "unknown persona 'nobody'; known: ashley, " in r.stderr and "did you mean" not in r.stderr
