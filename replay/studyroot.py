"""Which people's study folder a path is in: the folder (`pairplay protocol init`'s) holding a study's journal and
its study file, that is the path or holds it.

Rule: this module stays light (pathlib and the two file names): every verb's output check (cli/args.py) and
`run_study` ask it, and the study's data layer (replay/studydata.py, ~44 modules) is not loaded for it: importing
it from `run_study` raised the simulated study's peak memory by ~5 MiB (191-192 -> 196-199 MiB; issue 16's goal is
200).
"""

from __future__ import annotations

from pathlib import Path

from pairplay.schemas.study import STUDY_FILE

JOURNAL = "journal.jsonl"  # a study folder's journal (replay/studydata.py: the event log of the study)


def study_root(path: str | Path) -> Path | None:
    """The study folder (`pairplay protocol init`: its journal and study file) that is `path` or holds it, resolved;
    None if there is none."""
    p = Path(path).resolve()
    for folder in (p, *p.parents):
        if (folder / JOURNAL).is_file() and (folder / STUDY_FILE).is_file():
            return folder
    return None
