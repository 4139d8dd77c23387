"""Copies of a study's participant data that a verb writes where their deletion would not reach on its own.

Rule: a verb that writes a file derived from a study folder's data (a game's recording or anything beside it, a
game's policy, a bias policy, the folder itself for the report) journals it in that study's journal
(`CopyWritten`: whose data, which verb, the absolute path, the SHA-256 of the bytes written), once the file is in
place, unless the deletion erases it by itself (a file named after the game beside its recording in recordings/,
the report's own files in report/, exports/<id>.zip). Whose data an input holds the journal says (`holders`):
the game whose recording or policy it is, the games a bias policy combined, everyone who played for the whole
folder. Before any work the verb checks that the journal can take the line (`Copies.check`): a copy its
participant's deletion would not know is never made; and a line that cannot be written once the file is in place
(the folder's lock not free when the wait ends, a signal in the wait) removes the file, said in the verb's one line
(`Copies.journal_each`). `pairplay participant delete` (replay/studydata.py
`delete_participant`) then erases each journaled copy that is still pairplay's own, unchanged file (the same path,
a regular file, the bytes it wrote) and names every other one: changed since, or gone from there.
A file made from a copy (a recording copied elsewhere by hand, an export unzipped) is beyond what pairplay can
know: the journal names the copies pairplay made, not the ones people make of them.
A verb whose output lands inside a study folder writes that folder, journaled or not (a view's .rrd or a
recover's copy beside a game's recording, a stale recorder's journal removed there, a report in report/; any
other output there is refused: cli/args.py `check_study_folders`): `Copies.check` takes the folder's
writer lock (pairplay/folderlock.py) for it, held until the verb ends (cli/main.py `release_held`; the
kernel's at the process's end), and refuses at once, in one line, beside another writer (a running
`protocol serve`): the .rrd of `view --recording R` was written into a served folder outside its lock.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterable

from pairplay import folderlock
from pairplay.errors import OutputError, UserError
from pairplay.outputs import is_owned
from pairplay.schemas import journal as j

from .studydata import JOURNAL, REPORT_OUTPUTS, StudyData, sha256_of
from .studyroot import study_root  # noqa: F401  (re-exported: the verbs' output checks)


def holders(data: StudyData, rel: str) -> set[str]:
    """The participants whose data the study's file `rel` (relative posix path; "" for the whole folder) holds,
    as its journal says: the game whose recording (or a file named after it beside it), journal or policy it is,
    the games of a bias policy's combination, an export's participant, everyone who played for the folder."""
    games = list(data.state.games.values())
    if rel == "":
        return {g.participant for g in games}
    found = set()
    for g in games:
        policy = g.ended.policy if g.ended is not None else ""
        if (rel == g.recording or rel == policy or rel.startswith(f"recordings/{g.session}.")
                or rel.startswith(f"policies/{g.session}.")):
            found.add(g.participant)
    by_policy = {g.ended.policy: g.participant for g in games if g.ended is not None and g.ended.policy}
    for combined in data.state.combinations:  # an earlier bias policy, kept for the record, too
        if rel == combined.output:
            found |= {by_policy[i] for i in combined.inputs if i in by_policy}
    parts = rel.split("/")
    if len(parts) == 2 and parts[0] == "exports" and parts[1].endswith(".zip"):
        found |= {parts[1][:-4]} & set(data.state.participants)
    return found


def erased_anyway(data: StudyData, pids: Iterable[str], verb: str, path: Path) -> bool:
    """Whether `participant delete` erases `path` by itself for each of `pids` (no line is needed): inside their
    study folder, a file named after one of their games in recordings/ (what a view or a recover writes beside
    it), their exports/<id>.zip, or a file of report/ the report wrote (its manifest lists it)."""
    path = Path(path).resolve()
    if not path.is_relative_to(data.folder):
        return False
    rel = path.relative_to(data.folder).as_posix()
    if verb == "report" and rel.startswith("report/") and is_owned(rel.removeprefix("report/"), REPORT_OUTPUTS):
        return True
    for pid in pids:
        sessions = [g.session for g in data.games_of(pid)]
        if not (rel == f"exports/{pid}.zip"
                or any(rel.startswith(f"recordings/{s}.") and "/" not in rel.removeprefix("recordings/")
                       for s in sessions)):
            return False
    return True


_HELD: list[int] = []  # the study folders' writer locks the verbs of this process hold (`Copies.check`)


def release_held() -> None:
    """Release every study folder's writer lock a verb of this process took through `Copies.check` (module rule):
    cli/main.py calls it when a verb ends, however it ends, so a verb run in-process (a test) leaves no lock."""
    while _HELD:
        folderlock.release(_HELD.pop())


class Copies:
    """What a run of `verb` reads of study folders (its `inputs`: files, or a study folder), to journal what it
    writes of them (module rule)."""

    def __init__(self, verb: str, inputs: Iterable[str | Path]):
        self.verb = verb
        self._held: dict[Path, int] = {}  # a study folder an output lands in, resolved -> its writer lock's descriptor
        self._studies: dict[Path, StudyData] = {}
        self._of: dict[Path, tuple[Path, frozenset[str]]] = {}  # an input, resolved -> (its study, whose data)
        self._typed: dict[Path, Path] = {}  # a study, resolved -> as the user's path reaches it (what a refusal names)
        for given in inputs:
            root = study_root(given)
            if root is None:
                continue
            self._typed.setdefault(root, next((p for p in (Path(given), *Path(given).parents)
                                               if p.resolve() == root), root))
            if root not in self._studies:  # one pairplay cannot read is said (StudyDataError): its copy unjournaled
                self._studies[root] = StudyData(self._typed[root])  # would be a copy the deletion never knew (named as typed)
            key = Path(given).resolve()
            rel = "" if key == root else key.relative_to(root).as_posix()
            pids = frozenset(holders(self._studies[root], rel))
            if pids:
                self._of[key] = (root, pids)

    def _lines(self, written: Iterable[Path], inputs: Iterable[str | Path] | None) -> dict[Path, set[str]]:
        """(study -> whose data) of the outputs `written` made of `inputs` (default: all of the verb's)."""
        keys = self._of if inputs is None else [Path(i).resolve() for i in inputs]
        studies: dict[Path, set[str]] = {}
        for key in keys:
            if key in self._of:
                root, pids = self._of[key]
                studies.setdefault(root, set()).update(pids)
        return {root: pids for root, pids in studies.items()
                if not all(erased_anyway(self._studies[root], pids, self.verb, w) for w in written)}

    def check(self, places: Iterable[str | Path]) -> None:
        """Before any work: OutputError, naming the journal, if a study whose data the verb would write to `places`
        (its output files or folders) cannot take the journal line of it (a copy the deletion would not know)."""
        for root in self._lines([Path(p) for p in places], None):
            journal = self._typed.get(root, root) / JOURNAL
            self._studies[root].check_folds()  # a journal a line more would not mend (a registration removed by hand)
            try:  # opened for appending, nothing written: what the append will need (a read-only mount refuses)
                os.close(os.open(root / JOURNAL, os.O_WRONLY | os.O_APPEND))
            except OSError as err:
                raise OutputError(f"cannot write there ({err.strerror or err}), and this `pairplay {self.verb}` "
                                  "writes a copy of its participants' data that their deletion must know: make the "
                                  "study's journal writable first", journal) from None
            try:  # its line will need the folder's writer lock (one writer per study folder): free now (or soon)?
                folderlock.release(folderlock.take(root, self.verb, folderlock.WAIT_S,
                                                   folderlock.say_waiting(self.verb, self._typed.get(root, root))))
            except folderlock.FolderBusy as busy:
                raise OutputError(f"another pairplay writes this study folder: {busy.holder or 'a process'}; this "
                                  f"`pairplay {self.verb}` writes a copy of its participants' data that their deletion "
                                  "must know, in its journal: run it when that one has finished",
                                  self._typed.get(root, root)) from None
        for place in places:  # an output inside a study folder writes that folder: its lock, held (module rule)
            root = study_root(place)
            if root is None or root in self._held:
                continue
            try:  # a short holder (a register, an export) is waited for, as by every writer of the folder
                fd = folderlock.take(root, self.verb, folderlock.WAIT_S,
                                     folderlock.say_waiting(self.verb, self._typed.get(root, root)))
            except folderlock.FolderBusy as busy:
                raise OutputError(f"another pairplay writes this study folder: {busy.holder or 'a process'}; this "
                                  f"`pairplay {self.verb}` would write into it ({place}): run it when that one has "
                                  "finished", self._typed.get(root, root)) from None
            if fd is not None:
                self._held[root] = fd
                _HELD.append(fd)

    def hand_over(self, folder: str | Path) -> int | None:
        """The writer lock this object holds of study folder `folder` (None if none), handed to the caller, who
        releases it (a StudyData made with it: `StudyData(..., held=)`); this object forgets it."""
        fd = self._held.pop(Path(folder).resolve(), None)
        if fd is not None:
            _HELD.remove(fd)
        return fd

    def journal(self, written: Iterable[str | Path], inputs: Iterable[str | Path] | None = None) -> None:
        """Journal each file of `written` (in place now) made of `inputs` (default: all of the verb's) in the
        studies whose data they hold (`journal_each`)."""
        self.journal_each([(written, inputs)])

    def journal_each(self, groups: Iterable[tuple[Iterable[str | Path], Iterable[str | Path] | None]],
                     data: StudyData | None = None) -> None:
        """Journal each file of each group (files in place now, the inputs they were made of: None for all of the
        verb's) in the studies whose data they hold, one CopyWritten each, but for the ones their deletion erases by
        itself. `data`: the study folder's StudyData the verb holds the writer lock with (report: its lines under the
        lock its output was written under), used for its folder. A line that cannot be written (the folder's lock
        not free when the wait for a short holder ends, a signal during that wait, a journal refused) leaves no copy
        its participants' deletion would not know: every file still waiting for its line is removed, and the error
        says so in its one line (OutputError; a signal's KeyboardInterrupt carries it in `said`, cli/main.py). Why:
        the outputs are renamed into place before their line, and `rebuild --out elsewhere` of a study's recording
        whose folder a register held past the wait left its policy there, unjournaled."""
        pending: list[tuple[Path, set[str], Path]] = []  # (study, whose data, file) for each line to write
        for written, inputs in groups:
            files = [Path(w) for w in written if Path(w).is_file()]
            for root, pids in self._lines(files, inputs).items():
                pending += [(root, pids, w) for w in files
                            if not erased_anyway(self._studies[root], pids, self.verb, w)]
        try:
            for root in dict.fromkeys(root for root, _, _ in pending):
                mine = data is not None and data.folder == root
                # the journal read afresh, under the folder's writer lock: the verb itself may have journaled
                # meanwhile (report's PolicyBuilt lines), and a copy read before would be refused as stale
                with contextlib.nullcontext(data) if mine else \
                        StudyData(self._typed[root], writer=self.verb, held=self.hand_over(root)) as study:
                    for line in [p for p in pending if p[0] == root]:
                        _, pids, w = line
                        if not erased_anyway(study, pids, self.verb, w):
                            study.append(j.CopyWritten(participants=sorted(pids), verb=self.verb,
                                                       path=str(w.resolve()), sha256=sha256_of(w)))
                        pending.remove(line)
        except BaseException as err:
            files = list(dict.fromkeys(w for _, _, w in pending))
            removed = _removed(files)
            if not removed or not isinstance(err, (UserError, OSError, KeyboardInterrupt)):
                raise  # (a bug of ours stays a traceback; its copies are removed all the same)
            said = (f"{removed}: each a copy of participants' data whose line could not be written in their study's "
                    "journal (their deletion would not know it)")
            if isinstance(err, KeyboardInterrupt):
                raise Interrupted(said) from None
            if isinstance(err, OSError):  # a full disk: said as every verb says it (`what (where)`)
                raise OutputError(f"{err.strerror or err}; {said}", err.filename or "") from None
            raise OutputError(f"{err.what}; {said}", err.where) from None


def _removed(files: list[Path]) -> str:
    """Remove `files` (outputs whose journal line could not be written): "removed A, B" as it says them."""
    gone, kept = [], []
    for f in files:
        try:
            f.unlink()
            gone.append(str(f))
        except FileNotFoundError:
            continue
        except OSError as err:  # said, never passed over: remove it by hand
            kept.append(f"{f} ({err.strerror or err}: remove it by hand)")
    return "; ".join(([f"removed {', '.join(gone)}"] if gone else []) + ([f"NOT removed {', '.join(kept)}"] if kept else []))


class Interrupted(KeyboardInterrupt):
    """A signal stopped the verb while it waited to journal its outputs: they were removed (`said`, its line's
    end after `interrupted (...)`, cli/main.py)."""

    def __init__(self, said: str):
        super().__init__(said)
        self.said = said
