"""Choosing a robot backend from a URL: `--robot virtual|iristk://host:1932|furhat://host:9000`.

Rule: the URL names the protocol and the robot; everything else comes from the
RobotConfig (file or defaults), and a few query parameters override it for one
run: iristk://host:port?ticket=furhat&name=pairplay&gestures=thesis,
furhat://host:port?key=SECRET&gestures=furhat, virtual?time_scale=0.1.
Gesture names default to the backend's own set (GESTURE_PRESETS): "iristk" over
the broker, "furhat" over the Realtime API and for the virtual robot.
An unknown scheme, port or parameter is refused with the accepted forms
(schemas/robot_url.py: the one parser of a robot URL, also a study file's).
"""

from __future__ import annotations

import logging
from typing import Callable

import msgspec

from pairplay.inputs import refusal
from pairplay.schemas.jsonfile import a_folder, empty, in_words, without_bom
from pairplay.schemas.robot import GESTURE_PRESETS, PRESET_NOTES, BoardCalibration, RobotActed, RobotConfig
from pairplay.schemas.robot_url import FORMS, parse_robot_url  # noqa: F401 (FORMS: the --robot help)

from pairplay.services.robot.calibration import Board, load_calibration
from pairplay.services.robot.driver import RobotDriver
from pairplay.services.robot.iristk import IrisTKTransport
from pairplay.services.robot.realtime import RealtimeTransport
from pairplay.services.robot.render import Renderer
from pairplay.services.robot.transport import Transport
from pairplay.services.robot.virtual import VirtualTransport
from pairplay.schemas.nesting import json_decode


def make_transport(url: str, config: RobotConfig | None = None) -> tuple[Transport, RobotConfig]:
    scheme, host, port, config, extra = parse_robot_url(url, config)
    if scheme == "iristk":
        return IrisTKTransport(host, port, config), config
    if scheme == "furhat":
        return RealtimeTransport(host, port, config), config
    return VirtualTransport(extra.get("time_scale", 1.0)), config


def load_robot_config(path: str | None) -> RobotConfig:
    """A RobotConfig JSON file (strict), or the defaults for None."""
    if path is None:
        return RobotConfig()
    if said := refusal(path):  # before opening: a pipe blocked (pairplay/inputs.py)
        raise ValueError(f"robot config {path}: {said}")
    try:
        with open(path, "rb") as f:
            raw = f.read()
        if empty(raw):
            raise ValueError(f"robot config {path}: {empty(raw)}")
        config = json_decode(without_bom(raw), type=RobotConfig)
    except IsADirectoryError:
        raise ValueError(a_folder(path, "robot config", "its JSON file")) from None
    except OSError as exc:
        raise ValueError(f"cannot read robot config {path}: {exc}") from exc
    except msgspec.DecodeError as exc:
        raise ValueError(f"robot config {path} is not valid: {in_words(exc, RobotConfig, without_bom(raw))}") from exc
    config.validate()
    return config


def open_robot(url: str, on_acted: Callable[[RobotActed], None], *,
               config: RobotConfig | None = None,
               calibration: BoardCalibration | str | None = None,
               on_rejected: Callable[[str, str], None] | None = None) -> RobotDriver:
    """A started driver for the robot at `url`; it connects (and reconnects) on its own.

    calibration: a BoardCalibration, a path to a calibration file, or None for
    the packaged default. Call `.perform(Suggestion)` and finally `.close()`.
    """
    transport, config = make_transport(url, config)
    if not isinstance(calibration, BoardCalibration):
        calibration = load_calibration(calibration)
    gestures = config.gestures or GESTURE_PRESETS["furhat"]  # parse_robot_url always fills it
    for preset, note in PRESET_NOTES.items():
        if gestures == GESTURE_PRESETS[preset]:
            logging.getLogger("pairplay.robot").warning("gestures %s: %s", preset, note)
    renderer = Renderer(Board(calibration), gestures, config)
    return RobotDriver(transport, renderer, config, on_acted, on_rejected).start()
