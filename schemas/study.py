"""A study with people, defined in one TOML file (thesis 7.2): phases, games, rounds, questionnaires.

Rule: `load_study(path)` reads the file with tomllib, converts it strictly (an
unknown key is an error) and checks what a type cannot say (a phase's bias
names an earlier phase, a questionnaire named by a phase exists, a Likert
scale has 2..11 points...). Every problem is a `StudyFileError` whose message
is ONE line naming the file and the place (`phase[1].bias`, `questionnaire.
after-game.item[3].kind`): the CLI prints it as it is. Nothing else in the
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
from importlib import resources
from pathlib import Path
from typing import Literal, Union

import msgspec

from pairplay.numbers import TYPE_NAMES, counted, shown, type_name, typed_floats

from .config import LearnerConfig
from .jsonfile import empty
from .robot_url import parse_robot_url
from .session import MS_FIELDS, MS_RANGE, SEED_RANGE
from .tomlplace import TOP, misplaced, table_not_value

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
    phase's bias policy (pi-reuse). `learner`: fields of LearnerConfig that
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


class Study(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    study: StudyHead
    phase: list[Phase]
    questionnaire: dict[str, Questionnaire] = {}

    def phase_by_id(self, phase_id: str) -> Phase:
        for p in self.phase:
            if p.id == phase_id:
                return p
        raise KeyError(f"no phase {phase_id!r} in study {self.study.id!r}")

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


def _check(study: Study) -> None:
    """Every rule a type cannot state; raises StudyFileError('<where>: <what>')."""
    def need_id(where: str, value: str) -> None:
        if not ID.match(value):
            raise StudyFileError(f"{where}: {value!r} must be 1-40 characters of a-z 0-9 - _ (it names files)")

    need_id("study.id", study.study.id)
    if not SEED_RANGE[0] <= study.study.seed <= SEED_RANGE[1]:  # every session's seed (core/rng.py game_seed)
        raise StudyFileError(f"study.seed: must be {SEED_RANGE[0]}..{SEED_RANGE[1]}, got {study.study.seed}")
    for key in MS_FIELDS:
        if not MS_RANGE[0] <= getattr(study.study, key) <= MS_RANGE[1]:  # also refuses nan and inf
            raise StudyFileError(f"study.{key}: must be {MS_RANGE[0]:g}..{MS_RANGE[1]:g} (ms), "
                                 f"got {shown(getattr(study.study, key))}")
    robot = study.study.robot
    if robot != NO_ROBOT:  # the --robot option's parser: a URL a session would refuse is refused here
        try:
            parse_robot_url(robot)
        except ValueError as err:
            why = str(err).removeprefix("--robot ")
            forms = "" if "use one of" in why else " (virtual, none, iristk://HOST[:PORT] or furhat://HOST[:PORT])"
            raise StudyFileError(f"study.robot: {why}{forms}") from None
    if not study.phase:
        raise StudyFileError("phase: a study needs at least one [[phase]]")
    seen: list[str] = []
    for n, p in enumerate(study.phase):
        where = f"phase[{n}]"
        need_id(f"{where}.id", p.id)
        if p.id in seen:
            raise StudyFileError(f"{where}.id: {p.id!r} is used twice")
        if not 1 <= p.games <= 20:
            raise StudyFileError(f"{where}.games: must be 1..20, got {p.games}")
        if not 1 <= p.rounds <= 100:
            raise StudyFileError(f"{where}.rounds: must be 1..100, got {p.rounds}")
        if p.algorithm == "pi-reuse" and not p.bias:
            raise StudyFileError(f"{where}.bias: pi-reuse needs the phase whose policies make the bias policy")
        if p.bias and p.bias not in seen:
            raise StudyFileError(f"{where}.bias: {p.bias!r} is not an earlier phase (earlier: {seen or 'none'})")
        if p.bias and p.algorithm != "pi-reuse":
            raise StudyFileError(f"{where}.bias: only a pi-reuse phase uses a bias policy")
        if p.bias and study.phase_by_id(p.bias).games < 1:
            raise StudyFileError(f"{where}.bias: phase {p.bias!r} plays no games")
        for name in p.questionnaires:
            if name not in study.questionnaire:
                raise StudyFileError(f"{where}.questionnaires: no [questionnaire.{name}] in the file")
        try:
            schedule = study.learner_config(p)
        except (TypeError, ValueError, msgspec.ValidationError) as err:
            # a phase's key below its [phase.learner] line is the learner's (schemas/tomlplace.py)
            raise StudyFileError(_placed(f"{err} - at `$.{where}.learner`") or f"{where}.learner: {err}") from None
        never = schedule.never_reuses() if p.algorithm == "pi-reuse" else ""
        if never:  # 1 round under human-phase2: its one round is the last, on the new policy alone
            raise StudyFileError(f"{where}: a pi-reuse phase of {counted(p.rounds, 'round')} "
                                 f"that never reuses the bias policy: {never} (preset {p.preset}; give 2 rounds "
                                 "or more, or learner overrides that reuse)")
        seen.append(p.id)
    if study.phase[0].players == "all":
        raise StudyFileError("phase[0].players: the first phase has no earlier players; use \"new\"")
    for name, q in study.questionnaire.items():
        need_id(f"questionnaire.{name}", name)
        if not q.item:
            raise StudyFileError(f"questionnaire.{name}: needs at least one [[questionnaire.{name}.item]]")
        ids: set[str] = set()
        for n, item in enumerate(q.item):
            where = f"questionnaire.{name}.item[{n}]"
            need_id(f"{where}.id", item.id)
            if item.id in ids:
                raise StudyFileError(f"{where}.id: {item.id!r} is used twice in questionnaire {name!r}")
            ids.add(item.id)
            if not item.text.strip():
                raise StudyFileError(f"{where}.text: the question is empty")
            if item.kind == "likert" and not 2 <= item.scale <= 11:
                raise StudyFileError(f"{where}.scale: a Likert scale has 2..11 points, got {item.scale}")
            if item.kind == "choice" and len(item.options) < 2:
                raise StudyFileError(f"{where}.options: a choice needs at least 2 options")
            if item.kind != "choice" and item.options:
                raise StudyFileError(f"{where}.options: only a choice item has options")
            if not 1 <= item.max_chars <= 20000:
                raise StudyFileError(f"{where}.max_chars: must be 1..20000")


def parse_study(text: str, source: str = "study") -> Study:
    """A Study from TOML text; StudyFileError('<source>: <where>: <what>') if anything is wrong."""
    if empty(text):  # (tomllib reads it as a table of nothing: "Object missing required field `study`")
        raise StudyFileError(f"{source}: {empty(text)}")
    with typed_floats() as parse_float:  # a number a line echoes, as the file has it (pairplay/numbers.py)
        try:
            raw = tomllib.loads(text, parse_float=parse_float)
        except tomllib.TOMLDecodeError as err:
            raise StudyFileError(f"{source}: not valid TOML: {err}") from None
        try:
            study = msgspec.convert(raw, Study)
        except msgspec.ValidationError as err:
            raise StudyFileError(f"{source}: {_placed(str(err), raw) or _where(str(err), raw)}") from None
        try:
            _check(study)
        except StudyFileError as err:
            raise StudyFileError(f"{source}: {err}") from None
    return study


def _where(message: str, raw: object = None) -> str:
    """msgspec's 'Expected `int`, got `str` - at `$.phase[0].rounds`' as 'phase[0].rounds: Expected ...'.
    A table's value (`learner = { alpha_start = "x" }`) msgspec says at `[...]`: its key is named, from
    the TOML read (`raw`), so the line says which field."""
    if not re.search(r" - at `\$", message):
        return message
    what, where = _located(message)
    if "[...]" in where and raw is not None:
        where = _name_keys(where, what, raw)
    # msgspec's type names in words, as the sweep file's check says them ("rounds = 1e3 is not an integer"
    # there, "Expected `int`, got `float`" here: a trial)
    kinds = re.fullmatch(r"Expected `(\w+)`, got `(\w+)`", what)
    if kinds and all(k in TYPE_NAMES for k in kinds.groups()):
        what = f"must be {type_name(kinds[1])}, not {type_name(kinds[2])}"
    return f"{where or 'top level'}: {what}"


# the file's tables (schemas/tomlplace.py): a table's path, its indices as "#" and a questionnaire's name as
# "*", -> the Struct whose fields are its keys
TABLES = {(): Study, ("study",): StudyHead, ("phase", "#"): Phase, ("phase", "#", "learner"): LearnerConfig,
          ("questionnaire", "*"): Questionnaire, ("questionnaire", "*", "item", "#"): Item}


def _located(message: str) -> tuple[str, str]:
    """msgspec's message as (what, where): 'Expected `int`, got `str` - at `$.phase[0].rounds`' ->
    ('Expected ...', 'phase[0].rounds'); where is "" at the file's top, which msgspec does not name."""
    m = re.match(r"^(.*) - at `\$\.?(.*)`$", message)
    return m.groups() if m else (message, "")


def _shape(path: tuple) -> tuple:
    return tuple("#" if isinstance(t, int) else "*" if n == 1 and path[0] == "questionnaire" else t
                 for n, t in enumerate(path))


def _header(path: tuple) -> str:
    """A table's header as the file writes it: ("phase", 0, "learner") -> [phase.learner]."""
    if not path:
        return TOP
    names = ".".join(t for t in path if isinstance(t, str))
    return f"[[{names}]]" if isinstance(path[-1], int) else f"[{names}]"


def _keys(shape: tuple) -> frozenset[str]:
    return frozenset(f.name for f in msgspec.structs.fields(TABLES[shape]))


def _placed(message: str, raw: object = None) -> str:
    """msgspec's error as 'where: which table the key belongs to' when a key or a table stands at the wrong
    level (schemas/tomlplace.py), else "". `raw`: the TOML read, to find a required key that a table
    written too early took (`[phase.learner]` above the phase's `games`)."""
    # msgspec names no place for a key of the file's top ("Object contains unknown field `robot`")
    what, where = _located(message)
    if "[...]" in where:  # a table's value (a key of [phase.learner], a questionnaire's name): named from `raw`
        if raw is None:
            return ""
        where = _name_keys(where, what, raw)
    path = tuple(int(t[1:-1]) if t.startswith("[") else t.lstrip(".")
                 for t in re.findall(r"\[\d+\]|\.?[^.\[]+", where))
    unknown = re.match(r"Object contains unknown field `(.+)`$", what)
    missing = re.match(r"Object missing required field `(.+)`$", what)
    if unknown or missing:
        table, key = path, (unknown or missing).group(1)
        if missing:  # a table below the table's other keys took it: name it there
            node = _at(raw, table)
            child = next((k for k, v in (node or {}).items() if isinstance(v, dict) and key in v), None)
            if child is None or _shape(table + (child,)) not in TABLES:
                return ""
            table, where = table + (child,), f"{where}.{child}"
        where = f"{where}.{key}" if where else key
    elif path and isinstance(path[-1], str) and _shape(path[:-1]) in TABLES:
        table, key = path[:-1], path[-1]
        if "got `object`" in what and isinstance(_at(raw, path), dict) and key in _keys(_shape(table)):
            return f"{where}: {table_not_value(key, _header(path), _header(table))}"
    else:
        return ""
    if _shape(table) not in TABLES:
        return ""
    tables = {_header(tuple(t if t not in ("#", "*") else (0 if t == "#" else (table[1] if len(table) > 1 else "NAME"))
                            for t in shape)): _keys(shape) for shape in TABLES}
    enclosing = [_header(table[:n]) for n in range(len(table) - 1, -1, -1) if _shape(table[:n]) in TABLES]
    said = misplaced(key, _header(table), tables, enclosing, table=isinstance(_at(raw, table + (key,)), dict))
    return f"{where}: {said}" if said else ""


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


def load_study(path: str | Path) -> Study:
    """Read and check a study file (StudyFileError, one line, if it cannot be used)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # an editor's byte order mark is no TOML error
    except (OSError, UnicodeDecodeError) as err:
        raise StudyFileError(f"{path}: cannot read: {getattr(err, 'strerror', None) or err}") from None
    return parse_study(text, str(path))


def example_text() -> str:
    """The shipped example study (the thesis's chapter 7 protocol), as TOML text."""
    return resources.files("pairplay.schemas").joinpath("studies", EXAMPLE).read_text(encoding="utf-8")
