"""The robot bridge (issue 5): performs each suggestion on a Furhat robot or a virtual one.

Rule: `open_robot(url, on_acted)` picks the backend from a URL (virtual,
iristk://host:1932, furhat://host:9000) and returns a started driver;
`RobotBridge` is the bus service that feeds it SuggestionMade events and
publishes one RobotActed per suggestion. See docs/robot.md.
"""

from pairplay.services.robot.backends import make_transport, open_robot, parse_robot_url
from pairplay.services.robot.driver import RobotDriver, Suggestion

__all__ = ["RobotDriver", "Suggestion", "make_transport", "open_robot", "parse_robot_url"]
