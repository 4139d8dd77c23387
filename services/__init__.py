"""Processes on the bus and the command line: thin shells around `pairplay.core`.

Only this package imports zenoh, the robot clients, the web server or rerun.
"""
