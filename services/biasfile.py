"""Where a combination's bias policy is written: never over a file it cannot prove its own.

Rule: the combiner writes a study's bias policy under a hidden name beside its place that carries the
request's id, `merged/.<name>.<request id>.combining` (`temp_name`); under the journal line's held
signals (replay/studydata.py `journaled_or_removed`) it is hard-linked onto `merged/<name>` (`os.link`:
refused if a file is there, never replaced), its BiasCombined appended, and the hidden name removed
(`put_in_place`). A process killed (SIGKILL: nothing of ours runs) at any point leaves a state that
proves itself: only the hidden name (before the link), or the two names of one file (the link made,
its line not written: the file is ours by its inode, and no BiasCombined names it), or the hidden name
beside a file its line names (killed after the line). The next combination removes exactly those
(`remove_leftovers`); any other file at its place is someone's (the researcher's own `pairplay combine
-o st/merged/...`, a copy, a combination of an older pairplay killed before its line) and is refused
in one line naming it (`check_free`), left as it is. Before, every combination removed a file at its
place first, "a killed combination's leftover", which deleted a researcher's file there without a word.
"""

from __future__ import annotations

import contextlib
import os
import re
import stat
from pathlib import Path

from pairplay.outputs import NO_HARD_LINKS, remove_dead_temps
from pairplay.replay.studydata import StudyDataError

SUFFIX = ".combining"
# .<name>.<request id: 12 hex>.combining, and pairplay/outputs.py's temporary of one (the combiner writes it
# through output_file: `.<that>.<pid>.<hex>.tmp`), which a SIGKILL while writing leaves
_LEFTOVER = re.compile(r"\.(?P<name>[^/]+\.policy\.json)\.[0-9a-f]{12}\.combining")
_WRITING = re.compile(r"\.(?P<combining>\.[^/]+\.combining)\.\d+\.[0-9a-f]{6}\.tmp")
REFUSED = "exists, not a combination of this study: move it away"


def temp_name(output: str, request_id: str) -> str:
    """The hidden name, relative to the study folder as `output`, the combiner writes `output` under."""
    out = Path(output)
    return out.with_name(f".{out.name}.{request_id}{SUFFIX}").as_posix()


def remove_leftovers(folder: Path, output: str, named: set[str]) -> None:
    """Remove what a killed combination left in `output`'s folder (module rule): each hidden name, and the
    file linked from one that no BiasCombined names (`named`: the journal's outputs). The study folder has one
    writer (pairplay/folderlock.py): a hidden name found here is no live combination's."""
    merged = folder / Path(output).parent
    if not merged.is_dir():
        return
    for path in merged.iterdir():
        if (m := _WRITING.fullmatch(path.name)) is not None:
            remove_dead_temps(merged / m["combining"])  # only a dead process's (it checks the pid)
            continue
        if (m := _LEFTOVER.fullmatch(path.name)) is None or not _regular(path):
            continue
        placed = merged / m["name"]
        if (Path(output).parent / m["name"]).as_posix() not in named and _regular(placed) \
                and os.path.samestat(placed.lstat(), path.lstat()):
            placed.unlink()  # its line never written: the file is this hidden one, not anybody's
        path.unlink(missing_ok=True)


def check_free(folder: Path, output: str, given: Path) -> None:
    """Refuse (naming it as the user gave the folder: `given`) a file at `output` that `remove_leftovers`
    did not prove ours: never removed nor replaced."""
    if os.path.lexists(folder / output):
        raise StudyDataError(REFUSED, given / output)


@contextlib.contextmanager
def put_in_place(folder: Path, temp: str, output: str, given: Path):
    """`temp` linked onto `output` (refused as `check_free` if a file appeared there meanwhile), then the
    block (the journal line), then `temp` removed; `output` is removed again if the block fails: no file at
    its place without its line (call it under the line's held signals: `journaled_or_removed`)."""
    tmp, out = folder / temp, folder / output
    try:
        os.link(tmp, out)
    except FileExistsError:
        raise StudyDataError(REFUSED, given / output) from None
    except OSError as err:  # a file system without hard links: checked, then renamed (a kill then proves nothing)
        if err.errno not in NO_HARD_LINKS:
            raise
        check_free(folder, output, given)
        os.rename(tmp, out)
    try:
        yield
    except BaseException:
        out.unlink(missing_ok=True)  # ours: linked (or renamed) just now, its line not written
        raise
    tmp.unlink(missing_ok=True)


def _regular(path: Path) -> bool:
    """A regular file itself, not a link to one (a symbolic link is nobody's leftover)."""
    try:
        return stat.S_ISREG(path.lstat().st_mode)
    except OSError:
        return False
