"""`pairplay report STUDY_FOLDER`: the human-world report of a study with people (report/human.py).

Rule: reads only the study folder; writes <folder>/report (or --out) through a
temporary folder renamed when complete, never over an existing report without
--force; prints where report.md is.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

from pairplay.replay.studydata import StudyDataError
from pairplay.schemas.policy import PolicyFileError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=Path, help="the study folder (pairplay protocol init)")
    p.add_argument("--out", type=Path, help="report folder (default <folder>/report)")
    p.add_argument("--reference", type=Path,
                   help="a policy file drawn beside each bias policy (figure 7.5: the virtual Blind+Deaf merge, "
                        "out/study/merged/blind+deaf.json of `pairplay study`)")
    p.add_argument("--force", action="store_true", help="replace an existing report")


def run(args) -> int:
    from pairplay.report.human import human_report
    out = (args.out or args.folder / "report").resolve()
    if out.exists() and not args.force:
        print(f"pairplay report: {out} exists (use --force to replace it)", file=sys.stderr)
        return 2
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        report = human_report(args.folder, tmp, args.reference)
    except (StudyDataError, PolicyFileError, ValueError, OSError) as err:
        shutil.rmtree(tmp, ignore_errors=True)
        print(f"pairplay report: {err}", file=sys.stderr)
        return 2
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    print(f"{len(report.games)} valid games of {len({g.participant for g in report.games})} participants"
          + (f"; left out: {', '.join(report.excluded)}" if report.excluded else ""))
    print(f"report: {out / 'report.md'}")
    return 0
