"""`pairplay report STUDY_FOLDER`: the human-world report of a study with people (report/human.py).

Rule: reads only the study folder (first building the policy of any completed game journaled
without one, from its recording: replay/studydata.py build_missing_policies); writes <folder>/report (or --out) through a
temporary folder renamed when complete (pairplay/outputs.py `output_folder`,
as every verb's folder of outputs), never into a folder that holds files
without --force; with --force each file of the report replaces its namesake
and the folder's other files stay (before, --force removed the whole --out
folder first, a user's files in it included, and a failure left the temporary
folder behind). Prints where report.md is.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pairplay.cli.args import option_policy, output_folder
from pairplay.errors import escaped
from pairplay.numbers import counted
from pairplay.replay.studydata import StudyDataError, not_a_study_folder
from pairplay.schemas.policy import PolicyFileError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=Path, help="the study folder (pairplay protocol init)")
    p.add_argument("--out", type=output_folder, help="report folder (default <folder>/report)")
    p.add_argument("--reference", type=Path,
                   help="a policy file drawn beside each bias policy (figure 7.5: the virtual Blind+Deaf merge, "
                        "out/study/merged/blind+deaf.json of `pairplay study`)")
    p.add_argument("--force", action="store_true", help="replace the files of an existing report")
    p.add_argument("--include-scripted", action="store_true",
                   help="pool the games scripted personas played (protocol pilot, serve --pilot) with people's "
                        "(default: listed and left out; a folder no person played in is reported as a rehearsal)")


def run(args) -> int:
    from pairplay.cli.protocol import built_missing_policies
    from pairplay.outputs import check_output_folder, hold, output_folder
    from pairplay.replay.studydata import StudyData
    from pairplay.report.human import HUMAN_MANIFEST, HUMAN_OUTPUTS, human_report

    from pairplay.replay.copies import Copies

    if args.reference is not None:  # a wrong --reference refused before the work (it waited for the games)
        option_policy(args.reference, f"--reference {args.reference}")
    if args.folder.is_file():  # it said "cannot write there" of its report/ (a file where a folder is needed)
        print(f"pairplay report: {not_a_study_folder(args.folder)}", file=sys.stderr)
        return 2
    hold(args.out or args.folder / "report", "report")  # one writer per output (pairplay/outputs.py)
    out = check_output_folder(args.out or args.folder / "report", args.force, HUMAN_OUTPUTS,
                              HUMAN_MANIFEST)  # before any work
    copies = Copies("report", [args.folder])  # a report beyond report/ is a copy their deletion must know
    copies.check([out])
    try:
        # a completed game a signal left without its policy gets it now, from its recording
        # it journals policies and writes report/: a writer, the folder's lock held to the end (one writer per
        # study folder: pairplay/folderlock.py; beside a running server, its console writes the report)
        # (the lock is taken by copies.check already when `out` is in the folder: handed over, not taken twice)
        with StudyData(args.folder, writer="report", held=copies.hand_over(args.folder)) as data:
            built_missing_policies(data, "report")
            with output_folder(out, args.force, owned=HUMAN_OUTPUTS, manifest=HUMAN_MANIFEST) as tmp:
                report = human_report(args.folder, tmp, args.reference, include_scripted=args.include_scripted)
                written = [out / f.relative_to(tmp) for f in sorted(tmp.rglob("*")) if f.is_file()]
            # journaled under the lock it was written under: no other writer between (a line that cannot be written
            # removes the copy, replay/copies.py journal_each; the lock retaken after it once let a wait time out)
            copies.journal_each([(written, None)], data=data)
    except (StudyDataError, PolicyFileError, ValueError) as err:
        print(f"pairplay report: {err}", file=sys.stderr)
        return 2
    if report.rehearsal:
        print(f"a rehearsal: {counted(len(report.games), 'scripted game')}, no person played")
    print(f"{counted(len(report.games), 'valid game')} of {counted(len({g.participant for g in report.games}), 'participant')}"
          + (f"; left out: {escaped(', '.join(report.excluded))}" if report.excluded else "")
          # counted, but said: their bias policy was made with a game marked invalid since (replay/biases.py)
          + (f"; played on a bias policy made with a game marked invalid since: {escaped(', '.join(flawed))}" if
             (flawed := [f"{g.session} ({g.bias})" for g in report.games if g.bias_flawed]) else ""))
    if report.read_whole:  # a damaged input, on stderr, -q or not (cli/main.py `warn`: -q hid it with the summary)
        print(f"pairplay report: read whole from a damaged file: {escaped(', '.join(report.read_whole))}", file=sys.stderr)
    if report.unreadable:  # cited from the journal; the files themselves cannot be read now (stderr, as above)
        # a report missing what it cites is not a whole report: exit 1, "done, and the answer is no" (README's exit
        # status table), the partial report written, as `replay --verify` of a partial recording (it was exit 0)
        print(f"pairplay report: not a whole report: unreadable policy files, cited from the journal: "
              f"{escaped('; '.join(report.unreadable))}", file=sys.stderr)
    print(f"report: {escaped(out / 'report.md')}")
    return 1 if report.unreadable else 0
