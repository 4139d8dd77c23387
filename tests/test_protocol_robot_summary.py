"""`protocol serve`'s robot summary after a game: a normal one is info, a real failure a warning.

Each game of `protocol serve` logged `WARNING pairplay.protocol: ... robot virtual: 5 of 177 suggestions
delivered`: every game whose participant was quicker than the robot (superseded suggestions) read as a
fault. Now only a failed or unacknowledged suggestion (replay/delivery.py TROUBLE) makes it a warning."""

from __future__ import annotations

import logging
from pathlib import Path

from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner, scripted_players
from pairplay.services.robot.choice import RobotChoice

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def test_a_games_normal_robot_summary_is_info_not_a_warning(tmp_path, caplog):
    data = StudyData.create(tmp_path / "study", STUDY, key_file=tmp_path / "keys.csv")
    pid = data.register("phase1")
    caplog.set_level(logging.INFO, logger="pairplay.protocol")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus, robot=RobotChoice("virtual?time_scale=0"))
        # blind picks at once: the robot is superseded turn after turn, the normal course of a quick participant
        game = runner.run_game(pid, "phase1", 1, scripted_players(runner, {pid: "blind"})(pid, "phase1", 1))
    line = runner.delivery[game.session]
    assert "suggestions delivered" in line and "failed" not in line and "unacknowledged" not in line, line
    said = [r for r in caplog.records if r.name == "pairplay.protocol" and line in r.getMessage()]
    assert [r.levelname for r in said] == ["INFO"], [(r.levelname, r.getMessage()) for r in caplog.records]
