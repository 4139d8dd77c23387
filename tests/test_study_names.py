"""A study file or a phase named wrong is refused with what there is (a new user's trial).

`pairplay protocol init ST --study thesis-ch8` (a bundled study's name, misremembered) said only
"thesis-ch8: cannot read: No such file or directory", not that `--study` takes a bundled study's name
nor which ones there are; `protocol register --phase phase3` named no phase of the study. Now: the
bundled studies (and the one it resembles, pairplay/nearest.py), and the study's phases.
"""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("verb", [["protocol", "init", "ST", "--study"], ["protocol", "check"]])
@pytest.mark.parametrize("name, hint", [("thesis-ch8", ""), ("thesis_ch7", " (did you mean 'thesis-ch7'?)"),
                                        ("my-study.toml", "")])
def test_a_study_file_neither_there_nor_bundled_lists_the_bundled_ones(pairplay_cli, tmp_path, verb, name, hint):
    r = pairplay_cli(*verb, name, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "", r
    assert r.stderr == (f"pairplay {' '.join(verb[:2])}: {name}: no such study file, nor a bundled study{hint}; "
                        "the bundled studies: thesis-ch7 (`pairplay protocol example` prints one to edit); "
                        "or give the path of a study TOML file" + (" (--study)" if "--study" in verb else "") + "\n")
    assert not (tmp_path / "ST").exists()


def test_a_bundled_study_by_name_still_makes_the_folder(pairplay_cli, tmp_path):
    r = pairplay_cli("protocol", "init", "ST", "--study", "thesis-ch7", cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "ST" / "study.toml").exists(), r
    assert not list(tmp_path.glob(".thesis-ch7*")), "the bundled study's temporary copy is gone"


def test_a_phase_not_in_the_study_is_said_with_its_phases(pairplay_cli, tmp_path):
    assert pairplay_cli("protocol", "init", "ST", "--study", "thesis-ch7", cwd=tmp_path).returncode == 0
    r = pairplay_cli("protocol", "register", "ST", "--phase", "phase3", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr == ("pairplay protocol register: no phase 'phase3' in study 'thesis-ch7'; "
                                              "its phases: phase1, phase2\n"), r
    r = pairplay_cli("protocol", "register", "ST", "--phase", "phse1", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr == ("pairplay protocol register: no phase 'phse1' in study 'thesis-ch7' "
                                              "(did you mean 'phase1'?); its phases: phase1, phase2\n"), r
