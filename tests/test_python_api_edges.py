"""The public Python API's edges: a file that is no recording, an empty log, a constructor's or a function's
unknown argument, each said in the project's words (pairplay/arguments.py), never an empty result.

A new user's trial: `pairplay.read_log("notes.txt")` returned an EventLog with `.error` set and no events (the
script went on with nothing), `pairplay.fold_events([])` an empty fold (no config, no round, a Q-table of zeros),
`pairplay.StudySettings(bogus=1)` Python's "__init__() got an unexpected keyword argument" and
`pairplay.SessionConfig(sesion=...)` msgspec's "Unexpected keyword argument". Every public function and class
(`pairplay.API`) is given an unknown argument here; the readers that must take any file (recover, a server
reading back a game's recording) keep the non-raising reader, `read_any_log`.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import msgspec
import pytest

import pairplay
from pairplay.errors import ArgumentError, InputError, UserError

ROOT = Path(__file__).resolve().parents[1]
REC = ROOT / "recordings" / "samples" / "sim-helmut-fmt2.mcap"


def one_line(err: UserError, *words: str) -> str:
    line = str(err)
    assert "\n" not in line and all(w in line for w in words), line
    return line


@pytest.mark.parametrize("content, words", [
    (b"not a recording\n", "not a recording: not an MCAP file"),
    (b"", "the file is empty (0 bytes), not a recording"),
    (b"\x89MCA", "not an MCAP file"),
])
def test_read_log_of_a_file_that_is_no_recording_raises_naming_it(tmp_path, content, words):
    path = tmp_path / "notes.mcap"
    path.write_bytes(content)
    with pytest.raises(InputError) as caught:
        pairplay.read_log(path)
    assert one_line(caught.value, words).endswith(f"({path})")


def test_a_file_its_recorder_is_writing_reads_as_live_even_before_its_first_record(tmp_path):
    """A script polling a recording a session is writing: a file of nothing yet, a journal beside it, is no
    recorder that stopped (the refusal's words for a dead one): read as live, as far as it goes (nothing)."""
    from pairplay import livelock
    from pairplay.replay.wal import wal_path
    path = tmp_path / "now.mcap"
    held = livelock.hold(path, create=True)
    try:
        wal_path(path).write_bytes(b"")
        log = pairplay.read_log(path)
        assert log.live and not log.events and livelock.LIVE in log.error
    finally:
        livelock.release(held)
    with pytest.raises(InputError) as caught:  # its recorder gone, the same file is one that stopped
        pairplay.read_log(path)
    one_line(caught.value, "its recorder stopped before it wrote a record", "pairplay recover")


def test_the_non_raising_reader_is_kept_for_those_that_take_any_file(tmp_path):
    from pairplay.replay.reader import read_any_log
    path = tmp_path / "notes.mcap"
    path.write_bytes(b"not a recording\n")
    log = read_any_log(path)
    assert log.error and not log.events and log.no_session
    assert pairplay.read_log(REC).events  # a recording reads as before


@pytest.mark.parametrize("events", [[], (), iter([])], ids=["list", "tuple", "iterator"])
def test_fold_events_of_no_event_is_refused(events):
    with pytest.raises(InputError) as caught:
        pairplay.fold_events(events)
    one_line(caught.value, "events is empty", "pairplay.fold_events(events)")


def test_fold_events_of_a_recording_still_folds_and_the_internal_fold_takes_nothing():
    from pairplay.replay.fold import fold_any
    fold = pairplay.fold_events(e.event for e in pairplay.read_log(REC).events)
    assert fold.config is not None and fold.whole_rounds()
    assert fold_any([]).events == 0  # a session a signal stopped before its first event: lab, session, a server


@pytest.mark.parametrize("make, words", [
    (lambda: pairplay.StudySettings(bogus=1), "no argument `bogus` is known here; it takes seed, personas"),
    (lambda: pairplay.StudySettings(sede=1), "no argument `sede` is known here (did you mean `seed`?)"),
    (lambda: pairplay.StudySettings(*range(16)), "takes at most 15 by position, got 16"),
    (lambda: pairplay.StudySettings(1, seed=2), "`seed` is given twice"),
    (lambda: pairplay.SessionConfig(sesion="x"), "no argument `sesion` is known here (did you mean `session`?)"),
    (lambda: pairplay.SessionConfig(session="s"), "needs `participant`, `seed`, `rounds` (no default)"),
    (lambda: pairplay.SessionConfig("s"), "takes its values by name only"),
], ids=["unknown", "misspelt", "too-many", "twice", "struct-misspelt", "struct-missing", "struct-positional"])
def test_a_public_constructor_says_a_mistake_in_the_projects_words(make, words):
    with pytest.raises(ArgumentError) as caught:  # an InputError and a TypeError (pairplay/errors.py)
        make()
    assert isinstance(caught.value, TypeError)
    one_line(caught.value, words, "pairplay.")


def test_the_checked_constructors_still_build_decode_and_compare():
    settings = pairplay.StudySettings(seed=3, games=2)
    assert (settings.seed, settings.games) == (3, 2)
    from dataclasses import replace
    assert replace(settings, rounds=7).rounds == 7
    config = pairplay.SessionConfig(session="s", participant="sim:blind", seed=1, rounds=3, persona="blind")
    assert msgspec.json.decode(msgspec.json.encode(config), type=pairplay.SessionConfig) == config
    assert msgspec.structs.replace(config, rounds=4).rounds == 4
    assert type(config) is pairplay.SessionConfig


@pytest.mark.parametrize("name", sorted(pairplay.API))
def test_every_public_name_refuses_an_unknown_argument_with_a_suggestion(name):
    """Every function and class of the API (listed in pairplay/__init__.py), given a misspelling of its first
    argument by name: one line, the argument, the one it resembles, where (no Python TypeError of its own)."""
    public = getattr(pairplay, name)
    first = next(p.name for p in inspect.signature(public).parameters.values() if p.name != "self")
    wrong = first + "x"
    with pytest.raises(ArgumentError) as caught:
        public(**{wrong: 1})
    one_line(caught.value, f"no argument `{wrong}` is known here (did you mean `{first}`?)", f"pairplay.{name}({wrong})")


def test_the_lowest_msgspec_pyproject_allows_lets_a_public_struct_say_our_words():
    """msgspec lets a metaclass derive from its StructMeta from 0.20 on (schemas/public.py); pyproject allowed 0.19,
    where `pairplay.SessionConfig(sesion=...)` said msgspec's "Unexpected keyword argument 'sesion'" and the
    struct cases above failed (checked with msgspec 0.19.0 in a scratch venv). The lowest allowed is 0.20."""
    import re
    import tomllib
    project = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())["project"]
    [spec] = [d for d in project["dependencies"] if re.match(r"msgspec\b", d)]
    lowest = re.search(r">=\s*([0-9.]+)", spec)[1]
    assert tuple(int(n) for n in lowest.split(".")) >= (0, 20), spec
    assert hasattr(msgspec, "StructMeta")  # the installed one, within the bounds
