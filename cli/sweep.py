"""`pairplay sweep GRID.toml`: the simulated study over a grid of settings x seeds (report/sweep.py).

Rule: the grid file says what is fixed ([study]), what is swept ([grid]) and
the seeds; results land in --out (default out/sweep-<grid name>): cells/ (one
JSON per finished cell), sweep.csv, cells.csv, figures/, sweep.md. Running
the same grid into the same folder resumes: finished cells are not computed
again; with every cell finished and the summary written, nothing is written
(sweep.md keeps the run that did the work) and one line says so; a summary file
missing or unreadable (a deleted figure, a junk sweep.md: report/sweep.py
`summary_to_write`) is written again, the others kept, and the line names it
(it said "nothing to do" and left them so). With --force the whole summary is
written again from the cells (a folder's --force replaces the files it writes
there); the cells are results and stay. "The same grid" is
the same grid as read (`same_grid`: its settings, axes, seeds and reuse), not the same
text: a comment changes nothing. A folder that holds another grid's sweep, or files but
no sweep, is refused unless --force (which removes the other grid's cell files, those
a sweep wrote: named by the id of the cell they hold, report/sweep.py `is_cell_file`; a
user's file named like one stays, and is said); an --out that is a file is refused before any work, and so
is a folder where one of its files goes (a cell's file, sweep.md, a figure) or a
file where one of its folders goes (cells/, figures/): named, one line, exit 2
(`check_sweep_places`; a folder is not the sweep's to remove, so it is not taken for
a damaged cell). The summary (sweep.csv, cells.csv, sweep.md, figures/) is written
whole each time; the figures an earlier run drew that this one does not draw
(a --force run of another grid) are removed (report/sweep.py `SWEEP_OUTPUTS`, its
manifest `.pairplay-sweep.manifest`), every other file stays.
`--scheduler tcp://HOST:PORT` runs the cells on a Dask distributed cluster (with
--workers, which would be ignored there, it is refused); an address where no Dask
scheduler answers in time is refused before anything is written
(report/sweep.py check_scheduler).
Interrupted (SIGINT/SIGTERM), or refused a write by the system while it runs
(a full disk, a folder removed under it: exit 2, as any OSError, README's exit
table; it was 1, and the line named no file), the cells finished stay and ONE
line says why and so; with none finished, nothing the sweep made stays
(`stopped`). A cell that fails (a fault, not a mistake: every setting is checked
before any work, its memory included, report/study.py) leaves the same: with no
cell finished, no grid.toml that would refuse the corrected grid's re-run.
Work lost with a worker process or the Dask cluster (pairplay.errors.WorkerLost: a
worker killed, the scheduler gone, a cell failed on a Dask worker) is the same
stop, its line saying what happened, exit 1 (README's exit table).
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from pathlib import Path

from pairplay.cli.args import output_folder, workers
from pairplay.cli.progress import bar as progress
from pairplay.errors import OptionError, OutputError, WorkerLost, escaped
from pairplay.outputs import check_folder, hold, write_text, written
from pairplay.report.sweep import (GridError, check_scheduler, check_sweep_memory, finished_cells, is_cell_file,
                                    read_grid, run_sweep, summary_files, summary_to_write,
                                    write_sweep)
from pairplay.numbers import counted

log = logging.getLogger("pairplay.sweep")


SUMMARY = ("sweep.csv", "cells.csv", "sweep.md")  # what write_sweep writes besides the figures, sweep.md last


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("grid", type=Path, help="the sweep's TOML file ([study], [grid], seeds, reuse)")
    p.add_argument("--out", type=output_folder, help="result folder (default out/sweep-<grid file name>)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler (tcp://host:port)")
    p.add_argument("--workers", type=workers,
                   help="local processes when no --scheduler (default 1; at most the CPUs this process may use)")
    p.add_argument("--force", action="store_true", help="replace a folder that holds another grid's sweep, or write into one that holds other files; "
                   "a finished sweep's summary is written again from its cells")


def stopped(out: Path, grid, made: list[Path], had_copy: bool, why: str) -> int | None:
    """The sweep stopped part way (a signal; the system refused a write: a full disk, a folder removed
    under it): the cells it finished stay (the same command resumes from them) and ONE line says
    `why` and so; with none finished, nothing it made stays (grid.toml, cells/, the folders it made:
    an interrupted sweep left an empty sweep folder) and None is returned: the caller says why its
    own way (cli/main.py's line for a signal)."""
    kept = len(finished_cells(out, grid))  # a cell being written is not among them: its temporary file is gone
    if kept:
        # the summary already in place (pairplay/outputs.py `written`: its folder renamed into place) is said: a
        # signal just after it said only that the cells were kept, for the same command to resume from them
        summed = Path(out) in written
        print(escaped(f"pairplay sweep: {why}; {kept} of {counted(len(grid.cells()), 'cell')} finished, kept in "
                      f"{out / 'cells'}" + (f"; its summary {out / 'sweep.md'} was written whole before it and kept; "
                                            "nothing more was written" if summed else
                                            ": the same command resumes from them")), file=sys.stderr)
        return 0
    if not had_copy:
        (out / "grid.toml").unlink(missing_ok=True)
    for folder in made:  # deepest first; one that holds something stays
        try:
            folder.rmdir()
        except FileNotFoundError:  # not made yet (stopped before cells/): the ones above may be
            continue
        except OSError:
            break
    return None


CELL_FILE = re.compile(r"[0-9a-f]{20}\.json")  # report/sweep.py Cell.id: a 10-byte blake2b digest, in hex


def same_grid(copy: Path, grid) -> bool:
    """Whether the sweep folder's `grid.toml` describes `grid` (the same settings, axes, seeds and reuse:
    a cell's id digests only its axes' values and seed, so a changed [study] setting is another grid too).
    Compared as read, not as text: a comment or a blank line made "the sweep of another grid" (exit 2),
    and with --force every finished cell was thrown away. A copy that no longer reads is another grid."""
    try:
        read = read_grid(copy)
    except (GridError, OSError, UnicodeDecodeError):
        return False
    # the axes' order too: a cell's id digests its setting in the grid's key order (reordered [grid] keys
    # were "the same grid", and every cell was computed again under new ids beside the old ones)
    return read == grid and list(read.axes) == list(grid.axes)


def check_sweep_places(out: Path, grid) -> None:
    """OutputError before any work if a file the sweep writes would land on a folder, or under a file where
    a folder goes (cells/, figures/): a cell file replaced by a folder was found only when the cell, computed,
    was stored ("is a folder; give a file name", exit 2, its work lost); now it is named with its setting and
    seed. A folder is never removed (it is not the sweep's), so it is refused, not taken for a damaged cell."""
    from pairplay.outputs import check_places, check_theirs
    from pairplay.report.sweep import MANIFEST, SWEEP_OUTPUTS, setting_label

    check_theirs(out, SWEEP_OUTPUTS, MANIFEST)  # another verb's file there (its manifest says) is not the sweep's

    for cell in grid.cells():
        place = out / "cells" / f"{cell.id}.json"
        if place.is_dir() and not place.is_symlink():
            raise OutputError(f"is a folder where cell {cell.id}'s result is written ({setting_label(cell.setting)}, "
                              f"seed {cell.seed}); a folder is never replaced, --force or not: remove or rename it",
                              place)
    check_places(out, SWEEP_OUTPUTS, files=["grid.toml", *SUMMARY, *(f"cells/{c.id}.json" for c in grid.cells())])


def run(args) -> int:
    if args.scheduler is not None and args.workers is not None:  # it was accepted and ignored (a trial)
        raise OptionError(f"--workers is the local processes run without --scheduler; on {args.scheduler} the "
                          "cluster's own workers run the cells: give one or the other", f"--workers {args.workers}")
    args.workers = args.workers or 1
    try:
        grid = read_grid(args.grid)
    except GridError as exc:
        print(f"pairplay sweep: {escaped(exc)}", file=sys.stderr)
        return 2
    if args.scheduler is None:  # before anything is written (run_sweep checks it again)
        check_sweep_memory(grid, args.workers)
    else:
        check_scheduler(args.scheduler)
    # out/sweep-<grid>, the grid's "sweep-" said once (examples/sweep-psi.toml wrote out/sweep-sweep-psi)
    out = args.out or Path("out") / f"sweep-{args.grid.stem.removeprefix('sweep-')}"
    hold(out, "sweep")  # one writer per output (pairplay/outputs.py): two sweeps of one folder computed each cell twice
    out = check_folder(out)
    copy = out / "grid.toml"
    text = args.grid.read_text()
    check_sweep_places(out, grid)  # before any work: a folder where a file goes is not one of ours to replace
    # (first: a folder at grid.toml was "the sweep of another grid", and with --force the OS's "Is a directory";
    # a pipe at sweep.md was "holds files but no sweep ... or --force", which --force would not have done)
    if out.is_dir() and any(out.iterdir()) and not copy.exists() and not args.force:  # not a sweep's folder
        raise OutputError("holds files but no sweep (no grid.toml); give another --out, or --force to write "
                          "the sweep's files there", out)
    other_grid = copy.exists() and not same_grid(copy, grid)
    if other_grid and not args.force:
        print(escaped(f"pairplay sweep: {out} holds the sweep of another grid ({copy}); give another --out or --force"),
              file=sys.stderr)
        return 2
    if other_grid:  # --force: the other grid's cells no longer count
        for old in sorted((out / "cells").glob("*.json")):
            # a cell file a sweep wrote (its name the id of the cell it holds); a folder of that name, or a
            # user's file, one named like a cell too (it was removed), stays, and is said
            if not CELL_FILE.fullmatch(old.name):
                continue
            if is_cell_file(old):
                old.unlink()
            else:
                log.warning("%s: named like a cell but not one a sweep wrote; left", old)
    made = [f for f in (out / "cells", out, *out.absolute().parents) if not f.exists()]
    had_copy = copy.exists()
    cells = grid.cells()
    done = len(finished_cells(out, grid))
    every = f"all {counted(len(cells), 'cell')} ({counted(len(grid.settings()), 'setting')} x {counted(len(grid.seeds), 'seed')})"
    redo = None  # a finished sweep resumed without --force: the summary files to write again, the others stay
    if had_copy and done == len(cells) and not args.force:
        # a resume with nothing to do rewrote sweep.md ("computed 0 in 0.0 s"), losing the run that did the work;
        # but a deleted figure or a junk sweep.md stayed so too ("nothing to do"): those are written again
        redo = summary_to_write(out, grid, finished_cells(out, grid))
        if not redo:
            print(escaped(f"nothing to do: {every} were finished; {out / 'sweep.md'} is as it was"))
            return 0
        if not any((out / f).exists() for f in redo) and len(redo) == len(summary_files(grid, finished_cells(out, grid))):
            redo = None  # no summary yet (a run stopped after its cells): written as any run's, its usual line
    try:
        out.mkdir(parents=True, exist_ok=True)
        if not had_copy or copy.read_text() != text:  # the same grid's copy stays as it is
            write_text(copy, text, force=True)
        with progress(len(cells), "sweep", "cell", args.quiet, initial=done) as bar:  # on a terminal only
            result = run_sweep(grid, out, scheduler=args.scheduler, workers=args.workers, progress=bar.update)
        results = finished_cells(out, grid)
        # --force: the whole summary written again from the cells (README: a folder's --force replaces the files
        # it writes there; it said "nothing to do" and left a junk sweep.md); the cells are results and stay
        keep = [] if redo is None else [f for f in summary_files(grid, results) if f not in redo]
        write_sweep(out, grid, results, result, keep=keep)  # a signal here: the cells stay, a rerun writes these again
    except KeyboardInterrupt:
        from pairplay.cli.main import interrupted_what
        if stopped(out, grid, made, had_copy, interrupted_what()) is None:
            raise  # nothing kept: cli/main.py says the usual line
        return 130  # the status is the signal's (cli/main.py)
    except OSError as err:  # the system refused a write while the sweep ran: exit 2, as before the work
        from pairplay.cli.main import os_error_line
        if stopped(out, grid, made, had_copy, os_error_line(err)) is None:
            raise  # nothing kept: cli/main.py says the line (README: exit 2, nothing written)
        return 2
    except WorkerLost as err:  # a worker process or the cluster lost (errors.py): the cells finished stay, exit 1
        if stopped(out, grid, made, had_copy, str(err)) is None:
            raise  # nothing kept: cli/main.py says the line (nothing it made stays)
        return 1
    except Exception:  # a cell failed (a fault, not the user's): with no cell finished, nothing it made stays,
        if not finished_cells(out, grid):  # so a corrected grid runs into the same --out (it was refused as
            stopped(out, grid, made, had_copy, "failed")  # "another grid's sweep"); finished cells stay to resume
        raise
    if redo is not None:
        print(escaped(f"{every} were finished; written again (missing or unreadable): {', '.join(redo)}; the rest is "
                      f"as it was; {out / 'sweep.md'}"))
        return 0
    print(f"{counted(result.cells, 'cell')} ({counted(len(grid.settings()), 'setting')} x {counted(len(grid.seeds), 'seed')}), {result.computed} "
          f"computed in {result.wall_s:.1f} s on {result.where}; {escaped(out / 'sweep.md')}")
    return 0
