"""Did the robot get the suggestions: a session's RobotActed counted, in one line.

Rule: every suggestion the robot bridge took has one RobotActed (schemas/robot.py);
`delivery_line` counts those with something to send ("nothing", the do-nothing
action, has not) as delivered (done, sent, aborted, stopped), unconfirmed (unacknowledged, in-flight:
written, not confirmed), superseded (a newer suggestion came first: normal when
the participant is quick) and not delivered (failed: also a stale one the robot
could not have taken, unreachable, which the driver records failed, not
superseded), naming the commonest reason a suggestion failed. A session whose robot could not be reached said
so only under -v, and its summary said nothing: this line is what `session`,
`lab` and `protocol serve/pilot` print after a game with a robot. `troubled` says
whether it reports a real failure (failed, unacknowledged): `protocol serve` logs
only that as a warning, the normal line (superseded, in flight at the end) as info.
"""

from __future__ import annotations

from collections import Counter
from typing import Iterable

from pairplay.schemas.robot import RobotActed
from pairplay.numbers import counted

DELIVERED = ("done", "sent", "aborted", "stopped")
UNCONFIRMED = ("unacknowledged", "in-flight")
# what went wrong with the robot, not the session's normal course: a suggestion superseded (the participant was
# quicker) or in flight when the session ended is normal; one failed, or never confirmed by a robot that was
# asked (its reply did not come, its connection died), is not
TROUBLE = ("failed", "unacknowledged")


def troubled(others: Counter) -> bool:
    """Whether `delivery_counts`'s outcome counts hold a real failure (TROUBLE): a warning, not the usual line."""
    return any(others[o] for o in TROUBLE)


def delivery_counts(acted: Iterable[RobotActed]) -> tuple[int, int, Counter, str, str]:
    """(suggestions, delivered, outcome -> count of the others, the commonest failure's error, the backend)."""
    total, delivered, others, errors, backend = 0, 0, Counter(), Counter(), ""
    for a in acted:
        if a.outcome == "nothing":
            continue
        total += 1
        backend = backend or a.backend
        if a.outcome in DELIVERED:
            delivered += 1
        else:
            others[a.outcome] += 1
            if a.outcome == "failed" and a.error:
                errors[a.error] += 1
    return total, delivered, others, (errors.most_common(1)[0][0] if errors else ""), backend


def delivery_line(acted: Iterable[RobotActed]) -> str:
    """`robot <backend>: D of N suggestions delivered[; ...]`, or "" for a session without a robot."""
    total, delivered, others, error, backend = delivery_counts(acted)
    if not total:
        return ""
    line = f"robot {backend}: {delivered} of {counted(total, 'suggestion')} delivered"
    parts = [f"{others[o]} {o}" for o in ("failed", *UNCONFIRMED, "superseded") if others[o]]
    if parts:
        line += f" ({', '.join(parts)})"
    if error:
        line += f"; failed: {error}"
    return line

