"""Run the test suite against the LOWEST versions pyproject.toml declares (the dependency policy's check).

Rule: every direct dependency (the `dependencies` and the `test` extra) is pinned
to the lower bound of its range (`name>=X` becomes `name==X` in a constraints
file: uv's "lowest-direct" resolution, done with plain pip); what those need
comes at whatever version pip resolves. A fresh venv on the lowest declared
Python (python3.11) installs the project with those constraints and runs
`python -m pytest` (the README's command; extra pytest arguments pass through)
on a copy of the committed tree (`git archive HEAD`: edits under way in the
work tree do not leak into the run). The venv and the copy live in a temporary
folder removed at the end (--keep keeps it).

    python tools/lowest_deps.py [--python python3.11] [--keep] [-- PYTEST ARGS]

Exit status: pytest's, or 2 when the lowest versions cannot be installed
(a lower bound that no longer installs is itself a finding: raise it).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LOWER = re.compile(r"^\s*([A-Za-z0-9_.\-]+)\s*(?:\[[^\]]*\])?\s*(.*)$")


def lower_bounds(pyproject: Path = ROOT / "pyproject.toml", extras: tuple[str, ...] = ("test",)) -> dict[str, str]:
    """{distribution: lowest declared version} of every direct dependency with a `>=` bound."""
    project = tomllib.loads(pyproject.read_text())["project"]
    specs = list(project["dependencies"])
    for extra in extras:
        specs += project.get("optional-dependencies", {}).get(extra, [])
    out = {}
    for spec in specs:
        name, rest = LOWER.match(spec.split(";")[0]).groups()
        for clause in rest.split(","):
            clause = clause.strip()
            if clause.startswith(">="):
                out[name] = clause[2:].strip()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--python", default="python3.11", help="interpreter of the venv (the lowest declared Python)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary venv and print where it is")
    ap.add_argument("pytest_args", nargs="*", help="extra arguments for pytest (after --)")
    args = ap.parse_args(argv)
    bounds = lower_bounds()
    tmp = Path(tempfile.mkdtemp(prefix="pairplay-lowest-"))
    started = time.monotonic()
    try:
        constraints = tmp / "constraints.txt"
        constraints.write_text("".join(f"{name}=={version}\n" for name, version in sorted(bounds.items())))
        print("pinned to the lower bounds:", ", ".join(f"{n}=={v}" for n, v in sorted(bounds.items())), flush=True)
        src = tmp / "src"
        src.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", "HEAD"], check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
        venv = tmp / "venv"
        subprocess.run([args.python, "-m", "venv", str(venv)], check=True)
        py = venv / "bin" / "python"
        install = subprocess.run([str(py), "-m", "pip", "install", "-q", "-q", "-c", str(constraints), "-e", f"{src}[test]"])
        if install.returncode != 0:
            print("the lowest declared versions do not install together (see pip's message above)", file=sys.stderr)
            return 2
        subprocess.run([str(py), "-m", "pip", "list", "--format=freeze"], check=False)
        installed_at = time.monotonic()
        test = subprocess.run([str(py), "-m", "pytest", *args.pytest_args], cwd=src)
        done = time.monotonic()
        print(f"lowest-deps: install {installed_at - started:.0f} s, tests {done - installed_at:.0f} s, "
              f"pytest exit {test.returncode}", flush=True)
        return test.returncode
    finally:
        if args.keep:
            print(f"venv kept at {tmp / 'venv'}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
