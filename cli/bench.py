"""`pairplay bench`: every speed, latency and memory goal, each beside its raw reference, with a verdict.

Rule: every row is measured in this run next to a reference measured in the
same run (ratios are what travel between machines) and judged against its goal
in bench/goals.py (one table): met, missed, or context for a row without a
goal. `--runs N` repeats everything and gives each figure as a range, the
verdict on the median. `--quick` runs fewer and smaller measurements, each
timed after an untimed run of the same work as the full bench's are
(bench/core.py warm_then_best: it timed a cold first run, whose verdicts
said "missed" and "met" of the first call's costs), so its verdicts judge
the same goals, if on noisier figures. `--check` exits 1 when a goal is missed.
`--readme README.md` rewrites the README's benchmark table (between
`<!-- bench:start -->` and `<!-- bench:end -->`) from this run, with the
command that ran, the date, the machine and its load; it is checked before any
measuring (the section there, the folder writable), and refused with --only
or --quick: the README's table is a full run's, never part of one. Sources are modules with `bench_rows(quick) -> list[dict]`.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import json
import os
import platform
import sys
from pathlib import Path

from pairplay.bench.goals import MISSED, goal_text, verdict
from pairplay.cli.args import count, output_file
from pairplay.errors import InputError, OptionError, command_word
from pairplay.lists import comma_items, repeated
from pairplay.nearest import hinted
from pairplay.outputs import check_output, hold, write_text
from pairplay.numbers import counted

# name -> module providing bench_rows(quick)
SOURCES: dict[str, str] = {
    "core": "pairplay.bench.core",
    "lspi": "pairplay.bench.lspi",
    "bus": "pairplay.bench.bus",
    "view": "pairplay.bench.view",
    "robot": "pairplay.bench.robot",
    "lab": "pairplay.bench.lab",
}
README_START, README_END = "<!-- bench:start -->", "<!-- bench:end -->"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--only", default=",".join(SOURCES), help=f"comma-separated sources (default: {','.join(SOURCES)})")
    p.add_argument("--quick", action="store_true",
                   help="fewer, smaller runs, each timed warm as in the full bench (a smoke test, noisier numbers)")
    p.add_argument("--runs", type=count, default=1, help="measure everything N times; figures as ranges (default 1)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.add_argument("--check", action="store_true", help="exit 1 when a goal is missed")
    p.add_argument("--readme", type=output_file(), metavar="README",
                   help="rewrite the benchmark table of this README from this run")


def _fmt(value, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "steps/s":
        return f"{value / 1e6:.2f} M/s"
    if unit in ("events/s", "msg/s") or abs(value) >= 1000:
        return f"{value:,.0f} {unit}"
    if unit == "s":
        return f"{value:.2f} s"
    if unit in ("us", "ms"):
        return f"{value:.1f} {unit}"
    if unit == "MiB":
        return f"{value:.0f} MiB"
    if unit == "":
        return "yes" if value == 1.0 else ("no" if value == 0.0 else f"{value:.3g}")
    return f"{value:.3g} {unit}"


def _span(values: list, unit: str, fmt=_fmt) -> str:
    values = [v for v in values if v is not None]
    if not values:
        return "-"
    lo, hi = fmt(min(values), unit), fmt(max(values), unit)
    return lo if lo == hi else f"{lo} - {hi}"


def _ratio(x) -> str:
    return f"{x:.2f}x" if abs(x) >= 0.01 else f"{x:.2g}x"  # 1e-4 is not 0.00


def merge_runs(runs: list[list[dict]]) -> list[dict]:
    """One row per row of the first run: its values over the runs, the verdict on the median run."""
    merged = []
    for i, row in enumerate(runs[0]):
        same = [r[i] for r in runs if i < len(r)]
        out = dict(row)
        for key in ("value", "reference_value", "ratio"):
            out[key + "s"] = [r.get(key) for r in same]
        ordered = sorted(same, key=lambda r: (r.get("value") is None, r.get("value") or 0))
        median = ordered[len(ordered) // 2]
        out.update(value=median.get("value"), reference_value=median.get("reference_value"),
                   ratio=median.get("ratio"), failed=any(r.get("failed") for r in same))
        out["verdict"] = MISSED if any(r.get("failed") for r in same) else verdict(median)
        merged.append(out)
    return merged


def _cells(r: dict) -> list[str]:
    unit = r["unit"]
    ref_unit = r.get("reference_unit", unit)
    ratios = r.get("ratios", [r.get("ratio")])
    return [r["row"], _span(r.get("values", [r.get("value")]), unit), r.get("reference", ""),
            _span(r.get("reference_values", [r.get("reference_value")]), ref_unit),
            _span(ratios, "", lambda x, _u: _ratio(x)), goal_text(r), r.get("verdict") or verdict(r)]


HEAD = ["row", "measured", "reference (same run)", "reference value", "ratio", "goal", "verdict"]


def table(rows: list[dict]) -> str:
    body = [_cells(r) for r in rows]
    widths = [max(len(str(x[i])) for x in [HEAD] + body) for i in range(len(HEAD))]
    line = lambda cells: " | ".join(str(c).ljust(w) for c, w in zip(cells, widths))  # noqa: E731
    return "\n".join([line(HEAD), "-+-".join("-" * w for w in widths)] + [line(b) for b in body])


def _measured(name: str, quick: bool) -> list[dict]:
    """A source's rows; a source that needs a library this install lacks (an optional one: playwright
    is only in the [test] extra) gives one row saying so, and the other sources are still measured
    (before, `bench --quick` on the quick start's install ended in a traceback after 70 s, no row printed)."""
    try:
        return importlib.import_module(SOURCES[name]).bench_rows(quick=quick)
    except ModuleNotFoundError as err:
        library = (err.name or "").split(".")[0]
        if library in ("", "pairplay"):  # our own module missing is a fault, not an install
            raise
        return [{"row": f"{name}: not measured, {library} is not installed", "value": None, "unit": ""}]


def machine() -> str:
    """What ran the bench: CPU model, cores, Python, OS."""
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{model or platform.processor() or platform.machine()}, {counted(os.cpu_count(), 'core')}, "
            f"Python {platform.python_version()}, {platform.system()} {platform.release()}")


def markdown(rows: list[dict], runs: int, started: datetime.datetime, loads: list[tuple[float, float, float]],
             command: str = "") -> str:
    """The README's table; `command` (default: `readme_command(runs, "README.md")`) is the one that ran: the
    header said `--readme README.md` whatever file was written."""
    lo = min(l[0] for l in loads)
    hi = max(l[0] for l in loads)
    lines = [f"Generated by `{command or readme_command(runs, Path('README.md'))}` on "
             f"{started:%Y-%m-%d %H:%M} UTC; {machine()}; 1-minute load average {lo:.1f}-{hi:.1f} during the run "
             f"(a shared machine: every figure is a range over {counted(runs, 'run')}, the verdict "
             "is on the median run).", "",
             "| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    lines += ["| " + " | ".join(c.replace("|", "/") for c in _cells(r)) + " |" for r in rows]
    return "\n".join(lines)


def readme_command(runs: int, path: Path) -> str:
    """The command that writes the README's table, as the header names it."""
    return f"pairplay bench --runs {runs} --readme {command_word(path)}"


def _readme_parts(path: Path) -> tuple[str, str]:
    """(what stands before the table and its start marker, what stands from its end marker on), or
    InputError naming `path`: not a file, not UTF-8 text, no start marker before an end marker."""
    if not path.is_file():
        raise InputError("no README there" if not path.exists() else "is not a file", path)
    try:
        old = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text: not a README", path) from None
    start = old.find(README_START)
    end = old.find(README_END, start + len(README_START)) if start >= 0 else -1
    if end < 0:
        raise InputError(f"has no {README_START} ... {README_END} section to rewrite", path)
    return old[:start + len(README_START)], old[end:]


def check_readme(path: Path, names: list[str], quick: bool) -> None:
    """Before any measuring (it took minutes, then refused a README without the markers): the README can
    be rewritten (its section there, its folder writable: pairplay.outputs), and the run is one whose
    table may replace the README's: every source, full size. `--only lspi --readme` replaced the whole
    35-row table with LSPI's 4 rows, and `--quick` figures would stand as the README's."""
    partial = [opt for opt, given in (("--only", set(names) != set(SOURCES)), ("--quick", quick)) if given]
    if partial:
        raise OptionError(f"--readme rewrites the README's whole table from a full run; {' and '.join(partial)} "
                          "would replace it with part of one: give --readme without them", "--readme")
    check_output(path, force=True)  # first: a pipe there is refused, not read (reading one waits for a writer)
    _readme_parts(path)


def write_readme(path: Path, text: str) -> None:
    """Replace the README's table between the bench markers (pairplay.outputs: a temporary file renamed
    when complete, removed on any error; a full disk's OSError names `path`: it named nothing and left
    README.md.tmp). The file is read again: it may have changed while the bench ran."""
    head, tail = _readme_parts(path)
    write_text(path, f"{head}\n{text}\n{tail}", force=True)


def run(args) -> int:
    try:
        names = comma_items(args.only)
    except ValueError as exc:  # `a,,b` measured a and b without a word
        print(f"pairplay bench: {exc} (--only)", file=sys.stderr)
        return 2
    if twice := repeated(names):  # measured twice, its rows twice in the table (trial34 G)
        print(f"pairplay bench: {args.only!r} names {twice} twice: each source is measured once (--only)",
              file=sys.stderr)
        return 2
    unknown = [n for n in names if n not in SOURCES]
    if unknown:
        said = ", ".join(hinted(n, SOURCES) for n in unknown)  # `cor`: the one meant (pairplay/nearest.py)
        print(f"pairplay bench: unknown source{'s' * (len(unknown) > 1)} {said}; known: {', '.join(SOURCES)} (--only)",
              file=sys.stderr)
        return 2
    if args.readme is not None:
        hold(args.readme, "bench")  # one writer per output (pairplay/outputs.py): two benches rewrite one README
        check_readme(args.readme, names, args.quick)
    started = datetime.datetime.now(datetime.timezone.utc)
    loads = [os.getloadavg()]
    runs = []
    for i in range(args.runs):
        rows = []
        for name in names:
            if not getattr(args, "quiet", False):  # progress: -q keeps the table and the missed goals, its results (cli/main.py)
                print(f"measuring {name} (run {i + 1} of {args.runs}) ...", file=sys.stderr, flush=True)
            rows += _measured(name, args.quick)
            loads.append(os.getloadavg())
        runs.append(rows)
    rows = merge_runs(runs)
    print(json.dumps(rows, indent=1) if args.json else table(rows))
    if not getattr(args, "quiet", False):
        print(f"load average (1 min) {min(l[0] for l in loads):.1f}-{max(l[0] for l in loads):.1f}", file=sys.stderr)
    if args.readme is not None:
        write_readme(args.readme, markdown(rows, args.runs, started, loads, readme_command(args.runs, args.readme)))
    missed = [r["row"] for r in rows if r["verdict"] == MISSED]
    if missed:
        print(f"{len(missed)} goal(s) missed: " + "; ".join(missed), file=sys.stderr)
    return 1 if args.check and missed else 0
