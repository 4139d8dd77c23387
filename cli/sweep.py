"""`pairplay sweep GRID.toml`: the simulated study over a grid of settings x seeds (report/sweep.py).

Rule: the grid file says what is fixed ([study]), what is swept ([grid]) and
the seeds; results land in --out (default out/sweep-<grid name>): cells/ (one
JSON per finished cell), sweep.csv, cells.csv, figures/, sweep.md. Running
the same grid into the same folder resumes: finished cells are not computed
again. A folder that holds another grid's sweep, or files but no sweep, is
refused unless --force; an --out that is a file is refused before any work.
`--scheduler tcp://HOST:PORT` runs the cells on a Dask distributed cluster.
Interrupted (SIGINT/SIGTERM), the cells finished stay and the line says so;
with none finished, nothing the sweep made stays (`interrupted`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from pairplay.cli.args import count
from pairplay.errors import OutputError
from pairplay.outputs import check_folder
from pairplay.report.sweep import GridError, finished_cells, read_grid, run_sweep, write_sweep


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("grid", type=Path, help="the sweep's TOML file ([study], [grid], seeds, reuse)")
    p.add_argument("--out", type=Path, help="result folder (default out/sweep-<grid file name>)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler (tcp://host:port)")
    p.add_argument("--workers", type=count, default=1, help="local processes when no --scheduler (default 1)")
    p.add_argument("--force", action="store_true", help="replace a folder that holds another grid's sweep, or write into one that holds other files")


def interrupted(out: Path, grid, made: list[Path], had_copy: bool) -> int:
    """A signal stopped the sweep: the cells it finished stay (the same command resumes from them) and
    the line says so; with none finished, nothing it made stays (grid.toml, cells/, the folders it
    made): an interrupted sweep left an empty sweep folder. Re-raises when it has nothing to say
    (cli/main.py says the usual line)."""
    import os

    from pairplay.cli.main import interrupted_what
    for tmp in (out / "cells").glob(f".*.{os.getpid()}.tmp"):  # a cell being written (_write_json_atomic)
        tmp.unlink(missing_ok=True)
    kept = len(finished_cells(out, grid))
    if kept:
        print(f"pairplay sweep: {interrupted_what()}; {kept} of {len(grid.cells())} cells finished, kept in "
              f"{out / 'cells'}: the same command resumes from them", file=sys.stderr)
        return 130  # the status is the signal's (cli/main.py)
    if not had_copy:
        (out / "grid.toml").unlink(missing_ok=True)
    for folder in made:  # deepest first; one that holds something stays
        try:
            folder.rmdir()
        except OSError:
            break
    raise KeyboardInterrupt


def run(args) -> int:
    try:
        grid = read_grid(args.grid)
    except GridError as exc:
        print(f"pairplay sweep: {exc}", file=sys.stderr)
        return 2
    out = check_folder(args.out or Path("out") / f"sweep-{args.grid.stem}")
    copy = out / "grid.toml"
    text = args.grid.read_text()
    if out.is_dir() and any(out.iterdir()) and not copy.exists() and not args.force:  # not a sweep's folder
        raise OutputError("holds files but no sweep (no grid.toml); give another --out, or --force to write "
                          "the sweep's files there", out)
    if copy.exists() and copy.read_text() != text and not args.force:
        print(f"pairplay sweep: {out} holds the sweep of another grid ({copy}); give another --out or --force",
              file=sys.stderr)
        return 2
    if copy.exists() and copy.read_text() != text:  # --force: the other grid's cells no longer count
        for old in (out / "cells").glob("*.json"):
            old.unlink()
    made = [f for f in (out / "cells", out, *out.absolute().parents) if not f.exists()]
    had_copy = copy.exists()
    out.mkdir(parents=True, exist_ok=True)
    copy.write_text(text)
    cells = grid.cells()
    done = len(finished_cells(out, grid))
    try:
        with tqdm(total=len(cells), initial=done, desc="sweep", unit="cell", disable=args.quiet,
                  file=sys.stderr, dynamic_ncols=True) as bar:
            try:
                result = run_sweep(grid, out, scheduler=args.scheduler, workers=args.workers, progress=bar.update)
            except OSError as exc:
                print(f"pairplay sweep: {exc}", file=sys.stderr)
                return 1
        results = finished_cells(out, grid)
        write_sweep(out, grid, results, result)  # a signal here: the cells stay, a rerun writes these again
    except KeyboardInterrupt:
        return interrupted(out, grid, made, had_copy)
    print(f"{result.cells} cells ({len(grid.settings())} settings x {len(grid.seeds)} seeds), {result.computed} "
          f"computed in {result.wall_s:.1f} s on {result.where}; {out / 'sweep.md'}")
    return 0
