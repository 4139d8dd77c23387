"""Which robot a session uses, as a value: the three --robot options.

Rule: a `RobotChoice` names a backend URL (virtual, iristk://host:1932,
furhat://host:9000) and optionally a robot config and a board calibration
file; `check_choice` refuses a bad one before a session starts (ValueError,
CalibrationError), `robot_unreachable` says why its robot does not answer now
(`session` and `lab` refuse to start, `protocol serve/pilot` warn: docs/robot.md),
and `start_bridge` starts the bus service that performs a
session's suggestions with it.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

from pairplay.errors import folded
from pairplay.services.bus import Bus
from pairplay.services.robot.backends import load_robot_config, parse_robot_url
from pairplay.services.robot.bridge import RobotBridge
from pairplay.services.robot.calibration import load_calibration

CONNECT_PROBE_S = 1.0  # a robot that does not answer a TCP connect in this time is said to be unreachable
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


def robot_unreachable(url: str, timeout_s: float = CONNECT_PROBE_S) -> str:
    """Why a networked robot does not accept a TCP connection now ("" if it does, or is virtual), in about
    a second instead of the driver's retries with backoff: what a session says before it starts."""
    scheme, host, port, _, _ = parse_robot_url(url)
    if scheme == "virtual":
        return ""
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as err:
        return err.strerror or ("no answer within %g s" % timeout_s if isinstance(err, TimeoutError) else folded(err))
    return ""


def start_bridge(bus: Bus, session: str, choice: RobotChoice, stop=None) -> RobotBridge:
    """A started RobotBridge for `session` on `bus`; ValueError on a bad option or file.
    `stop` ends its wait for the log of a session under way (RobotBridge.start)."""
    config = load_robot_config(choice.config)
    calibration = load_calibration(choice.calibration)
    return RobotBridge(bus, session, choice.url, config=config, calibration=calibration).start(stop)
