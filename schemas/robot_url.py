"""The --robot URL, read as a value: `virtual|iristk://host:1932|furhat://host:9000`.

Rule: one parser for every place a robot URL is given (the --robot option, a
study file's `robot`, `protocol serve/pilot --robot`), so a URL one of them
refuses is refused by all, before anything starts. The URL names the protocol
and the robot; everything else comes from the RobotConfig (file or defaults),
and a few query parameters override it for one run:
iristk://host:port?ticket=furhat&name=pairplay&gestures=thesis,
furhat://host:port?key=SECRET&gestures=furhat, virtual?time_scale=0.1.
Gesture names default to the backend's own set (GESTURE_PRESETS): "iristk"
over the broker, "furhat" over the Realtime API and for the virtual robot. An
unknown scheme, a missing host, a bad port or an unknown parameter is a
ValueError naming the URL and the accepted forms. Pure: no connection is tried.
"""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

import msgspec

from .robot import GESTURE_PRESETS, RobotConfig

FORMS = "virtual, iristk://HOST[:1932], furhat://HOST[:9000]"
DEFAULT_PORTS = {"iristk": 1932, "furhat": 9000}  # the IrisTK broker's, the Furhat Realtime API's
DEFAULT_GESTURES = {"virtual": "furhat", "iristk": "iristk", "furhat": "furhat"}
# query parameter -> RobotConfig field, per scheme
OVERRIDES = {
    "virtual": {},
    "iristk": {"ticket": "iristk_ticket", "name": "iristk_name", "agent": "iristk_agent"},
    "furhat": {"key": "realtime_key"},
}


def _split(url: str):
    """`url` split as a URL (`virtual?time_scale=0` has no `://`)."""
    return urlsplit(url if "://" in url else url.replace("virtual", "virtual://", 1))


def robot_kind(url: str) -> str:
    """Which robot a --robot URL names, its scheme alone (`virtual`, `iristk`, `furhat`): what a session's config
    records of it (SessionConfig.robot; its host and its parameters, a key among them, are not recorded)."""
    return _split(url).scheme


def parse_robot_url(url: str, config: RobotConfig | None = None) -> tuple[str, str, int, RobotConfig, dict]:
    """(scheme, host, port, effective config, extra params) of a --robot URL; ValueError if wrong."""
    config = config or RobotConfig()
    parts = _split(url)
    scheme = parts.scheme
    if scheme not in OVERRIDES:
        raise ValueError(f"--robot {url!r}: unknown backend {scheme!r}; use one of {FORMS}")
    try:
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"--robot {url!r}: bad port ({exc})") from None
    if port == 0:  # `port or DEFAULT_PORTS` below made :0 the default port without a word (a new user's trial)
        raise ValueError(f"--robot {url!r}: bad port (0: give the robot's port, or none for the default)")
    host = parts.hostname or ""
    if scheme != "virtual" and not host:
        raise ValueError(f"--robot {url!r}: needs a host, e.g. {scheme}://192.0.2.10")
    if scheme == "virtual" and (host or port is not None or parts.path):
        raise ValueError(f"--robot {url!r}: the virtual robot has no host or port; use one of {FORMS}")
    params = {k: v[-1] for k, v in parse_qs(parts.query, keep_blank_values=True).items()}
    changes: dict = {}
    extra: dict = {}
    for key, value in params.items():
        if key in OVERRIDES[scheme]:
            changes[OVERRIDES[scheme][key]] = value
        elif key == "gestures":
            if value not in GESTURE_PRESETS:
                raise ValueError(f"--robot {url!r}: gestures must be one of {sorted(GESTURE_PRESETS)}")
            changes["gestures"] = GESTURE_PRESETS[value]
        elif key == "time_scale" and scheme == "virtual":
            try:
                extra["time_scale"] = float(value)
            except ValueError:
                raise ValueError(f"--robot {url!r}: time_scale must be a number") from None
        else:
            raise ValueError(f"--robot {url!r}: unknown parameter {key!r}")
    if config.gestures is None and "gestures" not in changes:
        changes["gestures"] = GESTURE_PRESETS[DEFAULT_GESTURES[scheme]]
    config = msgspec.structs.replace(config, **changes)
    config.validate()
    return scheme, host, port or DEFAULT_PORTS.get(scheme, 0), config, extra
