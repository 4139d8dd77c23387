"""`pairplay participant export|delete STUDY_FOLDER ID`: a participant's data, on their request.

Rule: `export` writes one zip (recordings, policies, questionnaire answers,
their journal lines, a README of the contents) to <folder>/exports/<id>.zip or
`-o PATH`, never over an existing file without --force. `delete` erases the
participant everywhere pairplay put their data (replay/studydata.py) and
journals the deletion without their id; it asks for --yes, since it cannot be
undone, and lists the merged policies that were combined from their games.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pairplay.cli.args import file_in, key_chunk, output_file
from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.numbers import counted
from pairplay.outputs import check_folder


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    e = sub.add_parser("export", help="one zip of a participant's recordings, policies and answers, with a README")
    e.add_argument("folder", type=Path)
    e.add_argument("participant", type=key_chunk("participant id"))
    e.add_argument("-o", "--out", type=output_file(into=True),
                   help="the zip (default <folder>/exports/<id>.zip; a folder: <id>.zip in it)")
    e.add_argument("--force", action="store_true", help="replace an existing zip")
    d = sub.add_parser("delete", help="erase a participant's data from the study (cannot be undone)")
    d.add_argument("folder", type=Path)
    d.add_argument("participant", type=key_chunk("participant id"))
    d.add_argument("--yes", action="store_true", help="confirm the deletion")


def run(args) -> int:
    # a StudyDataError is a UserError: cli/main.py says it, `pairplay participant <action>: what (where)`, with
    # the fix this action's options offer (`exists; --force replaces it`: it was said here without it)
    data = StudyData(args.folder)
    if args.action == "export":  # its default named as given (a refusal named the resolved study folder)
        out = file_in(args.out, f"{args.participant}.zip") or args.folder / "exports" / f"{args.participant}.zip"
        path = data.export_participant(args.participant, out, force=args.force)
        print(f"{args.participant}: {path}")
        return 0
    data.participant(args.participant)
    check_folder(args.folder)  # it writes in it: a folder one may not write in is one line, named as given
    if not args.yes:
        raise StudyDataError(f"deleting {args.participant} cannot be undone: add --yes")
    gone = data.delete_participant(args.participant)
    print(f"deleted: {counted(gone.sessions_removed, 'game')}, {counted(gone.files_removed, 'file')}, "
          f"{counted(gone.journal_lines_removed, 'journal line')}"
          + (", their line of the key file" if gone.key_file_line_removed else "")
          + f" (deletion {gone.deletion})")
    for m in gone.merged_policies_using_them:
        print(f"merged policy combined from their games (kept; re-combine without them if needed): {m}")
    return 0
