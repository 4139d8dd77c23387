"""A time a person gives as text (`2026-11-20T14:30`): ns since the epoch, or one line saying what is wrong.

Rule: one parser for every door a time comes in by (`protocol consent --given-at`, the console's Record
consent), so both take the same texts and refuse the same ones in the same words: ISO 8601
(`2026-11-20T14:30`, `2026-11-20`, `...Z`, `...+01:00`); one without a zone is this computer's local time, as a
person reads a clock. The future and the like are the caller's to refuse (it knows what the time is of).
Standard library only (every layer imports this).
"""

from __future__ import annotations

import datetime

EXAMPLES = "2026-11-20T14:30, 2026-11-20T13:30Z"


def iso_time_ns(text: str) -> int:
    """`text` as ns since the epoch (module rule); ValueError saying why not, the text echoed."""
    try:
        when = datetime.datetime.fromisoformat(text.strip())
    except ValueError:
        raise ValueError(f"not an ISO time ({EXAMPLES}): {text!r}") from None
    try:
        return int(when.astimezone().timestamp() * 1_000_000_000)
    except (OverflowError, OSError, ValueError):  # a year 1 or 9999 time the clock cannot hold
        raise ValueError(f"a time out of range: {text!r}") from None
