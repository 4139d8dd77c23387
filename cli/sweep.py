"""`pairplay sweep GRID.toml`: the simulated study over a grid of settings x seeds (report/sweep.py).

Rule: the grid file says what is fixed ([study]), what is swept ([grid]) and
the seeds; results land in --out (default out/sweep-<grid name>): cells/ (one
JSON per finished cell), sweep.csv, cells.csv, figures/, sweep.md. Running
the same grid into the same folder resumes: finished cells are not computed
again. A folder that holds another grid's sweep, or files but no sweep, is
refused unless --force; an --out that is a file is refused before any work.
`--scheduler tcp://HOST:PORT` runs the cells on a Dask distributed cluster.
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
    out.mkdir(parents=True, exist_ok=True)
    copy.write_text(text)
    cells = grid.cells()
    done = len(finished_cells(out, grid))
    with tqdm(total=len(cells), initial=done, desc="sweep", unit="cell", disable=args.quiet,
              file=sys.stderr, dynamic_ncols=True) as bar:
        try:
            result = run_sweep(grid, out, scheduler=args.scheduler, workers=args.workers, progress=bar.update)
        except OSError as exc:
            print(f"pairplay sweep: {exc}", file=sys.stderr)
            return 1
    results = finished_cells(out, grid)
    write_sweep(out, grid, results, result)
    print(f"{result.cells} cells ({len(grid.settings())} settings x {len(grid.seeds)} seeds), {result.computed} "
          f"computed in {result.wall_s:.1f} s on {result.where}; {out / 'sweep.md'}")
    return 0
