"""The known word a user's unknown one resembles: the "did you mean" of every refusal of a name.

Rule: one measure for all of them (difflib's ratio, at least 0.75: a letter left out, doubled or
swapped in a word of five or more, `ashly` for `ashley`, `rouns` for `rounds`), the closest one known
or none. A word that differs from a known one only in its digits is another one of a numbered kind, not a
misspelling of it (`phase3` beside phase1 and phase2, `thesis-ch8` beside thesis-ch7): no hint, the list
of what there is says it; the refusal then says it (`(did you mean `rounds`?)`) and, with none, what is known. Used by
the study and sweep files' keys and values, every JSON file's keys, a public function's argument names (pairplay/arguments.py), a name from a fixed list (a persona,
a name of a comma list: `bench --only`, `run --wait-for`, `combine --exclude`, `counterfactual --policy`: `hinted`), a
verb's options and an option's choices (cli/main.py Parser);
before, each place called difflib with its own copy of the cutoff, and a misspelt persona had no hint.
Standard library only (every layer imports this).
"""

from __future__ import annotations

import difflib
import re
from typing import Iterable

CUTOFF = 0.75


def nearest(word: str, known: Iterable[str]) -> str:
    """The word of `known` that `word` resembles most (module rule), "" if none does."""
    near = difflib.get_close_matches(word, list(known), n=1, cutoff=CUTOFF)
    if not near or _digitless(near[0]) == _digitless(word):
        return ""
    return near[0]


def hinted(word: str, known: Iterable[str]) -> str:
    """`word` as a refusal says it: quoted, with the known word it resembles (`'ashly' (did you mean 'ashley'?)`)."""
    near = nearest(word, known)
    return f"{word!r} (did you mean {near!r}?)" if near else repr(word)


def _digitless(word: str) -> str:
    return re.sub(r"\d+", "#", word)
