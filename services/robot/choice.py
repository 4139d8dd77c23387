"""Which robot a session uses, as a value: the three --robot options.

Rule: a `RobotChoice` names a backend URL (virtual, iristk://host:1932,
furhat://host:9000) and optionally a robot config and a board calibration
file; `check_choice` refuses a bad one before a session starts (ValueError,
CalibrationError) and `start_bridge` starts the bus service that performs a
session's suggestions with it.
"""

from __future__ import annotations

from dataclasses import dataclass

from pairplay.services.bus import Bus
from pairplay.services.robot.backends import load_robot_config, parse_robot_url
from pairplay.services.robot.bridge import RobotBridge
from pairplay.services.robot.calibration import load_calibration

NO_ROBOT = "none"  # --robot none: a session without a robot bridge (simulated participants need none)


@dataclass(frozen=True)
class RobotChoice:
    url: str = "virtual"
    config: str | None = None  # RobotConfig JSON file: gesture names, texts, timings
    calibration: str | None = None  # board calibration JSON file (default: the packaged one)


def check_choice(choice: RobotChoice) -> None:
    """Refuse a bad URL, robot config or calibration (ValueError, CalibrationError)."""
    parse_robot_url(choice.url, load_robot_config(choice.config))
    load_calibration(choice.calibration)


def start_bridge(bus: Bus, session: str, choice: RobotChoice, stop=None) -> RobotBridge:
    """A started RobotBridge for `session` on `bus`; ValueError on a bad option or file.
    `stop` ends its wait for the log of a session under way (RobotBridge.start)."""
    config = load_robot_config(choice.config)
    calibration = load_calibration(choice.calibration)
    return RobotBridge(bus, session, choice.url, config=config, calibration=calibration).start(stop)
