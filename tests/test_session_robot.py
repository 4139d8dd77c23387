"""`pairplay session --robot ...` chooses the robot bridge's backend, and every suggestion is acted."""

from collections import Counter

from pairplay.replay.reader import read_log
from pairplay.cli.main import main


def _tags(path):
    return Counter(type(r.event).__name__ for r in read_log(path).events)


def test_a_session_with_the_virtual_robot_records_one_robot_acted_per_suggestion(tmp_path):
    assert main(["session", "--participant", "sim:tatiana", "--rounds", "2", "--session", "withrobot",
                 "--robot", "virtual", "--out", str(tmp_path)]) == 0
    tags = _tags(tmp_path / "withrobot.mcap")
    assert tags["SuggestionMade"] > 0 and tags["RobotActed"] == tags["SuggestionMade"]


def test_no_robot_and_a_bad_robot_url(tmp_path, capsys):
    assert main(["session", "--participant", "sim:tatiana", "--rounds", "1", "--session", "norobot",
                 "--robot", "none", "--out", str(tmp_path)]) == 0
    assert _tags(tmp_path / "norobot.mcap")["RobotActed"] == 0
    assert main(["session", "--participant", "sim:tatiana", "--robot", "ftp://robot", "--out", str(tmp_path)]) == 2
    assert "robot" in capsys.readouterr().out.lower()
