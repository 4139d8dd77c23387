"""A JSON input that gives one key twice in one object is refused in one line naming the key and the file
(schemas/repeated.py; trial28 F16): msgspec and json kept the last value without a word, so a second
`"partial": ""` passed a partial policy off as whole and a second `"participant"` moved a policy."""

from __future__ import annotations

import logging
from importlib import resources
from pathlib import Path

import msgspec
import pytest

from pairplay.replay.rebuild import rebuild_recording
from pairplay.schemas import policy as policy_file

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"


@pytest.fixture(scope="module")
def policy_bytes() -> bytes:
    return policy_file.FILE.encode(rebuild_recording(SAMPLE).policy)


def _again(data: bytes, text: str) -> bytes:
    """`data`, one JSON object, with `text` (`"key": value`) added before its closing brace."""
    body = data.rstrip()
    assert body.endswith(b"}")
    return body[:-1] + b", " + text.encode() + b"}\n"


@pytest.mark.parametrize("verb", ["profile", "combine"])
def test_a_policy_whose_partial_flag_is_given_again_empty_is_refused_naming_the_key_and_file(
        tmp_path, policy_bytes, capsys, verb):
    """The finding's repro: a partial policy with a second `"partial": ""` was profiled and combined as whole,
    exit 0; now exit 2 and one line naming the file and the key."""
    from pairplay.cli.main import main

    partial = msgspec.structs.replace(policy_file.FILE.decode(policy_bytes), partial="damaged: chunk 14")
    bad = tmp_path / "dup_partial.json"
    bad.write_bytes(_again(policy_file.FILE.encode(partial), '"partial": ""'))
    (tmp_path / "b.json").write_bytes(policy_bytes)
    args = [verb, str(bad), str(tmp_path / "b.json")] + (["-o", str(tmp_path / "m.json")] if verb == "combine" else [])
    assert main(args) == 2
    [line] = capsys.readouterr().err.splitlines()
    assert str(bad) in line and "the key `partial` is given twice" in line, line
    assert not (tmp_path / "m.json").exists()


def test_a_nested_key_given_twice_is_named_where_it_is(policy_bytes):
    from pairplay.errors import InputError

    data = policy_bytes.replace(b'"participant"', b'"participant": "wasim", "participant"', 1)
    with pytest.raises(InputError, match="the key `participant` is given twice"):
        policy_file.FILE.decode(data, "p.json")
    from pairplay.schemas.repeated import repeated_key
    assert repeated_key(b'{"a": [{"b": {"c": 1, "c": 2}}]}') == ("a[0].b", "c")
    assert repeated_key(b'{"a": {"c": 1}, "b": {"c": 2}}') is None  # the same key in two objects is fine


def _robot_config(tmp_path):
    from pairplay.services.robot.backends import load_robot_config
    (tmp_path / "robot.json").write_bytes(b'{"gaze_speed": "fast", "gaze_speed": "medium"}')
    with pytest.raises(ValueError, match=r"robot\.json.*the key `gaze_speed` is given twice"):
        load_robot_config(str(tmp_path / "robot.json"))


def _calibration(tmp_path):
    from pairplay.services.robot.calibration import load_calibration
    calibration = resources.files("pairplay.services.robot").joinpath("calibration_default.json").read_bytes()
    (tmp_path / "calibration.json").write_bytes(calibration.replace(b'{', b'{"description": "moved", ', 1))
    with pytest.raises(Exception, match=r"calibration\.json.*the key `description` is given twice"):
        load_calibration(tmp_path / "calibration.json")


def _settings(tmp_path):
    from pairplay.replay.studydata import _settings
    (tmp_path / "settings.json").write_bytes(b'{"key_file": "keys.csv", "key_file": ""}')
    with pytest.raises(Exception, match=r"the key `key_file` is given twice") as err:
        _settings(tmp_path / "settings.json")
    assert "settings.json" in str(err.value)


def _cell(tmp_path):
    from pairplay.report.sweep import _check_cell, read_grid
    (tmp_path / "grid.toml").write_bytes(b'seeds = 1\n[study]\npersonas = "blind"\n')
    grid = read_grid(tmp_path / "grid.toml")
    (tmp_path / "cell.json").write_bytes(b'{"setting": [], "seed": 5, "seed": 0, "measures": {}}')
    with pytest.raises(ValueError, match=r"not a cell file: the key `seed` is given twice"):
        _check_cell(tmp_path / "cell.json", grid, grid.cells()[0])


def _journal_line(tmp_path):
    from pairplay.schemas.journal import decode_line
    line = b'{"event": "ParticipantRegistered", "participant": "p01", "participant": "p02", "joins": "a"}\n'
    with pytest.raises(msgspec.ValidationError, match="the key `participant` more than once"):
        decode_line(line)


def _manifest(tmp_path):
    from pairplay.outputs import MANIFEST_FORMAT, read_manifest
    (tmp_path / "manifest.json").write_bytes(
        b'{"format": "%s", "files": ["a.txt"], "files": ["b.txt"]}' % MANIFEST_FORMAT.encode())
    logger = logging.getLogger("pairplay.outputs")
    said: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: said.append(record.getMessage())
    logger.addHandler(handler)
    try:
        assert read_manifest(tmp_path / "manifest.json") == []
    finally:
        logger.removeHandler(handler)
    assert any("the key `files` more than once" in s for s in said), said


@pytest.mark.parametrize("case", [_robot_config, _calibration, _settings, _cell, _journal_line, _manifest],
                         ids=lambda f: f.__name__.strip("_"))
def test_every_json_file_a_user_edits_refuses_a_key_given_twice(tmp_path, case):
    """The robot config, the calibration, a study's settings.json, a sweep cell, a journal line and an output
    folder's manifest: each read a repeated key last-wins; each refuses it naming the key."""
    case(tmp_path)
