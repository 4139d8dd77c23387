"""CSV cells a spreadsheet reads as text, never as a formula (CSV injection).

Rule (OWASP, "CSV Injection"): a text cell that a spreadsheet would take for a
formula, one starting with = + - @, a tab or a carriage return, is written with
a single quote before it (`'=HYPERLINK(...)`), which spreadsheets take as "this
is text" and do not show; a text cell that starts with a quote gets one more,
so the rule can be undone exactly: `value` removes one leading quote, and gives
back what was given to `cell` (the name a researcher typed, read back from the
key file, is the same name). A number, and text that is a plain number (`-3`,
`-0.5`: a spreadsheet makes it that number, nothing runs), is written as it
is. Every CSV of what people typed goes through here (the study's key file, its
tables and a participant's export, the human-world report's tables: names,
questionnaire answers) and every table of the simulated study, the sweep and the
counterfactual (a persona's name comes from a study file: `=cmd` is text too).
"""

from __future__ import annotations

import csv
from typing import IO, Iterable

TRIGGERS = ("=", "+", "-", "@", "\t", "\r")
QUOTE = "'"


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return text.strip() == text


def cell(v):
    """`v` as written to a CSV cell: text that would start a formula, or that starts with a quote,
    behind one more quote; anything else as it is."""
    if isinstance(v, str) and v.startswith(TRIGGERS + (QUOTE,)) and not _number(v):
        return QUOTE + v
    return v


def value(text: str) -> str:
    """What `cell` was given, from the text read back from a cell (one leading quote removed)."""
    return text[1:] if text.startswith(QUOTE) else text


class Writer:
    """csv.writer whose every cell goes through `cell`."""

    def __init__(self, f: IO[str], **kw):
        self._w = csv.writer(f, **kw)

    def writerow(self, row: Iterable):
        return self._w.writerow([cell(v) for v in row])

    def writerows(self, rows: Iterable[Iterable]) -> None:
        for row in rows:
            self.writerow(row)


def writer(f: IO[str], **kw) -> Writer:
    return Writer(f, **kw)
