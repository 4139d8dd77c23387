"""`pairplay bench`: speed and latency goals, each beside its raw reference.

Rule: every row is measured in this run next to a reference measured in the
same run (ratios are what travel between machines); goals are printed, never
asserted. Sources are modules with `bench_rows(quick) -> list[dict]`.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys

# name -> module providing bench_rows(quick)
SOURCES: dict[str, str] = {
    "core": "pairplay.bench.core",
    "lspi": "pairplay.bench.lspi",
    "bus": "pairplay.bench.bus",
    "view": "pairplay.bench.view",
    "robot": "pairplay.bench.robot",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--only", default=",".join(SOURCES), help=f"comma-separated sources (default: {','.join(SOURCES)})")
    p.add_argument("--quick", action="store_true", help="smaller runs (a smoke test, noisier numbers)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")


def _fmt(value, unit: str) -> str:
    if value is None:
        return "-"
    if unit in ("steps/s", "events/s", "msg/s") or abs(value) >= 1000:
        return f"{value:,.0f} {unit}"
    if unit == "s":
        return f"{value:.2f} s"
    if unit in ("us", "ms"):
        return f"{value:.1f} {unit}"
    return f"{value:.3g} {unit}"


def _ratio(ratio) -> str:
    if ratio is None:
        return "-"
    return f"{ratio:.2f}x" if abs(ratio) >= 0.01 else f"{ratio:.2g}x"  # 1e-4 is not 0.00


def table(rows: list[dict]) -> str:
    head = ["row", "value", "reference", "reference value", "ratio", "goal"]
    body = [[r["row"], _fmt(r["value"], r["unit"]), r.get("reference", ""),
             _fmt(r.get("reference_value"), r.get("reference_unit", r["unit"])),
             _ratio(r.get("ratio")), r.get("goal", "")] for r in rows]
    widths = [max(len(str(x[i])) for x in [head] + body) for i in range(len(head))]
    line = lambda cells: " | ".join(str(c).ljust(w) for c, w in zip(cells, widths))  # noqa: E731
    return "\n".join([line(head), "-+-".join("-" * w for w in widths)] + [line(b) for b in body])


def run(args) -> int:
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in SOURCES]
    if unknown:
        print(f"pairplay bench: unknown source(s) {unknown}; known: {', '.join(SOURCES)}", file=sys.stderr)
        return 2
    rows = []
    for name in names:
        print(f"measuring {name} ...", file=sys.stderr, flush=True)
        rows += importlib.import_module(SOURCES[name]).bench_rows(quick=args.quick)
    print(json.dumps(rows, indent=1) if args.json else table(rows))
    return 0
