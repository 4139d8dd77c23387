"""Every file pairplay writes for a user goes through here: no clobber, atomic, one writer per output.

Rule: an existing output is never replaced unless the caller says `force`
(the verbs' `--force`); a write goes to a temporary file beside its target
(same folder, so the rename is atomic) and is renamed onto the target only
when it is complete; on any error, or Ctrl-C, the temporary file (and any
folder made for it) is removed and the target is untouched. Without `force` the final step is a hard link
(`os.link` fails if the target appeared meanwhile), so even a file created
while we worked is not replaced. A folder of outputs (a study's report) is
built in a temporary folder and renamed as a whole; written with `force` into
a folder that holds an earlier run, it also removes the earlier run's files
that this run did not write (a study's sections of a persona no longer in it
looked current), and never another file: which are the writer's own its
patterns (`owned`) and its manifest (`manifest`: the files it wrote there, run
after run) say together, so a forced run removes an earlier run's stale outputs
and never the user's file of such a name (one it leaves is said); a folder
written before the manifests keeps all it holds. A file another writer's
manifest there lists is that writer's: never replaced, `force` or not
(`check_theirs`: `study` and `report` both write report.md), and so is a file a manifest in a folder above
lists (a people's study folder's: `rebuild --out STUDY/policies` is refused a game's policy). One that holds other files too
(`among_others`: `rebuild --out`, a sweep's summary beside its cells) gets its
files moved in together the same way. A folder
standing where a file is written, or a file where a folder is needed, is refused
(`check_places`, from `check_output_folder` before the work): a folder is never
replaced or removed, `force` or not; nor is anything but a regular file (a device, a pipe, a socket, a
symbolic link: `check_kind`, `force` or not, its line offering no --force). A verb holds its output's writer
lock (`hold`) from before its checks to its end: a second writer of it is refused at once. Refusals are
`OutputError`s naming the path, raised before any work where the caller
checks first (`check_output`, `check_outputs`, `check_folder`: each makes the
folders it needs and a file there, then removes them, so a place the system
refuses is refused before the work, not after it). A refusal by
the system while writing (a full disk, a folder one may not write in) is an
OSError naming the user's path, never our temporary one (`_named_for_user`):
`study --out /proc/x` named /proc/.x.<pid>.<hex>.tmp, and a full disk's
"No space left on device" named no file at all.

The one exception is a live recording (services/recorder.py): it streams to
its final name so that a crash loses at most its last 0.1 s (`pairplay
recover` completes it), and it never replaces a file (`free_path`); while its recorder
lives it is locked (pairplay/livelock.py) and `check_output` refuses it, `force` or not.

Each output, once renamed into place, is noted in `written` in the same step (pairplay/signals.py `held`), so
that a verb a signal stops after that says what it wrote whole (cli/main.py), not "nothing more was written":
a Ctrl-C as `rebuild` or `study` went on after its folder was in place said that of a folder it had written.
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import glob
import hashlib
import json
import logging
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path
from typing import IO, Iterable, Iterator

from pairplay import folderlock, signals, testpause
from pairplay.errors import OutputError
from pairplay.livelock import LIVE, is_live
from pairplay.numbers import counted
from pairplay.schemas.nesting import json_loads
from pairplay.schemas.repeated import refuse_repeated

FORCE_FIX = "--force replaces it"  # shown only by a verb that has --force (errors.UserError `fix`)


written: list[Path] = []  # every output renamed into place by this process, in order (module rule; cli/main.py)


# -- one writer per output -----------------------------------------------------------------------------------
# Two `pairplay sweep sweep-psi.toml` on the same output 1 s apart both computed every cell (rc 0 and 0): the work
# done twice, each writing over the other's cells. A verb writing an output (a folder of them: sweep, study,
# counterfactual, report, rebuild --out; a file: view --out, combine -o, recover -o) holds that output's writer
# lock from before its checks until it ends (`hold`; the kernel drops it however the process ends), and a second
# writer of the same output is refused at once, in one line naming the holder: its work would be done twice, and
# the outputs it meets half written by the other. The lock file is kept outside the output, in a folder of the
# user's in the system's temporary folder (`LOCKS`), named after the output's absolute path (symbolic links
# resolved: two names of one folder are one output), so that no output holds a file of it and a folder not yet
# made can be locked. flock, as pairplay/folderlock.py says why; a people's study folder keeps its own lock there.
# The lock file is removed as its holder lets go, while it holds it (`release_held`; folderlock `release`), and a
# writer checks, once it holds a lock, that the name is still its file's, else opens it again (folderlock
# `take_file`): so the folder holds the outputs written now and those a killed writer left (until their next
# writer), where it kept one file per output ever written (docs/architecture.md, "Output locks").

_HELD_OUTPUTS: dict[Path, tuple[int, Path]] = {}  # output (resolved) -> (its lock's descriptor, its lock file)


def _locks_folder() -> Path:
    return Path(tempfile.gettempdir()) / f"pairplay-outputs-{os.getuid()}"


def hold(path: str | Path, verb: str) -> None:
    """Take the writer lock of the output `path` (a file or a folder) for `verb` (`pairplay VERB`) until the
    process ends or `release_held`; OutputError "busy" naming the holder if another process holds it. Taken
    again by the same process: nothing to do. A system without the locks' folder or locks: the verb goes on
    unlocked (as a study folder's lock, pairplay/folderlock.py)."""
    key = Path(path).resolve()
    if key in _HELD_OUTPUTS:
        return
    folder = _locks_folder()
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
    except OSError:
        return
    name = hashlib.sha256(os.fsencode(key)).hexdigest()[:32] + ".lock"
    try:
        fd = folderlock.take_file(folder / name, f"pairplay {verb}")
    except folderlock.FolderBusy as busy:
        who = busy.holder or "another pairplay (it has not said which yet)"
        raise OutputError(f"busy: {who} writes it; wait for it to end, or give another output", path) from None
    if fd is not None:
        _HELD_OUTPUTS[key] = (fd, folder / name)


def release_held() -> None:
    """Release every output's writer lock this process holds (cli/main.py, when a verb ends however it ends: a
    verb run in-process, a test's, leaves none)."""
    while _HELD_OUTPUTS:
        fd, lock = _HELD_OUTPUTS.popitem()[1]
        folderlock.release(fd, remove=lock)  # its lock file goes with it: the folder holds the outputs held now


def _existing_ancestor(path: Path) -> Path:
    """The nearest existing folder above `path`, named as the user gave it (relative stays relative:
    a refusal named /tmp/work/afile where the user typed afile/x)."""
    p = path.parent
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_parent(path: Path, probe: bool = True) -> None:
    parent = _existing_ancestor(path)
    if not parent.is_dir():
        raise OutputError("cannot write there: a file stands where a folder is needed", parent)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError("cannot write there: the folder is read-only", parent)
    if probe:
        _try_writing(path.parent)


def _try_writing(folder: Path) -> None:
    """Make `folder` (and the folders above it that are missing) and a file in it, then remove them
    all: OutputError naming `folder` if the system refuses. os.access alone says yes where a write
    fails (root in /proc: `session --out /proc/x` opened its bus and printed its first line, then
    failed), so a verb's check before its work is a real one; nothing stays."""
    created = _missing_folders(folder)
    try:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            probe = _temp_name(folder / "probe")
            probe.touch(exist_ok=False)
            probe.unlink()
        except OSError as err:
            raise OutputError(f"cannot write there: {_refusal(err, folder)}", folder) from None
    finally:
        _remove_empty(created)


def _refusal(err: OSError, folder: Path) -> str:
    """The system's refusal to make `folder` or a file in it, in words true of it. ENOENT where the folder
    above exists is a file system that makes no new entries (/proc, /sys): its own "No such file or
    directory" read as if /proc did not exist (a new user's trial: `combine -o /proc/m.json`)."""
    said = err.strerror or str(err)
    if err.errno != errno.ENOENT:
        return said
    above = folder if folder.is_dir() else _existing_ancestor(folder)
    if not above.is_dir():
        return said
    there = "the folder exists" if above == folder else f"{above} exists"
    return f"its file system makes no new files or folders there (it answered {said!r}, though {there})"


def _file_id(path: Path) -> tuple[int, int] | None:
    """The file `path` is (device, inode: the same whatever name, link or `..` reaches it), None if none."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


# What may stand where a file is written: nothing, or a regular file (replaced with `force`). Anything else is
# refused in one line naming what it is, `force` or not (`check_kind`): as root, `combine -o mynull --force` (a
# character device), `-o myfifo --force` and `view --out mynull --force` replaced the device or pipe with a regular
# file, and `combine -o /dev/null` said "exists; --force replaces it", inviting the system's /dev/null to go. A
# symbolic link is refused too: replacing it loses the link, writing through it writes wherever it points.
_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device", stat.S_IFIFO: "a named pipe (FIFO)",
          stat.S_IFSOCK: "a socket", stat.S_IFLNK: "a symbolic link"}


def special_kind(path: str | Path, follow: bool = False) -> str | None:
    """What stands at `path` (not followed if a link, unless `follow`: a file appended to, not replaced) when it
    is neither nothing, a regular file nor a folder: "a character device", "a named pipe (FIFO)", "a symbolic
    link (to X)"...; None otherwise."""
    try:
        mode = (os.stat if follow else os.lstat)(path).st_mode
    except OSError:  # nothing there (or not to be told: the write itself says)
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = _KINDS.get(stat.S_IFMT(mode), "not a regular file")
    if stat.S_ISLNK(mode):
        kind += f" (to {os.readlink(path)})"
    return kind


def check_kind(path: str | Path) -> None:
    """OutputError if `path` holds something a written file may not replace (`special_kind`), `force` or not;
    its line gives no `--force` hint, since --force would not."""
    kind = special_kind(path)
    if kind is not None:
        raise OutputError(f"is {kind}, not a regular file; pairplay replaces only a regular file, --force or not: "
                          "give another name", path)


def check_output(path: str | Path, force: bool = False, inputs: Iterable[str | Path] = ()) -> Path:
    """`path` as a Path if a file may be written there; OutputError otherwise.

    Refused: a folder, a device, pipe, socket or link (`check_kind`, `force` or not), one of the verb's `inputs`
    (by any name, `force` or not: `combine a.json b.json -o a.json --force` replaced its own input, silently),
    an existing file (unless `force`), a place whose nearest existing folder is a file or read-only."""
    path = Path(path)
    check_kind(path)
    if path.is_dir():
        raise OutputError("is a folder; give a file name", path)
    me = _file_id(path)
    if me is not None and any(_file_id(Path(i)) == me for i in inputs):
        raise OutputError("is one of the inputs; an input is never replaced, --force or not: give another output",
                          path)
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputError("exists", path, fix=FORCE_FIX, option="--force")
    if is_live(path):  # --force or not: a live recording (or its journal) is never replaced
        raise OutputError(f"{LIVE}; not replaced", path)
    _check_parent(path)
    return path


def check_outputs(paths: Iterable[str | Path], force: bool = False, inputs: Iterable[str | Path] = ()) -> list[Path]:
    """check_output for each, and no two the same file (outputs of different inputs never collide)."""
    seen: dict[Path, Path] = {}
    out = []
    inputs = list(inputs)
    for p in paths:
        p = check_output(p, force, inputs)
        key = p.absolute()
        if key in seen:
            raise OutputError("two outputs would be written to the same file", p)
        seen[key] = p
        out.append(p)
    return out


def check_folder(path: str | Path) -> Path:
    """`path` as a Path if it is, or can become, a folder we write into; OutputError otherwise. A symbolic link
    to a folder is that folder (returned resolved): the output's own rename lands on the folder it names, where
    one onto the link failed with a bare "Not a directory" naming a temporary folder, and a link that names no
    folder (dangling, or to a file) is refused naming what it is (it said "cannot write there: File exists")."""
    path = Path(path)
    if path.is_symlink():
        if not path.is_dir():
            raise OutputError(f"is {special_kind(path)}, which names no folder: give a folder (or make the one "
                              "it names)", path)
        path = Path(os.path.realpath(path))
    if path.exists() and not path.is_dir():
        raise OutputError(f"is {special_kind(path) or 'a file'}, not a folder", path)
    if path.is_dir():
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError("cannot write there: the folder is read-only", path)
        _try_writing(path)
    else:
        _check_parent(path, probe=False)
        _try_writing(path)
    return path


def _temp_name(path: Path) -> Path:
    """A temporary name beside `path`: `.<name>.<pid>.<random>.tmp`; those a killed process left (SIGKILL:
    nothing of ours runs) are removed by the next writer of the same `path` (`remove_dead_temps`)."""
    remove_dead_temps(path)
    return path.with_name(f".{path.name}.{os.getpid()}.{os.urandom(3).hex()}.tmp")


_TEMP_HEX = re.compile(r"[0-9a-f]{6}")  # _temp_name's os.urandom(3).hex()


def remove_dead_temps(path: Path) -> None:
    """Remove what `_temp_name` made beside `path` for a process that is gone (a `rebuild --force` killed
    with SIGKILL left `.<name>.<pid>.<hex>.tmp` folders of up to ~1 MB for good); a live process's, or one
    whose process cannot be told, stays. Best effort: a temporary that cannot be removed is left."""
    for old in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
        parts = old.name[len(path.name) + 2:].split(".")  # <pid>, <hex>, "tmp"
        if (len(parts) != 3 or not parts[0].isdigit() or not _TEMP_HEX.fullmatch(parts[1])
                or int(parts[0]) == os.getpid() or _alive(int(parts[0]))):  # only a name _temp_name gives
            continue
        with contextlib.suppress(OSError):
            if old.is_dir() and not old.is_symlink():
                shutil.rmtree(old)
            else:
                old.unlink()


def _alive(pid: int) -> bool:
    """Whether process `pid` exists (or cannot be told: not ours to judge)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def _missing_folders(path: Path) -> list[Path]:
    """The folders of `path` (itself included) that do not exist yet, deepest first."""
    missing = []
    p = path.absolute()
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Undo _mkdir after a failure: the folders it created, if still empty (nothing written)."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            break


def _mkdir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError("cannot write there: a file stands where a folder is needed", path) from None
    except PermissionError:
        raise OutputError("cannot write there: the folder is read-only", _existing_ancestor(path / "x")) from None


# what os.link raises on a file system without hard links (then: checked, then renamed)
NO_HARD_LINKS = (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK)


def _commit(tmp: Path, path: Path, force: bool) -> None:
    if force:
        check_kind(path)  # again: a pipe or device made there while we worked is not replaced either
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        tmp.unlink(missing_ok=True)
        raise OutputError("appeared while it was being written; not replaced", path) from None
    except OSError as err:  # a file system without hard links: check, then rename
        if err.errno not in NO_HARD_LINKS:
            raise
        if path.exists():
            tmp.unlink(missing_ok=True)
            raise OutputError("appeared while it was being written; not replaced", path) from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def _named_for_user(err: OSError, tmp: Path, path: Path) -> OSError:
    """`err` naming `path` (or the file under it) where it named the temporary `tmp` or nothing."""
    name = err.filename
    try:
        inside = name is not None and Path(os.fsdecode(name)).absolute().is_relative_to(tmp.absolute())
    except (TypeError, ValueError):
        inside = False
    if name is not None and not inside:
        return err
    target = path / Path(os.fsdecode(name)).absolute().relative_to(tmp.absolute()) if inside else path
    named = OSError(err.errno, err.strerror or str(err), str(target))
    named.__cause__ = err
    return named


@contextlib.contextmanager
def output_path(path: str | Path, force: bool = False) -> Iterator[Path]:
    """A temporary path beside `path` to write to (for writers that take a name: matplotlib,
    rerun's FileSink, MCAP); it becomes `path` when the block ends without error."""
    path = check_output(path, force)
    created = _missing_folders(path.parent)
    _mkdir(path.parent)
    tmp = _temp_name(path)
    done = False
    try:
        try:
            yield tmp
            if not tmp.exists():
                raise OutputError("nothing was written", path)
            with signals.held():  # in place and noted, or neither (module rule)
                _commit(tmp, path, force)
                written.append(path)
        except OSError as err:
            raise _named_for_user(err, tmp, path) from err
        done = True
    finally:
        tmp.unlink(missing_ok=True)
        if not done:
            _remove_empty(created)


@contextlib.contextmanager
def output_file(path: str | Path, mode: str = "wb", force: bool = False, **open_kw) -> Iterator[IO]:
    """`open(path, mode)` for writing, through a temporary file (see output_path)."""
    if not mode.startswith("w"):
        raise ValueError(f"output_file writes a new file; mode {mode!r}")
    with output_path(path, force) as tmp:
        with open(tmp, mode, **open_kw) as f:
            yield f


def write_bytes(path: str | Path, data: bytes, force: bool = False) -> Path:
    with output_file(path, "wb", force) as f:
        f.write(data)
    return Path(path)


def write_text(path: str | Path, text: str, force: bool = False) -> Path:
    with output_file(path, "w", force, encoding="utf-8") as f:
        f.write(text)
    return Path(path)


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not any(path.iterdir())


def check_output_folder(path: str | Path, force: bool = False, owned: tuple[str, ...] = (),
                        manifest: str = "") -> Path:
    """`path` as a Path if output_folder may fill it: a folder that is, or can become, ours and
    holds no files unless `force`, where none of the writer's own files (`owned`) would land on a
    folder or under a file (`check_places`), nor replace a file another verb wrote there (`check_theirs`;
    `manifest`: the writer's own); OutputError otherwise (call it before the work)."""
    path = check_folder(path)
    check_theirs(path, owned, manifest)
    check_places(path, owned)  # first: --force would not help (a folder, a pipe where a file goes), so no hint of it
    if path.exists() and not _is_empty_dir(path) and not force:
        raise OutputError("exists and is not empty", path, fix="--force replaces the files written there",
                          option="--force")
    return path


def check_theirs(path: Path, owned: tuple[str, ...], manifest: str) -> None:
    """OutputError, before any work, if a file the writer may write in the folder `path` (one its patterns
    `owned` name) is listed by another writer's manifest there (`.pairplay-<verb>.manifest`), or by a manifest
    in a folder above it (a people's study folder's, `.pairplay-protocol.manifest`, lists its recordings,
    policies and tables: `rebuild --out STUDY/policies --force` replaced a game's policy): that verb's output,
    not this one's to replace, `--force` or not (`study --out R --force` replaced the report.md and merged.png a
    `pairplay report --out R` wrote, silently: the two write those names). Checked for every writer of a folder
    (study, report, counterfactual, rebuild, sweep), whatever names they share now."""
    if not owned or not path.is_dir():
        return
    here = path.absolute()
    for folder in (here, *here.parents):
        for other in sorted(folder.glob(manifest_name("*"))):
            if (folder == here and other.name == manifest) or not other.is_file():
                continue
            before, after = manifest_name("*").split("*")
            verb = other.name.removeprefix(before).removesuffix(after)
            for listed in read_manifest(other):
                file = folder / listed
                if not file.is_relative_to(here):
                    continue
                rel = file.relative_to(here).as_posix()
                if is_owned(rel, owned) and file.is_file():
                    where = other.name if folder == here else os.path.relpath(other, here)
                    raise OutputError(f"was written by `pairplay {verb}` (its manifest {where} lists it); "
                                      "another verb's output is not replaced, --force or not: give another folder",
                                      path / rel)


def check_places(path: Path, owned: tuple[str, ...] = (), files: Iterable[str] = ()) -> None:
    """OutputError, before any work, if a file the writer may write under the folder `path` (one `owned`
    names, or one of `files`: relative posix paths) would land where a folder stands, or under a file
    standing where a folder is needed (`study --out D --force` with D/report.md a folder ran the whole
    study, then failed moving it in). A folder is never removed or replaced: it is not one of ours."""
    if not path.is_dir():
        return
    for rel in files:
        target = path / rel
        check_kind(target)
        if target.is_dir() and not target.is_symlink():
            raise OutputError("is a folder where a file is written; a folder is never replaced, --force or not: "
                              "remove or rename it", target)
        _check_above(path, target)
    for pattern in owned:
        parts = pattern.split("/")
        literal = 0  # the folders above the pattern's first wildcard must be folders
        while literal < len(parts) - 1 and not any(c in parts[literal] for c in "*?["):
            literal += 1
        _check_above(path, path.joinpath(*parts[:literal], "x"))
        for old in sorted(path.glob(pattern)):
            if is_owned(old.relative_to(path).as_posix(), (pattern,)):
                check_kind(old)
            if old.is_dir() and not old.is_symlink() and is_owned(old.relative_to(path).as_posix(), (pattern,)):
                raise OutputError("is a folder where a file is written; a folder is never replaced, --force or "
                                  "not: remove or rename it", old)


def _check_above(path: Path, target: Path) -> None:
    """OutputError if a folder between `path` and `target` stands there as a file."""
    for above in reversed(target.relative_to(path).parents[:-1] if target != path else ()):
        if (path / above).exists() and not (path / above).is_dir():
            raise OutputError("is a file where a folder is needed; it is never replaced, --force or not: "
                              "remove or rename it", path / above)


@contextlib.contextmanager
def output_folder(path: str | Path, force: bool = False, owned: tuple[str, ...] = (),
                  among_others: bool = False, manifest: str = "") -> Iterator[Path]:
    """A new temporary folder beside `path` to fill; when the block ends without error it
    becomes `path`. A non-empty `path` is refused unless `force`; with `force` each file
    written replaces its namesake there. A writer that names its own outputs (`owned`: patterns of
    relative paths, `policies/*/game-*.json`, see `is_owned`) keeps a `manifest` (a file of that
    name in `path`, `write_manifest`: the files it wrote there, by every run into it; required with
    `owned`): the patterns alone cannot tell its files from the user's (`study --force` removed a
    user's notes named like a game file, `report --force` a figure of their own named `users-*.png`).
    With `force` a file there that `owned` names, the earlier manifest lists and this run did not
    write is removed (an earlier run's, stale beside this one's), with the folders that leaves empty;
    every other file stays, and one of them that `owned` names is said in one warning (`_say_left`:
    the user's, or one an older pairplay wrote before the manifests, to remove by hand if stale).
    SIGINT/SIGTERM wait while the files are moved
    in (pairplay/signals.py `held`): the folder is the earlier run's or this one's, never half of each.
    `among_others`: `path` may hold other files (`rebuild --out`: the caller checked its own
    outputs with check_outputs); a file written replaces its namesake only with `force`, and
    without it a namesake that appeared meanwhile refuses the whole (nothing moved in) (`rebuild
    REC1 --out D --force` after `rebuild REC1 REC2 --out D` removes REC2's policy from D; a user's
    x.policy.json there stays). A file would land on a folder, or under a file,
    in `path`: OutputError before anything is moved in (`check_places` says it before the work). A `path`
    without a name of its own (`.`, `..`: `rebuild --out .` was a traceback) is filled from a temporary
    folder inside it, file by file the same way."""
    if owned and not manifest:  # the patterns alone cannot tell the writer's files from the user's
        raise ValueError("output_folder: a writer that names its own files (owned) keeps a manifest of them")
    path = check_folder(path) if among_others else check_output_folder(path, force, owned, manifest)
    check_theirs(path, owned, manifest)  # again (among_others too): another verb may have written there meanwhile
    earlier = read_manifest(path / manifest, owned) if manifest else None
    created = _missing_folders(path.parent)
    _mkdir(path.parent)
    nameless = path.name in ("", ".", "..")  # no folder beside it can be named after it, nor renamed onto it
    tmp = _temp_name(path / "staging") if nameless else _temp_name(path)
    try:
        tmp.mkdir()
    except OSError as err:
        raise _named_for_user(err, tmp, path) from err
    done = False
    left: list[str] = []
    try:
        try:
            yield tmp
        except OSError as err:
            raise _named_for_user(err, tmp, path) from err
        if manifest:  # what this run wrote, and what an earlier run wrote that stays (none of it with force)
            ours = sorted(src.relative_to(tmp).as_posix() for src in tmp.rglob("*") if src.is_file())
            kept = [] if force else [f for f in (earlier or ()) if f not in ours and (path / f).is_file()]
            write_manifest(tmp / manifest, sorted({*ours, *kept}))
        if not nameless and (not path.exists() or _is_empty_dir(path)):
            with signals.held():  # in place and noted, or neither (module rule)
                os.replace(tmp, path)  # rename(2) onto an empty folder is atomic
                written.append(path)
                done = True
        else:
            # file by file into the earlier run's folder: a Ctrl-C in this loop (milliseconds) left the folder
            # half this run's and half the earlier one's, "nothing more was written" (a new user's trial), so
            # the loop finishes first and the signal is delivered after it
            with signals.held():
                files = [(src, path / src.relative_to(tmp)) for src in sorted(tmp.rglob("*")) if src.is_file()]
                if not force:
                    for _, dst in files:
                        if dst.name != manifest and (dst.exists() or dst.is_symlink()):
                            raise OutputError("appeared while it was being written; not replaced", dst)
                # all or nothing: a folder where a file goes, or a file where a folder goes, refuses the whole
                check_places(path, files=[dst.relative_to(path).as_posix() for _, dst in files])
                moved = set()
                for src, dst in files:
                    _mkdir(dst.parent)
                    os.replace(src, dst)
                    moved.add(dst.relative_to(path).as_posix())
                # only the files an earlier run of this writer wrote (its manifest) are stale; one named
                # like them that no run listed (the user's, or an older pairplay's) stays, and is said
                left = _remove_stale(path, moved, owned, listed=set(earlier or ()) if force else set())
                written.append(path)
                done = True  # before the held signal is delivered
            if left and force:
                _say_left(path, left, manifest)
        testpause.pause("folder-written")
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            _remove_empty(created)


def is_owned(relative: str, owned: tuple[str, ...]) -> bool:
    """Whether the posix path `relative` (inside an output folder) is named by one of the patterns
    `owned`, part by part (fnmatch: `merged/*.json` names merged/a.json, not merged/x/a.json)."""
    parts = relative.split("/")
    return any(len(parts) == len(p.split("/")) and all(map(fnmatch.fnmatchcase, parts, p.split("/")))
               for p in owned)


def _remove_stale(path: Path, written: set[str], owned: tuple[str, ...], listed: set[str]) -> list[str]:
    """Remove the files under `path` that `owned` names, this run did not write and `listed` (an earlier
    run's manifest) lists (output_folder); return those `owned` names that this run did not write and
    no manifest lists, which stay (sorted relative paths)."""
    left: list[str] = []
    if not owned:
        return left
    for old in sorted(path.rglob("*"), reverse=True):  # deepest first: a folder after its files
        rel = old.relative_to(path).as_posix()
        if not old.is_file() or old.is_symlink() or rel in written or not is_owned(rel, owned):
            continue
        if rel not in listed:
            left.append(rel)
            continue
        old.unlink()
        with contextlib.suppress(OSError):  # a folder left holding something else stays
            parent = old.parent
            while parent != path and not any(parent.iterdir()):
                parent.rmdir()
                parent = parent.parent
    return sorted(left)


def remove_written(path: Path, owned: tuple[str, ...], manifest: str) -> list[str]:
    """Remove from the output folder `path` what its writer wrote there (the files its manifest lists that
    its patterns `owned` name, and the manifest), with the folders that leaves empty, `path` included;
    return the files left (sorted relative paths: the user's notes, figures; a folder written before the
    manifests keeps all it holds). `participant delete` removed the whole report/ folder, the researcher's
    notes.md in it included: a derived output goes, a file of the user's never does."""
    if not path.is_dir():
        return []
    listed = set(read_manifest(path / manifest))
    _remove_stale(path, set(), owned, listed)
    (path / manifest).unlink(missing_ok=True)
    left = sorted(f.relative_to(path).as_posix() for f in path.rglob("*") if f.is_file() or f.is_symlink())
    for folder in sorted((f for f in path.rglob("*") if f.is_dir() and not f.is_symlink()), reverse=True):
        with contextlib.suppress(OSError):
            folder.rmdir()  # only an empty one goes
    with contextlib.suppress(OSError):
        path.rmdir()
    return left


def _say_left(path: Path, left: list[str], manifest: str) -> None:
    """One line (a warning) naming the files a forced run left in `path` though its patterns name them:
    no manifest there listed them, so they are the user's, or an older pairplay's written before the
    manifests; a stale one of those is the user's to remove by hand."""
    shown = ", ".join(left[:5]) + (f" and {len(left) - 5} more" if len(left) > 5 else "")
    logging.getLogger("pairplay.outputs").warning(
        "%s: left %s named like this verb's outputs that it did not write (not in %s: the user's, or an older "
        "pairplay's; remove any that are stale by hand): %s", path, counted(len(left), "file"), manifest, shown)


MANIFEST_FORMAT = "pairplay.outputs/1"


def manifest_name(writer: str) -> str:
    """The name of `writer`'s manifest in its output folder (`.pairplay-study.manifest`): one per writer, so
    one verb's forced run never takes another's files, written into the same folder, for its own."""
    return f".pairplay-{writer}.manifest"


def read_manifest(path: Path, owned: tuple[str, ...] = ()) -> list[str]:
    """The relative paths an output folder's manifest (`write_manifest`) lists; [] if there is none, or
    if it is not one (a user's file of that name, a damaged one: logged, and nothing is taken from it).
    An entry outside the folder (`../x`, `/etc/x`, empty) or, given the writer's `owned` patterns, one they do
    not name (`notes.txt`) is ignored, and the ignored entries are named in one warning (a forged manifest
    removed nothing outside, but said nothing either). A listed path is only ever removed if `owned` names
    it too (`_remove_stale`), so a forged manifest cannot name a file outside them."""
    if not path.is_file():
        return []
    try:
        text = path.read_text(encoding="utf-8")
        refuse_repeated(text)  # a second "files" would silently win
        data = json_loads(text)
        if data.get("format") != MANIFEST_FORMAT or not all(isinstance(f, str) for f in data["files"]):
            raise ValueError("not a pairplay manifest")
    except (OSError, ValueError, AttributeError, KeyError, TypeError) as err:
        logging.getLogger("pairplay.outputs").warning("%s: not read (%s); no earlier output is removed", path, err)
        return []
    files, ignored = [], []
    for f in data["files"]:
        inside = f and not f.startswith(("/", "\\")) and ".." not in re.split(r"[/\\]", f) and ":" not in f[:2]
        (files if inside and (not owned or is_owned(f, owned)) else ignored).append(f)
    if ignored:
        shown = ", ".join(map(repr, ignored[:5])) + (f" and {len(ignored) - 5} more" if len(ignored) > 5 else "")
        logging.getLogger("pairplay.outputs").warning(
            "%s: ignored %s outside the folder or not named like this verb's outputs (nothing of theirs is removed): "
            "%s", path, counted(len(ignored), "entry", "entries"), shown)
    return files


def write_manifest(path: Path, files: list[str]) -> None:
    """An output folder's manifest: the files its writer wrote there (output_folder `manifest`), written whole
    or not at all (a study folder's is written again beside its journal at each of its lines)."""
    doc = {"format": MANIFEST_FORMAT, "written_by": "pairplay", "files": files,
           "note": "the files pairplay wrote in this folder; a --force run removes those it does not write again"}
    tmp = _temp_name(path)
    try:
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


# `session --force` (services/recorder.py set_aside): an earlier recording and its journal renamed so, kept
# beside the new one until the new one holds a session; one left there was set aside by a run cut short
REPLACED = ".replaced"


def set_aside_of(path: str | Path) -> list[Path]:
    """What a `session --force` cut short before it settled left set aside beside the recording `path`:
    the `<name>.replaced` files of its recordings and journals (the earlier session's only copy)."""
    import glob

    path = Path(path)
    if not path.parent.is_dir():
        return []
    return sorted(path.parent.glob(f"{glob.escape(path.stem)}.*{REPLACED}"))
