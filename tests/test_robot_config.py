"""The robot config file's numbers are each checked against their range when the file is read
(schemas/robot.py RANGES, SIGNS). A trial: `yaw_sign = 0` was taken (the head never turned left or right)
and a time of 1e20 s overflowed the driver's thread wait; each is now one line naming the field, its range
and the value, from the loader and on the command line."""

from __future__ import annotations

import json

import pytest

from pairplay.schemas.robot import RANGES, SIGNS, RobotConfig
from pairplay.services.robot.backends import load_robot_config


@pytest.mark.parametrize("field,value,said", [
    ("yaw_sign", 0, "yaw_sign must be 1 or -1 (a direction), got 0"),
    ("pitch_sign", 0.5, "pitch_sign must be 1 or -1 (a direction), got 0.5"),
    ("yaw_sign", 2, "yaw_sign must be 1 or -1"),
    ("give_up_s", 1e20, "give_up_s must be > 0 and at most 3600, got 1e+20"),
    ("ack_timeout_s", 1e9, "ack_timeout_s must be > 0 and at most 600"),
    ("head_turn_hold_s", 1e6, "head_turn_hold_s must be 0..60"),
    ("inflight_window_s", 100, "inflight_window_s must be 0..10"),
    ("max_commands_per_s", 1e12, "max_commands_per_s must be > 0 and at most 1000000"),
    ("head_turn_offset_m", 50, "head_turn_offset_m must be > 0 and at most 2"),
    ("reconnect_min_s", 0, "reconnect_min_s must be > 0 and at most 60"),
])
def test_a_robot_config_number_out_of_its_range_is_refused_naming_it(tmp_path, field, value, said):
    path = tmp_path / "robot.json"
    path.write_text(json.dumps({field: value}))
    with pytest.raises(ValueError) as err:
        load_robot_config(str(path))
    assert str(err.value) == f"robot config: {said}" or said in str(err.value), err.value


def test_every_number_of_the_robot_config_has_a_range_and_the_defaults_are_in_it(tmp_path):
    numbers = {f.name for f in __import__("msgspec").structs.fields(RobotConfig)
               if f.type in (float, int) and f.name != "command_burst"}  # command_burst: its own 1..500
    assert numbers == set(RANGES) | set(SIGNS)
    RobotConfig().validate()
    for sign in (1, -1, 1.0, -1.0):
        RobotConfig(yaw_sign=sign, pitch_sign=sign).validate()


def test_the_command_line_says_a_wrong_sign_in_one_line(tmp_path, capsys):
    from pairplay.cli.main import main

    (tmp_path / "robot.json").write_text('{"yaw_sign": 0}')
    assert main(["session", "--participant", "sim:blind", "--rounds", "1", "--robot", "virtual",
                 "--robot-config", str(tmp_path / "robot.json"), "--out", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "yaw_sign must be 1 or -1" in err, err
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir())



def test_the_benchs_robot_config_is_a_valid_one():
    """`pairplay bench`'s robot row lifts the rate limit (max_commands_per_s 1e6); the ranges added for the robot
    config's numbers refused it and the bench ended in a traceback."""
    from pairplay.bench.robot import BENCH_CONFIG

    BENCH_CONFIG.validate()
    assert BENCH_CONFIG.max_commands_per_s == 1e6
