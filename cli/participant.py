"""`pairplay participant export|delete STUDY_FOLDER ID`: a participant's data, on their request.

Rule: `export` writes one zip (recordings, policies, questionnaire answers,
their journal lines, a README of the contents) to <folder>/exports/<id>.zip or
`-o PATH` outside the study folder (inside it only exports/<id>.zip: a copy in
recordings/ survived the deletion), never over an existing file without --force,
and journals where it went. `delete` erases the participant everywhere pairplay
put their data (replay/studydata.py) and journals the deletion without their id;
it asks for --yes, since it cannot be undone, and lists the merged policies that
were combined from their games; each copy the journal names beyond the folder's own
places (an export outside it, a verb's output: replay/copies.py) is erased, and said,
if still pairplay's unchanged file; the copies it could not erase (changed, moved)
and the files of report/ it kept (the user's) are said on stderr, -q or not: a copy
of their data is never left unsaid.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pairplay.cli.args import file_in, key_chunk, output_file
from pairplay.errors import escaped
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
    d.add_argument("--consent-withdrawn", action="store_true",
                   help="the person withdrew their consent: the journal's anonymous line of the deletion says so")


def run(args) -> int:
    # a StudyDataError is a UserError: cli/main.py says it, `pairplay participant <action>: what (where)`, with
    # the fix this action's options offer (`exists; --force replaces it`: it was said here without it)
    # both write it: one writer per folder; a study file edited since the study began does not hold up a
    # participant's export or erasure (a new user's trial: an unrelated edit stopped a deletion), it is said
    with StudyData(args.folder, writer=f"participant {args.action}", study_file_edited_ok=True) as data:
        if data.study_file_changed:
            from pairplay.cli.main import warn
            warn(f"participant {args.action}", f"the study file {data.study_file_changed}; the {args.action} goes on "
                 "(it needs only the journal)")
        return _on_folder(data, args)  # the lock released when the verb ends (in a process that goes on: tests)


def _on_folder(data: StudyData, args) -> int:
    if args.action == "export":  # its default named as given (a refusal named the resolved study folder)
        # a game left without its end is journaled first, and said: its README said "running" of it for ever
        from pairplay.cli.protocol import built_missing_policies
        built_missing_policies(data, "participant export")
        out = file_in(args.out, f"{args.participant}.zip") or args.folder / "exports" / f"{args.participant}.zip"
        path = data.export_participant(args.participant, out, force=args.force)
        print(escaped(f"{args.participant}: {path}"))
        return 0
    data.participant(args.participant)
    check_folder(args.folder)  # it writes in it: a folder one may not write in is one line, named as given
    if not args.yes:
        raise StudyDataError(f"deleting {args.participant} cannot be undone: add --yes")
    erased = data.delete_participant(args.participant, consent_withdrawn=args.consent_withdrawn)
    gone = erased.event
    print(f"deleted: {counted(gone.sessions_removed, 'game')}, {counted(gone.files_removed, 'file')}, "
          f"{counted(gone.journal_lines_removed, 'journal line')}"
          + (", their line of the key file" if gone.key_file_line_removed else "")
          + f" (deletion {gone.deletion}" + ("; consent withdrawn, journaled without their id" if gone.consent_withdrawn
                                           else "") + ")")
    for m in gone.merged_policies_using_them:
        print(escaped(f"merged policy combined from their games (kept; re-combine without them if needed): {m}"))
    for k in gone.flaws_kept:  # the flaw outlives the person (replay/biases.py): said, as status goes on saying it;
        # the mark's reason does not (their words about the person): said withheld, as every reader says it
        print(escaped(f"merged policy made with their game marked invalid since: {k.merged} (kept flagged without "
                      f"their id, {k.reason}; the plan combines it again if it is current)"))
    if erased.unnamed:  # another's words about them, rewritten: said, so the experimenter can read what is kept
        print(f"their name (from the key file, whole or a part of it) replaced by `deleted` in "
              f"{counted(erased.unnamed, 'kept reason')} of other people's games (`pairplay protocol status` shows them)")
    if erased.no_key_line:  # on stderr, as what a deletion could not erase (below)
        print(escaped(f"{args.participant} had no line in the key file {erased.no_key_line}: their name is not known "
                      "here, so the kept reasons of other people's games were not checked for it: read them "
                      "(`pairplay protocol status`)"), file=sys.stderr)
    for c in erased.copies:
        if c.erased:
            print(escaped(f"erased {copy_words(c, args.participant)}: {c.path} (pairplay's own file, unchanged: the "
                          "bytes it wrote)"))
    for line in left_lines(args.folder, args.participant, erased):  # on stderr: -q never hides a copy left
        print(escaped(line), file=sys.stderr)
    return 0


def copy_words(c, pid: str) -> str:
    """What a journaled copy is, in words: an export, or a verb's output."""
    return (f"an export of {pid} made outside the study folder" if c.verb == "participant export"
            else f"a copy of {pid}'s data `pairplay {c.verb}` wrote")


def left_lines(folder: Path, pid: str, erased) -> list[str]:
    """What a deletion could not erase, one line each (nothing survives unsaid): a journaled copy (an export made
    outside the study folder, a verb's output) that is no longer pairplay's unchanged file (changed since, or
    moved: pairplay cannot reach a copy handed on), a file of report/ the report did not write (the user's: it
    stays; it may name them)."""
    why = {"changed": "changed since pairplay wrote it (not the bytes it wrote), so not erased",
           "missing": "not there now (moved or copied elsewhere?)",
           "unverifiable": "journaled without its checksum (an older pairplay): it cannot be told unchanged"}
    lines = [f"NOT erased: {copy_words(c, pid)}: {c.path} ({why.get(c.fate, c.fate)}); erase it "
             f"(and any copy of it) by hand" for c in erased.copies if not c.erased]
    for rel, names in erased.left:
        lines.append(f"kept {folder / rel}: not written by the report (the user's)"
                     + (f"; it names {pid} (their id, or their name or a part of it, from the key file): edit it by "
                        "hand" if names
                        else f"; check it does not mention {pid}"))
    return lines
