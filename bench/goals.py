"""Every goal `pairplay bench` judges, in one table, and the verdict of a row against it.

Rule: a bench row names its goal by key (`row["goal"]`); the goal says what is
compared (the row's value, or its ratio to the reference measured in the same
run), how (">=" or "<=") and with what. A row met its goal or missed it; a row
without a goal is context (a reference shown for itself). Sources of the
figures: issue 16 (the compiled core), issue 17 (LSPI, the gym env), docs/bus.md (latency), docs/view.md.
"""

from __future__ import annotations

from typing import NamedTuple


class Goal(NamedTuple):
    text: str  # how the table states it
    on: str  # "value" or "ratio"
    op: str  # ">=" or "<="
    target: float


GOALS: dict[str, Goal] = {
    # core: the compiled simulator (issue 16)
    "steps": Goal(">= 3 M steps/s", "value", ">=", 3e6),
    "study_warm": Goal("<= 5 s", "value", "<=", 5.0),
    "study_first": Goal("<= 15 s", "value", "<=", 15.0),
    "study_memory": Goal("<= 200 MiB", "value", "<=", 200.0),
    "study_bytes": Goal("= pinned digests", "value", ">=", 1.0),
    "oracle": Goal("<= 0.5 s", "value", "<=", 0.5),
    "scaling": Goal("<= 1.0x proportional", "ratio", "<=", 1.0),
    "learner_work": Goal("<= 20 us", "value", "<=", 20.0),
    # online LSPI and pairplay.gym (issue 17)
    "lspi_sample": Goal("<= 50 us", "value", "<=", 50.0),
    "gym_vector": Goal(">= 0.5x the core (within 2x)", "ratio", ">=", 0.5),
    # bus
    "latency_p50": Goal("<= 2x paced raw", "ratio", "<=", 2.0),
    "latency_p99": Goal("<= 3x paced raw", "ratio", "<=", 3.0),
    "recorder": Goal(">= 0.9x raw, 0 lost", "ratio", ">=", 0.9),
    "rebuild": Goal(">= 0.8x raw", "ratio", ">=", 0.8),
    # view and robot
    "view_recording": Goal(">= 1,000 events/s", "value", ">=", 1000.0),
    "view_live": Goal(">= 0.8x bare", "ratio", ">=", 0.8),
    "robot_p50": Goal("< 2 ms", "value", "<=", 2000.0),
    "robot_p99": Goal("< 10 ms", "value", "<=", 10000.0),
}

MET, MISSED, CONTEXT = "met", "missed", "context"


def verdict(row: dict) -> str:
    """met / missed against the row's goal (a row may force missed, e.g. events lost); context if none."""
    key = row.get("goal")
    if key is None:
        return CONTEXT
    goal = GOALS[key]
    if row.get("failed"):
        return MISSED
    x = row.get(goal.on)
    if x is None:
        return MISSED
    return MET if (x >= goal.target if goal.op == ">=" else x <= goal.target) else MISSED


def goal_text(row: dict) -> str:
    key = row.get("goal")
    return "" if key is None else GOALS[key].text
