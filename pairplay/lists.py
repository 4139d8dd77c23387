"""A comma-separated list a user gives (`--personas a,b`, `--exclude p1,p2`, `--try 35,46`).

Rule: each item is stripped of spaces (`wasim, frances` is two names); an
empty item inside (`a,,b`, `a,b,`, ` , `) is a mistake, refused with a
ValueError naming the text and the item's place, never skipped: `--personas
a,,b` ran two personas without a word, where the user may have lost a name to a
typo. Blank text names nothing and is refused the same way: `bench --only ""`
measured nothing and exited 0 with an empty table, `counterfactual --policy ""`
quietly only fitted (a shell variable left empty is the usual cause). An option
whose list may be left out has no default text: it is None, not "". An item
given twice is a typo where each names one thing done once (`study --personas
blind,blind`, `bench --only core,core` measured core twice): `repeated` finds
it, for the caller to refuse with what is done once. Standard library only
(every layer imports this).
"""

from __future__ import annotations


def comma_items(text: str) -> list[str]:
    """The items of `text` (module rule); ValueError for an empty one or none."""
    if not text.strip():
        raise ValueError(f"{text!r} names nothing: give one or more, comma-separated")
    items = [item.strip() for item in text.split(",")]
    for place, item in enumerate(items, 1):
        if not item:
            raise ValueError(f"{text!r} has an empty item (item {place} of {len(items)}): remove the extra comma")
    return items


def repeated(items) -> str:
    """The first item given a second time in `items` ("" if none): `blind,blind` names blind twice."""
    seen: set = set()
    for item in items:
        if item in seen:
            return item
        seen.add(item)
    return ""
