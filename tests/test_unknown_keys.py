"""No input file drops a misspelt key silently: a key its reader does not declare is refused, at every level
of every file a user gives pairplay, in one line naming the file, the key and the key it resembles.

A new user's trial: a policy file with `reward_bonsu` (or `confgi`, `versoin`) at its top was accepted, the
key dropped and the default used; `pairplay combine` exited 0 (its nested structs already refused unknown
keys). A file of a newer version (which may add keys) is refused for its version, not for a key; and every
file pairplay itself writes reads back (it never writes a key its reader does not declare).
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest

from pairplay.cli.main import main
from pairplay.errors import InputError
from pairplay.schemas import policy as policy_file
from pairplay.schemas import usermodel

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "recordings" / "samples" / "sim-ashley.mcap"
HELMUT = ROOT / "recordings" / "samples" / "sim-helmut-fmt2.mcap"


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    """The files pairplay's writing verbs make: `study` (LSPI: its policies carry q_meaning and lspi; the merged
    ones info, rules, merged_from), `rebuild` of a recording, `combine` of those, `counterfactual` (a user model)."""
    out = tmp_path_factory.mktemp("made")
    runs = [["study", "--out", out / "study", "--personas", "blind,deaf", "--games", "2", "--rounds", "10",
             "--eval-rounds", "2", "--reuse-seeds", "1", "--algorithm", "lspi"],
            ["rebuild", SAMPLE, HELMUT, "--out", out / "rebuilt", "--no-plot"],
            # (two participants of two policies each: combine refuses a participant of one, whose profile
            # algorithm 3 cannot compute)
            ["combine", out / "study" / "policies" / "blind", out / "study" / "policies" / "deaf", "-o",
             out / "combined.policy.json"],
            ["counterfactual", HELMUT, "--fit-only", "--out", out / "cf"]]
    for args in runs:
        assert main([*map(str, args), "-q"]) == 0, args
    return out


def _key_line(capsys, args) -> str:
    """The one stderr line of a verb that must refuse (exit 2)."""
    capsys.readouterr()
    assert main([*map(str, args), "-q"]) == 2, args
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def _misspelt(data: dict, where: tuple, key: str) -> dict:
    """`data` (a copy) with `key` added to the object at `where`."""
    data = json.loads(json.dumps(data))
    node = data
    for k in where:
        node = node[k]
    node[key] = 1
    return data


@pytest.mark.parametrize("where,key,near", [
    ((), "reward_bonsu", "reward_bonus"),  # the trial's three
    ((), "confgi", "config"),
    ((), "versoin", "version"),
    (("info",), "compared_stats", "compared_states"),  # a merged policy's user information
])
def test_combine_refuses_a_policy_with_a_misspelt_key_naming_file_key_and_suggestion(tmp_path, made, capsys,
                                                                                    where, key, near):
    good = made / "study" / "merged" / "all.json"
    bad = tmp_path / "typo.json"
    bad.write_text(json.dumps(_misspelt(json.loads(good.read_bytes()), where, key)))
    line = _key_line(capsys, ["combine", good, bad, "-o", tmp_path / "m.json"])
    place = ".".join(where) + ": " if where else ""
    assert line.endswith(f"{bad}: corrupt or not a policy file: {place}no key `{key}` is known here "
                         f"(did you mean `{near}`?)"), line
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("where,key,near", [
    ((), "partal", "partial"),
    (("focus",), "levle", "level"),  # FeatureFit
    (("p_consider",), "estimat", "estimate"),  # RateFit
    (("persona",), "memroy", "memory"),  # already refused: the guard of the nested kind
])
def test_a_user_model_file_with_a_misspelt_key_is_refused_naming_file_key_and_suggestion(tmp_path, made, where,
                                                                                        key, near):
    good = made / "cf" / "sim-helmut-fmt2.usermodel.json"
    bad = tmp_path / "typo.usermodel.json"
    bad.write_text(json.dumps(_misspelt(json.loads(good.read_bytes()), where, key)))
    with pytest.raises(usermodel.UserModelFileError) as err:
        usermodel.read_user_model(bad)
    place = ".".join(where) + ": " if where else ""
    assert str(err.value) == (f"{bad}: corrupt or not a user-model file: {place}no key `{key}` is known here "
                              f"(did you mean `{near}`?)")


def test_a_counted_rate_with_a_misspelt_key_is_refused(tmp_path, made):
    """CountedRate (a simulated participant's own report): written only when the recording has it."""
    data = json.loads((made / "cf" / "sim-helmut-fmt2.usermodel.json").read_bytes())
    data["considered_counted"] = {"count": 1, "of": 2, "rate": 0.5, "low95": 0.1, "high95": 0.9, "rat": 1}
    with pytest.raises(usermodel.UserModelFileError, match=r"considered_counted: no key `rat` is known here "
                                                           r"\(did you mean `rate`\?\)"):
        usermodel.decode_user_model(json.dumps(data).encode(), "m.json")


@pytest.mark.parametrize("kind", ["policy", "user-model"])
def test_a_newer_file_is_refused_for_its_version_not_for_a_key_it_adds(tmp_path, made, kind):
    """A newer pairplay may add keys: its file is "newer than this pairplay; upgrade", not "no key `x`"."""
    good = made / "study" / "merged" / "all.json" if kind == "policy" else made / "cf" / "sim-helmut-fmt2.usermodel.json"
    module = policy_file if kind == "policy" else usermodel
    data = {**json.loads(good.read_bytes()), "version": module.VERSION + 1, "added_later": 1}
    with pytest.raises(InputError) as err:
        module.FILE.decode(json.dumps(data).encode(), "f.json")
    assert str(err.value) == (f"f.json: {kind} file version {module.VERSION + 1} is newer than this pairplay "
                              f"(reads up to {module.VERSION}); upgrade pairplay")


def test_a_file_of_another_kind_is_refused_for_its_format_not_for_its_keys(made):
    """A user model given as a policy: "not a pairplay policy file (format ...)", not its first unknown key."""
    with pytest.raises(policy_file.PolicyFileError) as err:
        policy_file.read_policy(made / "cf" / "sim-helmut-fmt2.usermodel.json")
    assert str(err.value).endswith("not a pairplay policy file (format 'pairplay.usermodel')"), err.value


def test_every_file_pairplays_verbs_write_reads_back(made):
    """pairplay never writes a key its reader does not declare: each JSON file the writing verbs made is read
    by its kind's strict reader (by its `format`), and none is left unread."""
    readers = {policy_file.FORMAT: policy_file.read_policy, usermodel.FORMAT: usermodel.read_user_model}
    read = {}
    for path in sorted(made.rglob("*.json")):
        read[path.relative_to(made).as_posix()] = readers[json.loads(path.read_bytes())["format"]](path)
    assert {"combined.policy.json", "study/merged/all.json", "study/policies/deaf/game-01.json",
            "rebuilt/sim-ashley.policy.json", "rebuilt/sim-helmut-fmt2.policy.json",
            "cf/sim-helmut-fmt2.usermodel.json"} <= set(read)
    assert read["study/policies/deaf/game-01.json"].q_meaning  # an LSPI file: its extra keys read too
    assert read["study/merged/all.json"].info is not None and read["study/merged/all.json"].rules


def test_the_other_input_files_refuse_a_misspelt_key_at_every_level(tmp_path):
    """The robot config, the calibration, a study folder's settings.json, the study and sweep TOML files:
    (these refused unknown keys before; the guard that they still do, at each of their levels)."""
    from pairplay.replay.studydata import StudyDataError, _settings
    from pairplay.report.sweep import GridError, read_grid
    from pairplay.schemas.study import StudyFileError, example_text, parse_study
    from pairplay.services.robot.backends import load_robot_config
    from pairplay.services.robot.calibration import CalibrationError, load_calibration

    def refused(error, fn, text):
        with pytest.raises(error) as err:
            fn()
        assert text in str(err.value) and "\n" not in str(err.value), err.value

    for doc, said in [({"yaw_sgn": 1}, "no key `yaw_sgn` is known here (did you mean `yaw_sign`?)"),
                      ({"speech": {"uup": "x"}}, "speech: no key `uup` is known here (did you mean `up`?)"),
                      ({"gestures": {"smile": "a", "nod": "b", "smiel": "c"}},
                       "gestures: no key `smiel` is known here (did you mean `smile`?)")]:
        (tmp_path / "rc.json").write_text(json.dumps(doc))
        refused(ValueError, lambda: load_robot_config(str(tmp_path / "rc.json")), said)
    cal = json.loads(resources.files("pairplay.services.robot").joinpath("calibration_default.json").read_bytes())
    (tmp_path / "cal.json").write_text(json.dumps({**cal, "descripton": "x"}))
    refused(CalibrationError, lambda: load_calibration(tmp_path / "cal.json"),
            "no key `descripton` is known here (did you mean `description`?)")
    (tmp_path / "settings.json").write_text('{"key_fiel": "k.csv"}')
    refused(StudyDataError, lambda: _settings(tmp_path / "settings.json"),  # (its words were in parentheses)
            "not the study's settings: no key `key_fiel` is known here (did you mean "
            f'`key_file`?); it is {{"key_file": "<path or empty>"}} ({tmp_path / "settings.json"})')
    study = example_text()
    for old, new, said in [
            ("[study]", "sede = 3\n[study]", "s.toml: sede: the top of the file has no key `sede`"),
            ("[study]", "[study]\nsede = 3", "s.toml: [study] sede: [study] has no key `sede` (did you mean `seed`?)"),
            ("[[phase]]", "[[phase]]\ngmaes = 3", "[[phase]] has no key `gmaes` (did you mean `games`?)"),
            ("[questionnaire.after-game]", "[questionnaire.after-game]\ntitel = 'x'",
             "[questionnaire.after-game] has no key `titel` (did you mean `title`?)"),
            ("[[questionnaire.after-game.item]]", "[[questionnaire.after-game.item]]\nscael = 5",
             "[[questionnaire.after-game.item]] has no key `scael` (did you mean `scale`?)")]:
        refused(StudyFileError, lambda: parse_study(study.replace(old, new, 1), "s.toml"), said)
    for text, said in [('seds = 1\n[study]\npersonas = "blind"\n', "seds: no such key at the top of the file "
                                                                     "(did you mean `seeds`?)"),
                       ('[study]\nrouns = 3\n', "[study] rouns: no study setting `rouns` (did you mean `rounds`?)"),
                       ('[grid]\nrouns = [3]\n', "[grid] rouns: no study setting `rouns` (did you mean `rounds`?)")]:
        (tmp_path / "g.toml").write_text(text)
        refused(GridError, lambda: read_grid(tmp_path / "g.toml"), said)


def test_every_unknown_or_retired_key_of_a_json_file_is_named_at_once(tmp_path):
    """A robot config with two retired keys (and a typo, and one in a nested table) named them one at a time:
    fix one, rerun, told the next (a new user's trial). msgspec stops at the first; the line names all, in the
    file's order, each as the one alone is said (schemas/jsonfile.py `unknown_keys`); past 5, "and N more"."""
    from pairplay.services.robot.backends import load_robot_config
    from pairplay.services.robot.calibration import CalibrationError, load_calibration

    (tmp_path / "old.json").write_text(json.dumps({"iristk_subscriber_wait_s": 5.0, "yaw_sgn": 1,
                                                   "iristk_wait_for_subscriber": True, "speech": {"exakt": "x"}}))
    with pytest.raises(ValueError) as err:
        load_robot_config(str(tmp_path / "old.json"))
    line = str(err.value)
    said = ["the key `iristk_subscriber_wait_s` was retired", "no key `yaw_sgn` is known here (did you mean `yaw_sign`?)",
            "the key `iristk_wait_for_subscriber` was retired", "speech: no key `exakt` is known here (did you mean `exact`?)"]
    assert "\n" not in line and all(s in line for s in said), line
    assert [line.index(s) for s in said] == sorted(line.index(s) for s in said), line  # the file's order
    many = {**{f"extra{n}": n for n in range(7)}}
    (tmp_path / "many.json").write_text(json.dumps(many))
    with pytest.raises(ValueError) as err:
        load_robot_config(str(tmp_path / "many.json"))
    assert "`extra4`" in str(err.value) and "`extra5`" not in str(err.value) and str(err.value).endswith("; and 2 more")
    calibration = json.loads(resources.files("pairplay.services.robot").joinpath("calibration_default.json").read_text())
    (tmp_path / "cal.json").write_text(json.dumps({**calibration, "bogus": 1, "bogus2": 2}))
    with pytest.raises(CalibrationError) as err:
        load_calibration(tmp_path / "cal.json")
    assert "`bogus`" in str(err.value) and "`bogus2`" in str(err.value), str(err.value)


def test_every_unknown_key_of_a_study_or_sweep_file_is_named_at_once(tmp_path):
    from pairplay.report.sweep import GridError, read_grid
    from pairplay.schemas.study import StudyFileError, example_text, parse_study

    text = example_text().replace("seed = 0", "sed = 0\nrobt = \"virtual\"").replace("rounds = 5", "rouns = 5")
    with pytest.raises(StudyFileError) as err:
        parse_study(text, "s.toml")
    line = str(err.value)
    assert line.startswith("s.toml: [study] sed: [study] has no key `sed` (did you mean `seed`?); [study] robt: ") \
        and '[[phase]] "phase1" rouns: ' in line and '[[phase]] "phase2" rouns: ' in line and "\n" not in line, line
    (tmp_path / "g.toml").write_text('sedes = 3\n[study]\ngams = 2\nrouns = 3\n[grid]\nrewrd_bonus = ["match"]\n')
    with pytest.raises(GridError) as err:
        read_grid(tmp_path / "g.toml")
    line = str(err.value)
    assert all(s in line for s in ["sedes: no such key at", "[study] gams: no study setting `gams`", "[study] rouns: ",
                                   "[grid] rewrd_bonus: no study setting `rewrd_bonus` (did you mean `reward_bonus`?)"]), line
