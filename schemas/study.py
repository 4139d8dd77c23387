"""A study with people, defined in one TOML file (thesis 7.2): phases, games, rounds, questionnaires.

Rule: `load_study(path)` reads the file with tomllib, converts it strictly (an
unknown key is an error) and checks what a type cannot say (a phase's bias
names an earlier phase, a questionnaire named by a phase exists, a Likert
scale has 2..11 points...). Every problem is a `StudyFileError` whose message
is ONE line naming the file and the place in the file's words
(`[[phase]] "phase2" bias`, `[[questionnaire.after-game.item]] "followed" kind`,
a value as typed: schemas/tomlplace.py Written): the CLI prints it as it is. Nothing else in the
file is trusted: ids become file and bus key chunks, so they are restricted
to [a-z0-9-_].

The shipped example, `studies/thesis-ch7.toml` (package data), is the
thesis's own protocol: phase 1, 2 games x 5 rounds of Q-learning with epsilon
0.9 falling by a fifth of 0.9 a round; the phase-1 policies combined into the
bias policy; phase 2, 1 game x 5 rounds of pi-reuse with the last round on the
new policy alone; a questionnaire after every game built from what sections
7.2-7.3 report of the thesis's questionnaires.
"""

from __future__ import annotations

import re
import tomllib
import typing
from importlib import resources
from pathlib import Path
from typing import Literal, Union

import msgspec

from pairplay.inputs import check_input
from pairplay.nearest import nearest
from pairplay.numbers import TYPE_NAMES, counted, type_name, typed_floats

from .config import LearnerConfig
from .jsonfile import MAX_SAID, a_folder, empty, toml_words, unknown_keys
from .robot_url import parse_robot_url
from .session import MS_FIELDS, MS_RANGE, SEED_RANGE
from .tomlplace import Written, header, misplaced, table_not_value
from .nesting import toml_loads

ID = re.compile(r"^[a-z0-9][a-z0-9_-]{0,39}$")
PRESETS = ("virtual", "human-phase1", "human-phase2")
ALGORITHMS = ("q-learning", "pi-reuse")
NO_ROBOT = "none"  # a study without a robot bridge (services/robot/choice.py NO_ROBOT)
EXAMPLE = "thesis-ch7.toml"


class StudyFileError(ValueError):
    """A study file that cannot be used; the message is one line saying what and where."""


class Item(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One question. kind: "likert" (1..scale, `low`/`high` label the ends), "text" (free),
    "choice" (one of `options`). `ask`: who gets it: everyone, or only participants
    who played an earlier phase ("returning", thesis 7.2: phase-1 users get more
    questions in phase 2), or only those who did not ("new")."""

    id: str
    text: str
    kind: Literal["likert", "text", "choice"]
    scale: int = 5
    low: str = ""
    high: str = ""
    options: list[str] = []
    required: bool = True
    ask: Literal["all", "returning", "new"] = "all"
    max_chars: int = 2000


class Questionnaire(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    title: str
    item: list[Item]
    intro: str = ""


class Phase(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One phase of the protocol: who plays, how many games of how many rounds, how the robot learns.

    `players`: "new" (those registered for this phase) or "all" (also everyone
    of the earlier phases: the thesis's phase 2). `bias`: the phase whose
    policies are combined (algorithm 4, through the combiner service) into this
    phase's bias policy (pi-reuse); it plays 2 or more games a participant, since
    each participant's profile (algorithm 3) compares their policies (thesis 7.2:
    "the minimum required"). `learner`: fields of LearnerConfig that
    override the preset's. `questionnaires`: answered after every game.
    """

    id: str
    games: int
    rounds: int
    algorithm: Literal["q-learning", "pi-reuse"] = "q-learning"
    preset: Literal["virtual", "human-phase1", "human-phase2"] = "human-phase1"
    players: Literal["new", "all"] = "new"
    bias: str = ""
    learner: dict[str, Union[float, int, None]] = {}
    questionnaires: list[str] = []
    title: str = ""


class StudyHead(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """[study]: the name, the seed of every session's deal and agent streams, the
    touch-screen settings of 7.1.2-7.1.3 and the robot (--robot forms)."""

    id: str
    title: str = ""
    seed: int = 0
    ignore_window_ms: float = 1500.0
    # which clock times the two picks: the board page's ("page", the thesis's touch screen) or the server's
    ignore_clock: Literal["page", "server"] = "page"
    turn_back_ms: float = 1500.0  # a missed pair stays face up this long on the board
    wrong_suggestion_button: bool = True
    robot: str = "virtual"
    # the version of the informed-consent form participants sign (as the ethics board approved it, e.g.
    # "v2 2026-11"): registering a person records their consent to it, with the time (journal ConsentGiven)
    consent_form: str = ""


class Study(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    study: StudyHead
    phase: list[Phase]
    questionnaire: dict[str, Questionnaire] = {}

    def phase_by_id(self, phase_id: str) -> Phase:
        for p in self.phase:
            if p.id == phase_id:
                return p
        near = nearest(phase_id, [p.id for p in self.phase])  # `phse1`; not `phase3` for phase1: another one
        hint = f" (did you mean {near!r}?)" if near else ""
        raise KeyError(f"no phase {phase_id!r} in study {self.study.id!r}{hint}; its phases: "
                       f"{', '.join(p.id for p in self.phase)}")

    def learner_config(self, phase: Phase) -> LearnerConfig:
        """The phase's schedule: its preset for its rounds, with its overrides."""
        base = {"virtual": lambda r: LearnerConfig(), "human-phase1": LearnerConfig.human_phase1,
                "human-phase2": LearnerConfig.human_phase2}[phase.preset](phase.rounds)
        # convert, not replace: replace checks neither the types nor the ranges, and the session that
        # reads the schedule back (SessionConfig.learner_config) would refuse it when the game starts
        return msgspec.convert({**msgspec.structs.asdict(base), **phase.learner}, LearnerConfig)

    def questions(self, name: str, returning: bool) -> list[Item]:
        """The items of questionnaire `name` a (returning or new) participant is asked."""
        wanted = ("all", "returning" if returning else "new")
        return [i for i in self.questionnaire[name].item if i.ask in wanted]


class _Bad(Exception):
    """A rule of `_check` broken at `path` (keys, and ints for array elements): what is wrong."""

    def __init__(self, path: tuple, what: str):
        super().__init__(what)
        self.path, self.what = path, what


def _check(study: Study, written: Written) -> None:
    """Every rule a type cannot state; raises _Bad(path, what), each value as the file has it (`typed`)."""
    typed = written.typed

    def need_id(path: tuple, value: str) -> None:
        if not ID.match(value):
            raise _Bad(path, f"{typed(path, value)} must be 1-40 characters of a-z 0-9 - _ (it names files)")

    need_id(("study", "id"), study.study.id)
    if not SEED_RANGE[0] <= study.study.seed <= SEED_RANGE[1]:  # every session's seed (core/rng.py game_seed)
        raise _Bad(("study", "seed"), f"must be {SEED_RANGE[0]}..{SEED_RANGE[1]}, "
                                      f"got {typed(('study', 'seed'), study.study.seed)}")
    for key in MS_FIELDS:
        if not MS_RANGE[0] <= getattr(study.study, key) <= MS_RANGE[1]:  # also refuses nan and inf
            raise _Bad(("study", key), f"must be {MS_RANGE[0]:g}..{MS_RANGE[1]:g} (ms), "
                                       f"got {typed(('study', key), getattr(study.study, key))}")
    robot = study.study.robot
    if robot != NO_ROBOT:  # the --robot option's parser: a URL a session would refuse is refused here
        try:
            parse_robot_url(robot)
        except ValueError as err:
            why = str(err).removeprefix("--robot ")
            forms = "" if "use one of" in why else " (virtual, none, iristk://HOST[:PORT] or furhat://HOST[:PORT])"
            raise _Bad(("study", "robot"), f"{why}{forms}") from None
    form = study.study.consent_form
    if not consent_form_ok(form):
        raise _Bad(("study", "consent_form"), f"{typed(('study', 'consent_form'), form[:40])} {CONSENT_FORM_RULE}")
    if not study.phase:
        raise _Bad((), "a study needs at least one [[phase]]")
    seen: list[str] = []
    for n, p in enumerate(study.phase):
        where = ("phase", n)
        need_id(where + ("id",), p.id)
        if p.id in seen:
            raise _Bad(where + ("id",), f"{typed(where + ('id',), p.id)} is used twice")
        if not 1 <= p.games <= 20:
            raise _Bad(where + ("games",), f"must be 1..20, got {typed(where + ('games',), p.games)}")
        if not 1 <= p.rounds <= 100:
            raise _Bad(where + ("rounds",), f"must be 1..100, got {typed(where + ('rounds',), p.rounds)}")
        bias = where + ("bias",)
        if p.algorithm == "pi-reuse" and not p.bias:
            raise _Bad(bias, "pi-reuse needs the phase whose policies make the bias policy")
        if p.bias and p.bias not in seen:
            raise _Bad(bias, f"{typed(bias, p.bias)} is not an earlier phase (earlier: {', '.join(seen) or 'none'})")
        if p.bias and p.algorithm != "pi-reuse":
            raise _Bad(bias, "only a pi-reuse phase uses a bias policy")
        if p.bias and study.phase_by_id(p.bias).games < 2:
            # thesis 7.2: phase 1's two games are "the minimum required to generate the policies needed for the
            # user information extraction" (algorithm 3 compares a user's policies; one gives no profile)
            raise _Bad(bias, f"phase {typed(bias, p.bias)} plays {study.phase_by_id(p.bias).games} game per "
                             "participant; a bias phase needs 2 or more (algorithm 3 compares each participant's "
                             "policies: thesis 7.2)")
        for name in p.questionnaires:
            if name not in study.questionnaire:
                raise _Bad(where + ("questionnaires",), f"no [questionnaire.{name}] in the file")
        try:
            schedule = study.learner_config(p)
        except (TypeError, ValueError, msgspec.ValidationError) as err:
            raise _learner(err, where + ("learner",), p.learner, written) from None
        never = schedule.never_reuses() if p.algorithm == "pi-reuse" else ""
        if never:  # 1 round under human-phase2: its one round is the last, on the new policy alone
            raise _Bad(where, f"a pi-reuse phase of {counted(p.rounds, 'round')} "
                              f"that never reuses the bias policy: {never} (preset {p.preset}; give 2 rounds "
                              "or more, or learner overrides that reuse)")
        seen.append(p.id)
    if study.phase[0].players == "all":
        raise _Bad(("phase", 0, "players"), "the first phase has no earlier players; use \"new\"")
    for name, q in study.questionnaire.items():
        need_id(("questionnaire", name), name)
        if not q.item:
            raise _Bad(("questionnaire", name), f"needs at least one [[questionnaire.{name}.item]]")
        ids: set[str] = set()
        for n, item in enumerate(q.item):
            where = ("questionnaire", name, "item", n)
            need_id(where + ("id",), item.id)
            if item.id in ids:
                raise _Bad(where + ("id",), f"{typed(where + ('id',), item.id)} is used twice in questionnaire {name}")
            ids.add(item.id)
            if not item.text.strip():
                raise _Bad(where + ("text",), "the question is empty")
            if item.kind == "likert" and not 2 <= item.scale <= 11:
                raise _Bad(where + ("scale",), f"a Likert scale has 2..11 points, "
                                               f"got {typed(where + ('scale',), item.scale)}")
            if item.kind == "choice" and len(item.options) < 2:
                raise _Bad(where + ("options",), "a choice needs at least 2 options")
            if item.kind != "choice" and item.options:
                raise _Bad(where + ("options",), "only a choice item has options")
            if not 1 <= item.max_chars <= 20000:
                raise _Bad(where + ("max_chars",), f"must be 1..20000, got {typed(where + ('max_chars',), item.max_chars)}")


def _learner(err: Exception, where: tuple, given: dict, written: Written) -> _Bad:
    """A phase's learner overrides that LearnerConfig refuses, at the key it names: its range ("alpha_start
    must be 0..1, got nan", the value as typed), msgspec's type or unknown key (a phase's key below its
    [phase.learner] line is the learner's: schemas/tomlplace.py)."""
    text = str(err)
    ranged = re.fullmatch(r"(\w+) must be (.+), got .*", text)
    if ranged and ranged[1] in given:
        path = where + (ranged[1],)
        return _Bad(path, f"must be {ranged[2]}, got {written.typed(path, given[ranged[1]])}")
    what, inner = _located(text)  # msgspec's `$.epsilon_every`: a key of the learner's
    text = f"{what} - at `$.{where[0]}[{where[1]}].{where[2]}{'.' + inner if inner else ''}`"
    placed = _placed(text, written.raw, written)
    return placed or _where(text, written.raw, written)


def parse_study(text: str, source: str = "study") -> Study:
    """A Study from TOML text; StudyFileError('<source>: <place>: <what>') if anything is wrong, the place in
    the file's words (`[[phase]] "phase1" rounds`: schemas/tomlplace.py Written)."""
    if empty(text):  # (tomllib reads it as a table of nothing: "Object missing required field `study`")
        raise StudyFileError(f"{source}: {empty(text)}")
    with typed_floats() as parse_float:  # a number a line echoes, as the file has it (pairplay/numbers.py)
        try:
            raw = toml_loads(text, parse_float=parse_float)
        except tomllib.TOMLDecodeError as err:
            raise StudyFileError(f"{source}: not valid TOML: {toml_words(err, text)}") from None
        written = Written(text, raw)
        try:
            study = msgspec.convert(raw, Study)
            _check(study, written)
        except msgspec.ValidationError as err:
            if "unknown field" in str(err) and len(every := unknown_keys(raw, Study)) > 1:  # all at once, not one a run
                lines = []
                for where, key in every[:MAX_SAID]:
                    message = f"Object contains unknown field `{key}`" + (f" - at `$.{where}`" if where else "")
                    lines.append(_line("", _placed(message, raw, written) or _where(message, raw, written), written)
                                 .removeprefix(": "))
                more = f"; and {len(every) - MAX_SAID} more" if len(every) > MAX_SAID else ""
                raise StudyFileError(f"{source}: {'; '.join(lines)}{more}") from None
            bad = _placed(str(err), raw, written) or _where(str(err), raw, written)
            if "missing required field" in str(err) and text.strip() and not text.endswith("\n"):
                # a file cut mid-table is valid TOML up to its cut: what is missing is said with where it ends
                # (it said only "needs a [phase] table"); a file whose last line is whole ends with a newline
                lines = text.count("\n") + 1
                bad.what += (f"; the file ends at line {lines} without a final newline: cut short there? (a copy or "
                             "a save that did not finish: put back a whole copy)")
            raise StudyFileError(_line(source, bad, written)) from None
        except _Bad as bad:
            raise StudyFileError(_line(source, bad, written)) from None
    return study


def _line(source: str, bad: _Bad, written: Written) -> str:
    """`FILE: [table] key: what`, the place in the file's words (a rule of the whole file: `FILE: what`)."""
    place = written.place(bad.path)
    return f"{source}: {place}: {bad.what}" if place else f"{source}: {bad.what}"


def _where(message: str, raw: object, written: Written) -> _Bad:
    """msgspec's 'Expected `int`, got `str` - at `$.phase[0].rounds`' as (path, 'must be an integer, got
    "five"'), in words (as the sweep file's check says them) and the value as the file has it. A table's
    value (`learner = { alpha_start = "x" }`) msgspec says at `[...]`: its key is named from the TOML read
    (`raw`). An unknown key is said with the keys its table takes (the one it resembles first)."""
    what, where = _located(message)
    if "[...]" in where:
        where = _name_keys(where, what, raw)
    path = _path(where)
    kinds = re.fullmatch(r"Expected `([\w |]+)`, got `(\w+)`", what)
    if kinds:
        wanted = [k for k in kinds[1].split(" | ") if k != "null"]
        if {"int", "float"} <= set(wanted):
            wanted.remove("int")  # "a number" covers both
        if all(k in TYPE_NAMES for k in wanted):
            return _Bad(path, f"must be {' or '.join(type_name(k) for k in wanted)}, "
                              f"got {written.typed(path, _at(raw, path))}")
    enum = re.fullmatch(r"Invalid enum value (.+)", what)
    if enum:
        options = _options(path)
        said = f"must be one of {', '.join(options)}" if options else "is not one of the values it takes"
        near = nearest(str(_at(raw, path)), options)  # `preset = "human-phse1"`: the one meant (pairplay/nearest.py)
        return _Bad(path, f"{said}, got {written.typed(path, _at(raw, path))}" + (f" (did you mean {near!r}?)" if near else ""))
    unknown = re.fullmatch(r"Object contains unknown field `(.+)`", what)
    if unknown:
        key, shape = unknown[1], _shape(path)
        keys = sorted(_keys(shape)) if shape in TABLES else []
        kind = "table" if isinstance(_at(raw, path + (key,)), dict) else "key"
        near = nearest(key, keys) if kind == "key" else ""  # a misspelt key
        said = f"{header(path)} has no {kind} `{key}`"
        said += f" (did you mean `{near}`?)" if near else f"; its keys: {', '.join(keys)}" if keys else ""
        return _Bad(path + (key,), said)
    missing = re.fullmatch(r"Object missing required field `(.+)`", what)
    if missing:
        return _Bad(path, f"needs `{missing[1]} = ...` (a {header(path)} has no default for it)"
                    if path else f"needs a [{missing[1]}] table")
    return _Bad(path, what)


def _options(path: tuple) -> list[str]:
    """The values a Literal field at `path` takes (Item.kind: likert, text, choice), [] if none known."""
    shape = _shape(path[:-1])
    if shape not in TABLES or not path:
        return []
    for f in msgspec.structs.fields(TABLES[shape]):
        if f.name == path[-1]:
            return [str(a) for a in typing.get_args(f.type)]
    return []


# the file's tables (schemas/tomlplace.py): a table's path, its indices as "#" and a questionnaire's name as
# "*", -> the Struct whose fields are its keys
TABLES = {(): Study, ("study",): StudyHead, ("phase", "#"): Phase, ("phase", "#", "learner"): LearnerConfig,
          ("questionnaire", "*"): Questionnaire, ("questionnaire", "*", "item", "#"): Item}


def _located(message: str) -> tuple[str, str]:
    """msgspec's message as (what, where): 'Expected `int`, got `str` - at `$.phase[0].rounds`' ->
    ('Expected ...', 'phase[0].rounds'); where is "" at the file's top, which msgspec does not name."""
    m = re.match(r"^(.*?) - at `\$\.?(.*)`$", message)
    return m.groups() if m else (message, "")


def _path(where: str) -> tuple:
    """msgspec's 'phase[0].learner.alpha_start' (its keys named) as ("phase", 0, "learner", "alpha_start")."""
    return tuple(int(t[1:-1]) if t.startswith("[") else t.lstrip(".")
                 for t in re.findall(r"\[\d+\]|\.?[^.\[]+", where))


def _shape(path: tuple) -> tuple:
    return tuple("#" if isinstance(t, int) else "*" if n == 1 and path[0] == "questionnaire" else t
                 for n, t in enumerate(path))


def _keys(shape: tuple) -> frozenset[str]:
    return frozenset(f.name for f in msgspec.structs.fields(TABLES[shape]))


def _placed(message: str, raw: object, written: Written) -> _Bad | None:
    """msgspec's error as (path, which table the key belongs to) when a key or a table stands at the wrong
    level (schemas/tomlplace.py), else None. `raw`: the TOML read, to find a required key that a table
    written too early took (`[phase.learner]` above the phase's `games`)."""
    # msgspec names no place for a key of the file's top ("Object contains unknown field `robot`")
    what, where = _located(message)
    if "[...]" in where:  # a table's value (a key of [phase.learner], a questionnaire's name): named from `raw`
        where = _name_keys(where, what, raw)
    path = _path(where)
    unknown = re.match(r"Object contains unknown field `(.+)`$", what)
    missing = re.match(r"Object missing required field `(.+)`$", what)
    if unknown or missing:
        table, key = path, (unknown or missing).group(1)
        if missing:  # a table below the table's other keys took it: name it there
            node = _at(raw, table)
            child = next((k for k, v in (node or {}).items() if isinstance(v, dict) and key in v), None)
            if child is None or _shape(table + (child,)) not in TABLES:
                return None
            table = table + (child,)
    elif path and isinstance(path[-1], str) and _shape(path[:-1]) in TABLES:
        table, key = path[:-1], path[-1]
        if "got `object`" in what and isinstance(_at(raw, path), dict) and key in _keys(_shape(table)):
            return _Bad(path, table_not_value(key, header(path), header(table)))
    else:
        return None
    if _shape(table) not in TABLES:
        return None
    tables = {header(tuple(t if t not in ("#", "*") else (0 if t == "#" else (table[1] if len(table) > 1 else "NAME"))
                           for t in shape)): _keys(shape) for shape in TABLES}
    enclosing = [header(table[:n]) for n in range(len(table) - 1, -1, -1) if _shape(table[:n]) in TABLES]
    said = misplaced(key, header(table), tables, enclosing, table=isinstance(_at(raw, table + (key,)), dict))
    return _Bad(table + (key,), said) if said else None


def _at(raw: object, path: tuple) -> object:
    """The TOML read's value at `path` (None if it has none)."""
    for token in path:
        if isinstance(token, int):
            raw = raw[token] if isinstance(raw, list) and token < len(raw) else None
        else:
            raw = raw.get(token) if isinstance(raw, dict) else None
    return raw


# msgspec's name of a TOML value's type, as its "got `...`" says it
GOT = {str: "str", bool: "bool", int: "int", float: "float", list: "array", dict: "object"}


def _name_keys(where: str, what: str, raw: object) -> str:
    """`where` with each `[...]` (a key msgspec does not name) replaced by `.key`: the first key of that
    table whose value is the type msgspec got (`got `str``), else its first key."""
    got = re.search(r"got `(\w+)`", what)
    out, node = "", raw
    for token in re.findall(r"\.?[^.\[]+|\[[^\]]*\]", where):
        if token == "[...]" and isinstance(node, dict) and node:
            keys = [k for k, v in node.items() if got and GOT.get(type(v)) == got.group(1)] or list(node)
            key = keys[0]
            out, node = f"{out}.{key}", node[key]
            continue
        out += token
        name = token.lstrip(".")
        if token.startswith("["):
            index = token[1:-1]
            node = node[int(index)] if index.isdigit() and isinstance(node, list) and int(index) < len(node) else None
        else:
            node = node.get(name) if isinstance(node, dict) else None
    return out


STUDY_FILE = "study.toml"  # a study folder's copy of its study file (replay/studydata.py)


CONSENT_FORM_RULE = 'must be one line of at most 100 printable characters, no space at its ends (a version: "v2 2026-11")'


def consent_form_ok(form: str) -> bool:
    """Whether `form` is a consent form's version (CONSENT_FORM_RULE): the study file's, and one named later
    (`protocol consent-form`, `protocol consent --form`): it lands in tables, exports and lines said to a user."""
    return len(form) <= 100 and all(c.isprintable() for c in form) and form == form.strip()


def study_file_of(path: str | Path) -> Path:
    """The study file a path argument names: a file as it is, a study folder's own (`protocol check FOLDER`
    checks the folder's protocol); StudyFileError for another folder, saying what was expected (it said the
    system's "cannot read: Is a directory")."""
    path = Path(path)
    if path.is_dir():
        if (path / STUDY_FILE).is_file():
            return path / STUDY_FILE
        raise StudyFileError(a_folder(path, "study file", f"a study's TOML file or a study folder (one holding {STUDY_FILE})"))
    return path


def load_study(path: str | Path) -> Study:
    """Read and check a study file (StudyFileError, one line, if it cannot be used); a study folder, its own."""
    path = study_file_of(path)
    check_input(path, StudyFileError)  # before opening: a pipe blocked (pairplay/inputs.py)
    try:
        text = path.read_text(encoding="utf-8-sig")  # an editor's byte order mark is no TOML error
    except (OSError, UnicodeDecodeError) as err:
        raise StudyFileError(f"{path}: cannot read: {getattr(err, 'strerror', None) or err}") from None
    return parse_study(text, str(path))


def example_text() -> str:
    """The shipped example study (the thesis's chapter 7 protocol), as TOML text."""
    return bundled_text(EXAMPLE.removesuffix(".toml"))


def bundled_studies() -> list[str]:
    """The names of the study files shipped with pairplay (`studies/<name>.toml`: thesis-ch7), which
    `protocol check` and `init --study` take for a file's path."""
    folder = resources.files("pairplay.schemas").joinpath("studies")
    return sorted(f.name.removesuffix(".toml") for f in folder.iterdir() if f.name.endswith(".toml"))


def bundled_text(name: str) -> str:
    """The TOML text of the bundled study `name` (one of `bundled_studies()`)."""
    return resources.files("pairplay.schemas").joinpath("studies", f"{name}.toml").read_text(encoding="utf-8")


def no_study_file(name: str) -> StudyFileError:
    """The refusal of a study file argument that is neither a file nor a bundled study: with the bundled
    ones (and the one it resembles), since `--study thesis-ch8` said only "No such file or directory"."""
    near = nearest(name, bundled_studies())
    return StudyFileError(f"{name}: no such study file, nor a bundled study" + (f" (did you mean {near!r}?)" if near else "")
                          + f"; the bundled studies: {', '.join(bundled_studies())} (`pairplay protocol example` "
                          "prints one to edit); or give the path of a study TOML file")
