"""Option types shared by the verbs: numbers with their range, seeds, ports, the --force flag.

Rule: a value out of range is refused by argparse itself, before any work, with
the range in the message (`argument --rounds: must be at least 1, got -1`), the
value echoed as the user typed it (`--seed 1e3` is "not an integer: '1e3'", `--rounds
0_0` "got 0_0", `--psi 2e0` "got 2e0": the line points at what is on the command line;
an integer's echo was its parsed value, a number's the text);
main's Parser prints it on one line. A verb states its ranges where it declares
its options, never later in its run(). Every number option has a type from here
(tests/test_cli_options.py checks every verb): a bare `type=int` let `--seed -5`
reach core/rng.py as a traceback, and a bare `type=float` let `nan` and `inf`
into a session's config, which JSON writes as null (the recorder refused the
session after its bus had started).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import NamedTuple


def int_at_least(low: int):
    """An argparse type: an integer >= low."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {text}")
        return value
    parse.__name__ = f"integer >= {low}"
    return parse


def float_at_least(low: float, above: bool = False):
    """An argparse type: a finite number >= low (> low with `above`)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
        if value <= low if above else value < low:
            raise argparse.ArgumentTypeError(f"must be {'above' if above else 'at least'} {low:g}, got {text}")
        return value
    parse.__name__ = f"number {'>' if above else '>='} {low:g}"
    return parse


SEED_MAX = 2**64 - 1  # schemas/session.py SEED_RANGE, core/rng.py's (not imported: the parser stays light; a test pins it)


def seed_number(text: str) -> int:
    """A seed: an integer 0..SEED_MAX (every seed there has its own streams, core/rng.py)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"a seed is 0..{SEED_MAX}, got {text}")
    return value


GAME_INDEX_MAX = 2**63 - 1  # schemas/session.py GAME_INDEX_RANGE, core/rng.py's (a test pins it)


def game_index(text: str) -> int:
    """A game of a seed: an integer 0..GAME_INDEX_MAX (`--game-index 99999999999999999999` passed
    `non_negative`, started the bus and ended in core/rng.py's range check, a traceback)."""
    value = int_at_least(0)(text)
    if value > GAME_INDEX_MAX:
        raise argparse.ArgumentTypeError(f"a game index is 0..{GAME_INDEX_MAX}, got {text}")
    return value


def _between(at_least, kind: str, low, high, why: str):
    """An argparse type: a value of `at_least(low)` (int_at_least, float_at_least) that is also <= high."""
    def parse(text: str):
        value = at_least(low)(text)
        if value > high:
            raise argparse.ArgumentTypeError(f"must be {low:g}..{high:g}{f' ({why})' if why else ''}, got {text}"
                                             if kind == "number" else
                                             f"must be {low}..{high}{f' ({why})' if why else ''}, got {text}")
        return value
    parse.__name__ = f"{kind} {low}..{high}" if kind == "integer" else f"{kind} {low:g}..{high:g}"
    return parse


def int_between(low: int, high: int, why: str = ""):
    """An argparse type: an integer low..high; `why` (the bound's reason) is said when refused."""
    return _between(int_at_least, "integer", low, high, why)


def float_between(low: float, high: float, why: str = ""):
    """An argparse type: a finite number low..high; `why` (the bound's reason) is said when refused."""
    return _between(float_at_least, "number", low, high, why)


SPEED_RANGE = (1e-4, 1e6)  # a recording's pace, times real time: slower, one recorded second waits over 10000 s (the signal tests pace at 0.0005)


def speed(text: str) -> float:
    """A recording's pace (replay, view): `max` or 0 for as fast as possible, else a finite factor in
    SPEED_RANGE. `--speed nan` replayed nothing with exit 0 and `--speed 1e-300` made a pause too long
    for the clock (OverflowError)."""
    if text == "max":
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if value == 0:
        return 0.0
    low, high = SPEED_RANGE
    if not low <= value <= high:  # also refuses nan and inf
        raise argparse.ArgumentTypeError(f"must be max (or 0, as fast as possible) or {low:g}..{high:g} times real "
                                         f"time (slower, one recorded second waits over {1 / low:g} s), got {text}")
    return value


duration = float_between(0, 3600, "seconds to wait: an hour at most")  # `--linger 1e300` overflowed the clock


def workers(text: str) -> int:
    """A number of local worker processes: 1..pairplay.processes.max_workers() (its docstring says why)."""
    from pairplay.processes import max_workers
    return int_between(1, max_workers(), "the CPUs this process may use: more only queue cells")(text)


def port_or_any(text: str) -> int:
    """A TCP port, or 0 for one the system picks."""
    value = int_at_least(0)(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"a port is 0..65535, got {text}")
    return value


def fraction(text: str) -> float:
    """A number in 0..1 (a probability, a decay factor)."""
    value = float_at_least(0)(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text}")
    return value


count = int_at_least(1)  # rounds, games, seeds: at least one
# A session over the bus (session, lab, run) holds what it played until it ends (every service's Outbox keeps
# what it sent for a restarted recorder, the recorder and the CLI keep the events, the allocator keeps the
# rest): measured `session --participant sim:ashley`, peak RSS 289 MB at 200 rounds, 327 MB at 400, 465 MB
# at 800, 744 MB at 1600, so ~0.35 MB a round on ~180 MB. `--rounds 1000000000` grew to 3.7 GB in 10 min
# and was killed; the limit keeps a session under ~2 GB, as core/simulate.py MEMORY_LIMIT keeps a study.
SESSION_ROUNDS_MAX = 5_000
session_rounds = int_between(1, SESSION_ROUNDS_MAX, "a session over the bus holds ~0.35 MB a round until it "
                                                    "ends: at most ~2 GB")
UPDATES_MAX = 2**63 - 1  # report/study.py's: a state's update count is an int64 (a test pins it)
# how often a state was updated, a threshold (`--trained-updates 1e23` was met by no state, without a word)
update_count = int_between(0, UPDATES_MAX, "a state's updates are counted in 64 bits")
non_negative = int_at_least(0)
positive_number = float_at_least(0, above=True)  # a ridge penalty



def time_ns(text: str) -> int:
    """An argparse type: an ISO 8601 time in ns since the epoch (pairplay/isotime.py, the console's parser too;
    the future is the verb's to refuse)."""
    from pairplay.isotime import iso_time_ns
    try:
        return iso_time_ns(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def key_chunk(what: str):
    """An argparse type: an id that names a key chunk (a session id, a participant id): non-empty,
    no space of any kind, none of / * $ # ? @ (schemas/keys.py `check_chunk`). An empty `--session ''`
    used to fall back to a made-up id, and a blank one was taken as it was."""
    def parse(text: str) -> str:
        from pairplay.schemas.keys import check_chunk
        try:
            return check_chunk(what, text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None
    parse.__name__ = what
    return parse


def session_id(text: str) -> str:
    """An argparse type: a session id. A key chunk (key_chunk) that is also a safe file name: it names
    the session's recordings (`<id>.mcap`, a restarted recorder's parts `<id>.<k>.mcap`,
    `<id>.recovered.mcap`), so no `.` (session `x.1`'s file was part 1 of session `x`, and `--force`
    on `x` deleted it; `.` and `..` made hidden files) and no `\\`."""
    text = key_chunk("session id")(text)
    if "." in text or "\\" in text:
        raise argparse.ArgumentTypeError(
            f"session id '{text}' must be free of . and \\: it names its recording files (<id>.mcap, <id>.<k>.mcap)")
    if text.startswith("-"):  # `--session=-x` wrote -x.mcap, a file every command takes for an option (a trial)
        raise argparse.ArgumentTypeError(f"session id '{text}' must not start with '-': it names its recording "
                                         f"files (<id>.mcap), which commands would take for an option")
    return text


# Output paths. Rule: an option that names an output FILE is declared with `output_file`, one that names an
# output FOLDER with `output_folder` (tests/test_cli_paths.py finds every one on every verb's parser). argparse's
# `type=Path` dropped what said "folder": `-o out/` and `-o out/.` became Path('out'), and `participant export
# -o out/`, `recover -o out/`, `view --out x/`, `combine -o cmb/` wrote a FILE named out (a new user's trials).
# A file option given as a folder goes into that folder under the verb's default name (`into`), or, where the
# verb has none, is refused naming the option; never a file named after the folder.


def names_folder(text: str) -> bool:
    """Whether the path `text` can only name a folder: it ends with a separator, or its last part is `.` or
    `..` (pathlib forgets a trailing `/` and a last `.`)."""
    seps = tuple(s for s in (os.sep, os.altsep) if s)
    return text.endswith(seps) or text.rsplit(os.sep, 1)[-1] in (".", "..")


class IntoFolder(NamedTuple):
    """An output file's option given as a folder (`-o out/`): the file goes into `folder` under the verb's
    default name (`file_in`)."""
    folder: Path
    given: str

    def __str__(self) -> str:
        return self.given


def output_file(into: bool = False):
    """An argparse type: an output FILE's path. Given as a folder (`names_folder`): with `into` (the verb has
    a default name for the file) an IntoFolder, which the verb names with `file_in`; without, refused (the
    verb has no name to give the file)."""
    def parse(text: str) -> Path | IntoFolder:
        if not text:
            raise argparse.ArgumentTypeError("an empty path names no file")
        if names_folder(text):
            if into:
                return IntoFolder(Path(text), text)
            raise argparse.ArgumentTypeError(f"{text!r} names a folder; give a file name (a folder is never "
                                             "written as a file)")
        return Path(text)
    parse.__name__ = "output file"
    parse.into = into  # type: ignore[attr-defined]  # read by tests/test_cli_paths.py
    return parse


def output_folder(text: str) -> Path:
    """An argparse type: an output FOLDER's path (a trailing `/` says the same thing: kept as a folder)."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path names no folder")
    return Path(text)


output_folder.__name__ = "output folder"


def file_in(value: Path | IntoFolder | None, default_name: str) -> Path | None:
    """The output file an `output_file(into=True)` option names: `value` itself, or, given as a folder,
    `default_name` in that folder (`recover cut.mcap -o out/` writes out/cut.recovered.mcap); None stays None."""
    return value.folder / default_name if isinstance(value, IntoFolder) else value


def note_given(action: argparse.Action) -> None:
    """Make `action` note its dest in the namespace's `_given` when its option is on the command line
    (a default looks the same as a value given once parsed; the help still shows the default)."""
    base = type(action)

    class Noted(base):
        def __call__(self, parser, namespace, values, option_string=None):
            namespace._given = getattr(namespace, "_given", ()) + ((self.dest, option_string or self.dest),)
            super().__call__(parser, namespace, values, option_string)

    action.__class__ = Noted


def option_policy(path, option: str):
    """The policy file `path` an option names (`option`: as typed, `--policy reuse:p.json`); its refusal names the
    option, in place of the path it starts with: "nope.json: cannot read" named no option (a new user's trial)."""
    from pairplay.errors import OptionError, UserError
    from pairplay.schemas.policy import read_policy

    try:
        return read_policy(path)
    except UserError as err:
        what = err.what.removeprefix(f"{path}: ").removeprefix(f"{Path(path)}: ")
        raise OptionError(f"{option}: {what}", option.split()[0]) from None


def add_force(p: argparse.ArgumentParser, what: str = "existing outputs") -> None:
    p.add_argument("--force", action="store_true", help=f"replace {what} (never replaced without it)")


# A people's study folder (`pairplay protocol init`) is written by `pairplay protocol` alone: its journal says what
# every file in it is, and `participant delete` erases what it says. `report pk --out pk/recordings --force`,
# `study --out pk/policies` (a simulated study inside a people's one) all wrote there, exit 0 (a new user's trial).
# The places the study's own verbs own stay theirs: `report`'s STUDY/report, `participant export`'s
# STUDY/exports/<id>.zip, and what `view`/`recover` write beside a game's recording in STUDY/recordings/ (the
# deletion erases those too: replay/copies.py `erased_anyway`).


def _owned_by_study_verb(verb: str, action: str | None, args, path: Path, into: bool, root: Path) -> bool:
    """Whether the output `path` (a folder the file goes into, with `into`) inside the study folder `root`
    (resolved) is a place `verb` itself owns there (see above)."""
    full = path.resolve()
    if verb == "report":
        from pairplay.replay.copies import study_root
        folder = getattr(args, "folder", None)
        return full == root / "report" and folder is not None and study_root(folder) == root
    if verb == "participant" and action == "export":
        return True  # its own check says more (export_participant: only exports/<id>.zip of that participant)
    if verb in ("view", "recover"):
        if into:
            return full == root / "recordings"
        recordings = root / "recordings"
        return full.parent == recordings and any(
            full.name.startswith(f"{rec.name.split('.', 1)[0]}.") and full != rec
            for rec in recordings.glob("*.mcap"))
    return False


def check_study_folders(verb: str, parser: argparse.ArgumentParser | None, args) -> None:
    """Refuse, before any work, an output option (an `output_file` or `output_folder` one) of `verb` that names
    a place inside a people's study folder (replay/copies.py `study_root`), but those the study's own verbs own
    (see above): a UserError (cli/main.py: one line, exit 2) naming the option and the path as typed. `pairplay protocol`
    writes its study folders: never refused here. Called by cli/main.py for every verb: the one place all pass."""
    if parser is None or verb == "protocol":
        return
    from pairplay.replay.copies import study_root

    parsers = [parser]
    action = getattr(args, "action", None)
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction) and action in a.choices:
            parsers.append(a.choices[action])
    for p in parsers:
        for a in p._actions:
            if not (a.type is output_folder or getattr(a.type, "__name__", "") == "output file"):
                continue
            value = getattr(args, a.dest, None)
            if value is None or value == "":
                continue
            into = isinstance(value, IntoFolder)
            path = value.folder if into else Path(value)
            root = study_root(path)
            if root is None or _owned_by_study_verb(verb, action, args, path, into, root):
                continue
            shown = max(a.option_strings, key=len) if a.option_strings else (a.metavar or a.dest)
            from pairplay.errors import UserError
            raise UserError(f"{shown} {str(value)!r}: inside a people's study folder only `pairplay protocol` writes "
                            f"(and the study's own verbs their places: report/, exports/<id>.zip, a view or recover "
                            f"beside a game's recording); give {shown} elsewhere")
