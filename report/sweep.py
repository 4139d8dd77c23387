"""Sweeps of the simulated study: a grid of settings x seeds, each cell reproducible by its seed.

Rule: a sweep is read from a TOML file (`read_grid`): fixed study settings in
[study], lists of values in [grid] (the sweep is their product), and the
seeds (`seeds = 5` for 0..4, or a list). `personas` is a comma-separated
string or a TOML list of names, as fixed in [study] and as each value of a
[grid] axis (`personas = [["blind", "deaf"], ["blind"]]`; the same personas in another order are the same
value, `_axis_value`). Each (setting, seed) is one cell:
`cell_measures` runs the study's training, evaluation (and, with
`reuse = true`, the policy-reuse experiment) through `pairplay.core.study` and
returns plain numbers, so a cell's result depends on its settings and seed
only, wherever it runs. `run_sweep` runs the cells that have no result yet:
in this process (or `workers` local processes), or on a Dask distributed
cluster (`scheduler` = its address); each finished cell is written at once to
cells/<id>.json (atomically), so an interrupted sweep resumes without
recomputing finished cells. Work lost with a worker process or the cluster (a worker
killed, the scheduler gone, a cell failed on a Dask worker) is `WorkerLost` in our words
(`_cell_result`, pairplay/processes.py `result_of`), and a cluster whose workers cannot
load this pairplay is refused before any cell (`check_cluster_pairplay`). A cell file is checked whole when read
(`read_cells`: a msgspec CellFile, its seed and setting the cell's, its
measures exactly the cell's, each a finite number); one that cannot be used
is not a finished cell: it is computed again, with a warning naming the file
and why (a measure that was text ended the summary in a traceback, and
`"measures": {}` counted as finished, the summary's n one short). Then `summarise` folds the cells into one row per
(setting, measure): n, mean, sd and the 95% confidence interval of the mean
(Student's t; clipped to the values the measure can take, `measure_bounds`: a picks-per-round measure's at
18, a perfect round, a ratio's at 0, as report/counterfactual.py's intervals are), and the report writes sweep.csv, cells.csv, one figure per
measure and sweep.md.

Measures (picks per round: 18 is perfect play, lower is better):
  <persona>/learned        mean picks per round of the persona's greedy policies, epsilon 0
  <persona>/oracle         the oracle on the same evaluation games
  <persona>/ratio          learned / oracle
  <persona>/first50        online picks per round over the first 50 training rounds
  <persona>/last50         ... over the last 50 training rounds (a cell of fewer rounds has fewer in
                           each: its names stay, so a rounds axis lines up, and sweep.md says the windows)
  <persona>/reuse_gain     (reuse = true) scratch minus pi-reuse, first 50 rounds, held out
  all/ratio                mean of the personas' ratios
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import logging
import math
import sys
import time
import tomllib
from concurrent.futures import CancelledError
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Callable, Iterable

import msgspec
import numpy as np

from pairplay import csvcell
from pairplay.errors import OptionError, WorkerLost, command_word, escaped, folded
from pairplay.inputs import check_input
from pairplay.nearest import nearest
from pairplay.numbers import counted, shown, type_name, typed_floats
from pairplay.outputs import manifest_name, output_file, output_folder, write_text
from pairplay.processes import check_workers, result_of, worker_pool
from pairplay.schemas.jsonfile import MAX_SAID, empty, in_words, toml_words, without_bom
from pairplay.schemas.tomlplace import TOP, Written, misplaced, table_not_value
from pairplay.core.geometry import PERFECT_PICKS
from pairplay.core.rng import SEED_RANGE
from pairplay.core.study import FIRST_ROUNDS
from pairplay.report.study import SettingError, StudySettings, default_reuse_last
from pairplay.schemas.nesting import json_loads, toml_loads
from pairplay.schemas.repeated import refuse_repeated

log = logging.getLogger("pairplay.sweep")

MAX_CELLS = 10_000  # settings x seeds: each cell is a whole study and a file (`seeds = 100000000` ran out of memory listing them)
SWEEPABLE = {f.name: f.type for f in fields(StudySettings) if f.name not in ("seed", "train_only")}

# Student's t, 97.5% quantile, by degrees of freedom (1..30); above 30 the normal 1.96 is within 2%.
T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145,
        2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048,
        2.045, 2.042)


class GridError(ValueError):
    """A sweep file that cannot be run; the message names the file and the key."""


@dataclass(frozen=True)
class Cell:
    setting: tuple[tuple[str, object], ...]  # the grid's values for this cell, in the grid's key order
    seed: int

    @property
    def id(self) -> str:
        """A digest of the settings and the seed: the cell's file name and its identity across runs."""
        text = json.dumps({"setting": list(self.setting), "seed": self.seed}, sort_keys=True)
        return hashlib.blake2b(text.encode(), digest_size=10).hexdigest()


@dataclass(frozen=True)
class Grid:
    base: dict  # fixed StudySettings fields
    axes: dict  # key -> list of values
    seeds: tuple[int, ...]
    reuse: bool = False

    def settings(self) -> list[tuple[tuple[str, object], ...]]:
        keys = list(self.axes)
        return [tuple(zip(keys, values)) for values in itertools.product(*(self.axes[k] for k in keys))]

    def cells(self) -> list[Cell]:
        return [Cell(s, seed) for s in self.settings() for seed in self.seeds]

    def given(self, cell: Cell) -> dict:
        """The StudySettings fields `cell` sets (the rest are the study's defaults)."""
        given = {**self.base, **dict(cell.setting), "seed": cell.seed}
        if "reuse_last" not in given:  # not in the grid: the study's default for the cell's rounds (50 refused rounds = 20)
            given["reuse_last"] = default_reuse_last(given.get("rounds", StudySettings.rounds))
        return given

    def study_settings(self, cell: Cell) -> StudySettings:
        return StudySettings(**self.given(cell))


def as_toml(value) -> str:
    """A setting's value as the sweep file writes it: numbers as given (`shown`), text quoted."""
    return shown(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else \
        str(value).lower() if isinstance(value, bool) else repr(value)


def _no_setting(key: str, place: str) -> str:
    """`PLACE: no study setting `KEY`` with the one it resembles (else the settings known)."""
    near = nearest(key, SWEEPABLE)  # a misspelt setting
    return (f"{place}: no study setting `{key}`"
            + (f" (did you mean `{near}`?)" if near else f"; known: {', '.join(sorted(SWEEPABLE))}"))


def _axis_value(key: str, value) -> object:
    """What an axis value is, for the grid's repeat check: a `personas` value is the set of personas it
    names, whatever their order ("deaf,blind" is "blind,deaf": each persona's games are seeded by its key,
    core/study.py `train`, and each measure is named by it, so the order changes no number; a trial's
    sweep computed both, twice the work for identical rows); any other value is itself (its repr: 1 is
    not True)."""
    if key == "personas" and isinstance(value, str):
        from pairplay.core.personas import persona
        from pairplay.lists import comma_items

        def known(name: str) -> str:
            try:
                return persona(name).key  # a name and its key are one persona
            except KeyError:  # refused with its own line by the study's check, after this one
                return name

        try:
            return tuple(sorted(map(known, comma_items(value))))  # sorted, not a set: "blind,blind" is its own mistake
        except ValueError:  # `a,,b`: the study's check says it
            return repr(value)
    return repr(value)


def _typed(path: str, at: tuple, value, written: Written):
    """The value of the study setting at `at` (("study", key) or ("grid", key, n)) as its StudySettings field
    takes it; GridError `FILE: [table] key: what` (schemas/tomlplace.py Written), the value as typed."""
    key = at[1]
    want = SWEEPABLE.get(key)
    if want is None:
        raise GridError(f"{path}: {_no_setting(key, written.place(at[:2]))}")
    if key == "personas" and isinstance(value, list) and all(isinstance(v, str) for v in value):
        # a TOML list of names (["ashley", "helmut"]) is the list it says, as the study's "ashley,helmut"
        # (it was refused: "is not a str"); its names are checked as the study's (StudySettings.check)
        if not all(v.strip() and "," not in v for v in value):
            raise GridError(f"{path}: {written.place(at[:2])}: {written.typed(at, value)}: each item of the list is "
                            "one persona's name")
        value = ",".join(value)
    kind = {"int": int, "float": (int, float), "str": str, "bool": bool}[want if isinstance(want, str) else want.__name__]
    if isinstance(value, bool) and kind is not bool or not isinstance(value, kind):
        raise GridError(f"{path}: {written.place(at[:2])}: must be {type_name(want)}, got {written.typed(at, value)}")
    return float(value) if want in ("float", float) else value


# the file's tables and the keys each takes (schemas/tomlplace.py)
PLACES = {TOP: frozenset({"study", "grid", "seeds", "reuse"}), "[study]": frozenset(SWEEPABLE),
          "[grid]": frozenset(SWEEPABLE)}


def _check_places(path: str, data: dict, written: Written) -> None:
    """GridError for a key or a table at the wrong level: `seeds` or `reuse` below the [study] or [grid]
    line (that table's then; it was "unknown study setting 'seeds'"), a study setting above them (it was
    "unknown key(s) psi"), a [study.psi] table where psi takes a value, `study = 3` where a table is
    expected (a traceback)."""
    for key, value in data.items():
        if key in ("study", "grid") and not isinstance(value, dict):
            raise GridError(f"{path}: {key}: a value where a table is expected: write a [{key}] line, its keys below it")
        if key in ("seeds", "reuse") and isinstance(value, dict):
            raise GridError(f"{path}: {written.place((key,))}: {table_not_value(key, f'[{key}]', TOP)}")
        said = misplaced(key, TOP, PLACES)  # a study setting above the [study] or [grid] line
        if said:
            raise GridError(f"{path}: {written.place((key,))}: {said}")
    for table in ("study", "grid"):
        for key, value in data.get(table, {}).items():
            said = misplaced(key, f"[{table}]", PLACES, [TOP], table=isinstance(value, dict))
            if not said and isinstance(value, dict):
                said = table_not_value(key, f"[{table}.{key}]", f"[{table}]")
            if said:
                raise GridError(f"{path}: {written.place((table, key))}: {said}")


def read_grid(path: str | Path) -> Grid:
    """The sweep described by a TOML file (GridError naming the file and the key; a number it echoes, as the
    file has it: pairplay/numbers.py typed_floats)."""
    with typed_floats() as parse_float:
        return _read_grid(str(path), parse_float)


def _read_grid(path: str, parse_float) -> Grid:
    check_input(path, GridError)  # before opening: a pipe blocked (pairplay/inputs.py)
    try:
        with open(path, "rb") as f:
            raw = f.read()
        if empty(raw):  # (read as a grid of nothing, it ran the default study, exit 0: a new user's trial)
            raise GridError(f"{path}: {empty(raw)}")
        text = without_bom(raw).decode("utf-8")
        data = toml_loads(text, parse_float=parse_float)
    except FileNotFoundError:
        raise GridError(f"{path}: no such file") from None
    except IsADirectoryError:  # it said `Is a directory (bad)`: the system's words, not what to give
        raise GridError(f"{path}: a folder, not a sweep file: give the grid's TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise GridError(f"{path}: not TOML: {toml_words(exc, text)}") from None
    except UnicodeDecodeError:  # tomllib decodes bytes itself: a binary file was a traceback
        raise GridError(f"{path}: not TOML (not UTF-8 text)") from None
    written = Written(text, data)  # the file's places and values in its own words (schemas/tomlplace.py)
    _check_places(path, data, written)
    # every unknown key at once, the file's top first (one a run, fixed and rerun for the next, was a trial)
    unknown = []
    for key in [k for k in data if k not in ("study", "grid", "seeds", "reuse")]:
        near = nearest(key, ["seeds", "reuse"])
        unknown.append(f"{written.place((key,))}: no such key at {TOP}"
                       + (f" (did you mean `{near}`?)" if near else "; it takes [study], [grid], seeds, reuse"))
    unknown += [_no_setting(key, written.place((table, key))) for table in ("study", "grid")
                for key in data.get(table, {}) if key not in SWEEPABLE]
    if unknown:
        raise GridError(f"{path}: {'; '.join(unknown[:MAX_SAID])}"
                        + (f"; and {len(unknown) - MAX_SAID} more" if len(unknown) > MAX_SAID else ""))
    base = {k: _typed(path, ("study", k), v, written) for k, v in data.get("study", {}).items()}
    axes = {}
    for k, values in data.get("grid", {}).items():
        if not isinstance(values, list) or not values:
            raise GridError(f"{path}: {written.place(('grid', k))}: must be a non-empty list of values, "
                            f"got {written.typed(('grid', k), values)}")
        axes[k] = [_typed(path, ("grid", k, n), v, written) for n, v in enumerate(values)]
        same = [_axis_value(k, v) for v in axes[k]]
        again = next((n for n, v in enumerate(same) if v in same[:n]), None)
        if again is not None:
            first = same.index(same[again])
            said = written.typed(("grid", k, again), values[again])
            if repr(axes[k][first]) != repr(axes[k][again]):  # the same personas in another order
                said += (f" = {written.typed(('grid', k, first), values[first])}: the same personas in another "
                         "order, the same cells")
            raise GridError(f"{path}: {written.place(('grid', k))}: repeats a value ({said})")
    clash = sorted(set(base) & set(axes))
    if clash:
        raise GridError(f"{path}: {written.place(('grid', clash[0]))}: both fixed in [study] and swept in [grid]")
    seeds = data.get("seeds", 5)
    settings = math.prod(len(v) for v in axes.values())
    typed = written.typed
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if seeds < 1:
            raise GridError(f"{path}: seeds = {typed(('seeds',), seeds)}: give a count of at least 1 or a list of seeds")
        if seeds * settings > MAX_CELLS:
            raise GridError(f"{path}: seeds = {typed(('seeds',), seeds)}: {counted(settings, 'setting')} x "
                            f"{counted(seeds, 'seed')} is over the {MAX_CELLS} cells a sweep may have")
        seeds = list(range(seeds))
    if isinstance(seeds, list) and len(seeds) * settings > MAX_CELLS:
        raise GridError(f"{path}: [grid]: {counted(settings, 'setting')} x {counted(len(seeds), 'seed')} is over the {MAX_CELLS} cells "
                        "a sweep may have")
    lo, hi = SEED_RANGE
    if not isinstance(seeds, list) or not seeds:
        raise GridError(f"{path}: seeds: must be a count or a list of seeds {lo}..{hi}, got {typed(('seeds',), seeds)}")
    bad = next((n for n, s in enumerate(seeds) if not (isinstance(s, int) and not isinstance(s, bool) and lo <= s <= hi)), None)
    if bad is not None:
        raise GridError(f"{path}: seeds: must be a count or a list of seeds {lo}..{hi}, "
                        f"got {typed(('seeds', bad), seeds[bad])}")
    if len(set(seeds)) != len(seeds):
        again = next(n for n, s in enumerate(seeds) if s in seeds[:n])
        raise GridError(f"{path}: seeds: repeats a seed ({typed(('seeds', again), seeds[again])})")
    reuse = data.get("reuse", False)
    if not isinstance(reuse, bool):  # `reuse = "no"` was taken as true
        raise GridError(f"{path}: reuse: must be true or false, got {typed(('reuse',), reuse)}")
    grid = Grid(base, axes, tuple(seeds), reuse)
    for s in grid.settings():  # every cell's settings, before any cell runs: each must make the study asked for
        given = grid.given(Cell(s, grid.seeds[0]))
        try:  # each setting alone is checked as StudySettings is made, the rest by check
            personas = StudySettings(**given).check(speed_up=grid.reuse, compare_learners=False,
                                                    given={*base, *dict(s)})
        except SettingError as exc:
            value = given.get(exc.key, getattr(StudySettings, exc.key))
            # where the value came from, as the file has it (a TOML 2 became 2.0 for a float setting, 1_000 1000:
            # pairplay/numbers.py, schemas/tomlplace.py); a setting the file does not give is the study's default
            at = ("study", exc.key) if exc.key in base else _axis_at(exc.key, value, axes) if exc.key in axes else None
            said = typed(at, _at(data, at)) if at else as_toml(value)
            what = exc.what
            for parsed in dict.fromkeys((shown(value), str(value), repr(value))):  # its "got 1000": as typed
                if what.endswith(f"got {parsed}"):
                    what = what[:-len(parsed)] + said
            place = f"{written.place(at[:2])} = {said}" if at else f"{exc.key} = {said} (the study's default)"
            values = [f"{k} = {typed(_axis_at(k, v, axes), _at(data, _axis_at(k, v, axes)))}" for k, v in s]
            cell = f" (cell {', '.join(values)})" if s else ""
            raise GridError(f"{path}: {place}: {what}{cell}") from None
        if grid.reuse and len(personas) < 2:
            raise GridError(f"{path}: reuse: reuse = true needs at least 2 personas (one is held out)")
    return grid


def _axis_at(key: str, value, axes: dict) -> tuple:
    """The place in the file of a [grid] axis's value: ("grid", key, index)."""
    return ("grid", key, next(n for n, v in enumerate(axes[key]) if repr(v) == repr(value)))


def _at(data: dict, at: tuple):
    """The TOML read's value at `at` (("study", key) or ("grid", key, n))."""
    return data[at[0]][at[1]] if len(at) == 2 else data[at[0]][at[1]][at[2]]


def cell_measures(settings: StudySettings, reuse: bool = False) -> dict[str, float]:
    """The measures of one cell (see the module rule): a pure function of `settings`."""
    from pairplay.core import study
    from pairplay.schemas.config import LearnerConfig

    personas = settings.persona_list()
    config = LearnerConfig()
    training = study.train(personas, settings.games, settings.rounds, settings.seed, config,
                           reward_bonus=settings.reward_bonus, algorithm=settings.algorithm, lspi=settings.lspi())
    cmp = study.compare(personas, training, settings.eval_rounds, settings.seed, reward_bonus=settings.reward_bonus)
    out: dict[str, float] = {}
    picks = training.result.picks
    for i, p in enumerate(personas):
        rows = [j for j, q in enumerate(training.personas) if q.key == p.key]
        out[f"{p.key}/learned"] = float(cmp.learned[i])
        out[f"{p.key}/oracle"] = float(cmp.oracle[i])
        out[f"{p.key}/ratio"] = float(cmp.learned[i] / cmp.oracle[i])
        out[f"{p.key}/first50"] = float(picks[rows, :FIRST_ROUNDS].mean())  # fewer rounds: all (windows_note)
        out[f"{p.key}/last50"] = float(picks[rows, -FIRST_ROUNDS:].mean())
    out["all/ratio"] = float(np.mean([out[f"{p.key}/ratio"] for p in personas]))
    if reuse:
        users = study.user_set(personas, training, settings.seed, settings.trained_updates)
        reuse_config = LearnerConfig(psi_start=settings.psi, psi_decay=settings.psi_decay,
                                     reuse_rounds=max(0, settings.rounds - settings.reuse_last))
        result = study.reuse_experiment(personas, users, dict(zip(cmp.persona, cmp.oracle)), settings.reuse_seeds,
                                        settings.rounds, settings.seed, reuse_config,
                                        reward_bonus=settings.reward_bonus)
        for i, key in enumerate(result.persona):
            out[f"{key}/reuse_gain"] = float(result.first50[i, 0].mean() - result.first50[i, 1].mean())
    return out


def _run_cell(grid: Grid, cell: Cell) -> tuple[str, dict]:
    return cell.id, cell_measures(grid.study_settings(cell), grid.reuse)


def _run_cell_alone(grid: Grid, cell: Cell) -> tuple[str, dict]:
    """`_run_cell` on one thread: the local processes already use every core (core/threads.py)."""
    from pairplay.core import threads
    with threads.at_most(1):
        return _run_cell(grid, cell)


def _write_json_atomic(path: Path, data: dict) -> None:
    """`data` to `path` whole or not at all (pairplay.outputs: its temporary file is removed on any
    error or signal, and a full disk's OSError names `path`; before, it named nothing and left the
    temporary file)."""
    write_text(path, json.dumps(data, sort_keys=True, indent=1), force=True)


PER_PERSONA = ("learned", "oracle", "ratio", "first50", "last50")  # each persona's measures (the module rule)


def measure_names(settings: StudySettings, reuse: bool) -> frozenset[str]:
    """The measures `cell_measures(settings, reuse)` gives: a cell file must hold exactly these."""
    keys = [p.key for p in settings.persona_list()]
    names = {f"{k}/{m}" for k in keys for m in PER_PERSONA + (("reuse_gain",) if reuse else ())}
    return frozenset(names | {"all/ratio"})


class CellFile(msgspec.Struct, forbid_unknown_fields=True):
    """cells/<id>.json as `run_sweep` writes it: the cell's grid values, its seed, its measures."""
    setting: list[tuple[str, Any]]
    seed: int
    measures: dict[str, Any]  # each a finite number, checked by `_check_cell` naming the measure (msgspec: "$.measures[...]")


def _check_cell(path: Path, grid: Grid, cell: Cell) -> dict[str, float]:
    """The measures of the cell file at `path`, or ValueError saying why it cannot be used: not JSON,
    not a cell (msgspec: a measure that is text, a field missing), another cell's setting or seed, a
    measure missing or one this cell has not (`"measures": {}` was taken as finished: the summary's n
    silently one short), or one that is not a finite number."""
    data = path.read_bytes()
    if empty(data):
        raise ValueError(empty(data))
    try:
        refuse_repeated(without_bom(data))  # a measure given twice: json would keep the last, silently
        found = msgspec.convert(json_loads(without_bom(data)), CellFile)  # json: NaN is read, then refused below
    except ValueError as err:  # json.JSONDecodeError, msgspec.ValidationError (in the file's words: in_words)
        raise ValueError(f"not a cell file: {folded(in_words(err, CellFile))}") from None
    if found.seed != cell.seed or found.setting != [tuple(kv) for kv in json.loads(json.dumps(cell.setting))]:
        raise ValueError("holds another cell's setting or seed")
    want = measure_names(grid.study_settings(cell), grid.reuse)
    missing, extra = sorted(want - set(found.measures)), sorted(set(found.measures) - want)
    if missing or extra:
        raise ValueError("; ".join(([f"lacks measure(s) {', '.join(missing)}"] if missing else [])
                                   + ([f"has measure(s) no cell of this grid has: {', '.join(extra)}"] if extra else [])))
    odd = [f"{k} = {v!r}" for k, v in sorted(found.measures.items())
           if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)]
    if odd:
        raise ValueError(f"measure(s) not a finite number: {', '.join(odd)}")
    return {k: float(v) for k, v in found.measures.items()}


def is_cell_file(path: Path) -> bool:
    """Whether `path` is a cell file a sweep wrote, of any grid: a CellFile named by its own cell's id (the
    digest of the setting and seed it holds), which a user's file of a cell-like name is not by chance. Why
    not a manifest (pairplay/outputs.py): cells are written one by one as each finishes, and a stopped sweep's
    are kept to resume from, so a list written at the end would miss them; each cell file says what it is."""
    try:
        data = without_bom(path.read_bytes())
        refuse_repeated(data)
        found = msgspec.convert(json_loads(data), CellFile)
    except (OSError, ValueError, RecursionError):  # not readable, not JSON, not a cell
        return False
    return Cell(tuple(tuple(kv) for kv in found.setting), found.seed).id == path.stem


def read_cells(out: Path, grid: Grid) -> tuple[dict[str, dict], dict[Path, str]]:
    """The results on disk for this grid's cells (id -> measures), each file checked whole
    (`_check_cell`), and the files of this grid's cells that could not be used (path -> why):
    those cells are not finished. Files of other cells are left alone (--force removes another
    grid's)."""
    done, invalid = {}, {}
    wanted = {c.id: c for c in grid.cells()}
    for path in sorted((out / "cells").glob("*.json")):
        if path.stem not in wanted:
            continue
        try:
            done[path.stem] = _check_cell(path, grid, wanted[path.stem])
        except (OSError, ValueError) as err:
            invalid[path] = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
    return done, invalid


def finished_cells(out: Path, grid: Grid) -> dict[str, dict]:
    """Results already on disk for this grid's cells: id -> measures (`read_cells`: an unusable file is
    not a finished cell)."""
    return read_cells(out, grid)[0]


@dataclass
class SweepRun:
    cells: int
    computed: int  # cells computed in this run (the others were on disk)
    wall_s: float
    where: str


def check_sweep_memory(grid: Grid, workers: int) -> None:
    """OptionError (naming --workers) if `workers` local processes, each running a cell, could hold more
    than core/simulate.py MEMORY_LIMIT at once: each cell is checked against the limit alone
    (StudySettings.check_memory), and `--workers 8` ran eight of them side by side (8 x 2 GB)."""
    from pairplay.core.simulate import MEMORY_LIMIT, gigabytes

    at_once = min(workers, len(grid.cells()))
    if at_once <= 1:
        return
    settings = [grid.study_settings(Cell(s, grid.seeds[0])) for s in grid.settings()]
    cell = max(st.memory_bytes(len(st.persona_list()), grid.reuse, False) for st in settings)
    if cell * at_once > MEMORY_LIMIT:
        fit = max(1, MEMORY_LIMIT // max(cell, 1))
        raise OptionError(f"{counted(at_once, 'worker')} would hold about {gigabytes(cell * at_once)} of memory at once "
                          f"({counted(at_once, 'cell')} of up to {gigabytes(cell)}), over the {gigabytes(MEMORY_LIMIT)} allowed: "
                          f"give --workers {fit} or fewer", f"--workers {workers}")


SCHEDULER_TIMEOUT_S = 10  # how long a --scheduler has to answer, its handshake included


# the schemes a --scheduler may use: tls:// and wss:// need a security configuration (certificates) sweep does
# not take, inproc:// is one process's own, ucx:// needs UCX (Dask's connector for it could not even start)
SCHEMES = ("tcp", "ws")


def _scheduler_refused(address: str, what: str) -> OptionError:
    """The one line of a --scheduler where no scheduler can be reached: what happened, then the fix."""
    return OptionError(f"{what}: give the address a Dask scheduler prints at its start, tcp://HOST:PORT",
                       f"--scheduler {address}")


def check_scheduler(address: str) -> None:
    """OptionError naming --scheduler and `address` unless a Dask scheduler answers there within
    SCHEDULER_TIMEOUT_S of wall-clock time: connected, the comm handshake done, and its `identity`
    saying Scheduler. Dask's own Client timeout covers the connect only: at a port whose service
    waits for a request (`python3 -m http.server`) its handshake waited for ever, at one that sends
    bytes first (an SSH banner) it read them as a frame length and asked for 3 EiB (MemoryError: the
    line said "out of memory"), and a word with no port (`nonsense`) was a ValueError's traceback.
    Dask's connect retries a refused connection until its timeout (a closed port took the whole 10 s),
    so a plain socket connects first: refused, an unknown host, an unreachable network fail at once.
    Every way the probe can fail is the one line, in our words: a wrong address is the user's to fix."""
    import asyncio
    import socket

    def refuse(what: str) -> OptionError:
        return _scheduler_refused(address, what)

    try:
        from distributed.comm import connect
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.core import CommClosedError
        from distributed.comm.registry import get_backend
    except ImportError:  # a plain install has no Dask (a trial: a traceback)
        raise OptionError("a Dask cluster needs Dask's distributed package: pip install -e '.[cluster]'",
                          "--scheduler") from None

    try:
        scheme, location = parse_address(address)
        get_backend(scheme)  # foo://host:1: "unknown address scheme"
    except (ValueError, TypeError):
        raise refuse(f"not a Dask address (unknown scheme {address.partition('://')[0]}://)") from None
    if scheme not in SCHEMES:
        raise refuse(f"sweep reaches a scheduler over {' or '.join(s + '://' for s in SCHEMES)}, not {scheme}://")
    try:
        host, port = parse_host_port(location)
    except (ValueError, TypeError):  # `nonsense`, `tcp://localhost`: no port
        raise refuse(f"not a Dask address (HOST:PORT expected after {scheme}://, got {location!r})") from None
    if not host:
        raise refuse(f"not a Dask address (no host before :{port})")
    if not 1 <= port <= 65535:
        raise refuse(f"not a Dask address (port {port} is not 1..65535)")

    async def identity(timeout: float) -> dict:
        comm = await connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def probe() -> dict:
        deadline = time.monotonic() + SCHEDULER_TIMEOUT_S
        with socket.create_connection((host, port), timeout=SCHEDULER_TIMEOUT_S):
            pass  # something listens: now Dask's own handshake, in the time left
        left = max(deadline - time.monotonic(), 0.1)
        return asyncio.run(asyncio.wait_for(identity(left), left))

    try:
        try:
            asyncio.get_running_loop()
        except RuntimeError:  # none (the command line): probe on this thread, a signal ends it at once
            said = probe()
        else:  # called from a running loop (a notebook): asyncio.run must have a thread of its own
            from concurrent.futures import ThreadPoolExecutor
            with ThreadPoolExecutor(1) as pool:
                said = pool.submit(probe).result()
    except ConnectionRefusedError:
        raise refuse("nothing listens at that address (connection refused)") from None
    except socket.gaierror:
        raise refuse(f"the host {host} is not known (no address found for it)") from None
    except (TimeoutError, asyncio.TimeoutError):  # socket.timeout too; Dask's connect says "Timed out" below
        raise refuse(f"no Dask scheduler answered within {SCHEDULER_TIMEOUT_S} s") from None
    except MemoryError:  # its first bytes, read as a Dask frame's length, asked for exbibytes
        raise refuse("something that is not a Dask scheduler answered "
                     "(bytes that are no Dask message)") from None
    except CommClosedError:  # (an OSError) the other end closed the connection in the handshake
        raise refuse("something that is not a Dask scheduler answered "
                     "(it closed the connection)") from None
    except OSError as err:
        if "timed out" in str(err).lower():  # Dask's connect: "Timed out trying to connect to ... after 10 s"
            raise refuse(f"no Dask scheduler answered within {SCHEDULER_TIMEOUT_S} s") from None
        why = err.strerror or folded(err) or type(err).__name__  # "Network is unreachable"
        raise refuse(f"cannot connect ({why})") from None
    except Exception as err:  # noqa: BLE001 - whatever else the other end did: the address is wrong
        why = folded(err)
        raise refuse(f"no Dask scheduler answered ({type(err).__name__}{': ' + why if why else ''})"
                     ) from None
    kind = said.get("type") if isinstance(said, dict) else None
    if kind != "Scheduler":
        raise refuse(f"a Dask {kind}, not a scheduler, answered" if isinstance(kind, str)
                     else "something that is not a Dask scheduler answered")


NO_WORKER_S = 30.0  # how long a sweep waits for a cluster with no worker (none yet, or every one lost) before it stops
WORKER_POLL_S = 1.0  # how often a sweep waiting for its cells asks the scheduler how many workers it has
ERROR_SAID = 200  # the most of a worker's exception text a line shows (one line, not a traceback's worth)


def _finished_while_workers(client, address: str, futures: list, kept: Callable[[], int], total: int,
                            cells: Path) -> Iterable:
    """Each future of `futures` as it finishes, for as long as the cluster has a worker to run them.

    A scheduler answers with no worker at all (none started, or every one gone: a cluster whose workers
    died overnight) and its tasks wait for ever: a trial's sweep printed nothing for 10 minutes. So the
    wait wakes every WORKER_POLL_S to ask the scheduler for its workers; with none, it says so once on
    stderr, and after NO_WORKER_S with none it raises OptionError naming --scheduler, how many cells are
    kept (`kept()` of `total`, in `cells`; "none kept" when none: that folder is gone once the sweep ends)
    and that the same command resumes from them. A worker that joins in time ends the wait; nothing is said
    of one that comes back within a poll."""
    from dask.distributed import wait

    pending = set(futures)
    alone_since = None
    while pending:
        try:
            done, pending = wait(pending, timeout=WORKER_POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        except CancelledError:  # FuturesCancelledError: the scheduler lost ("scheduler-connection-lost")
            raise _scheduler_lost(address) from None
        yield from done
        if done or not pending:
            alone_since = None
            continue
        try:
            workers = client.nthreads()
        except OSError:  # CommClosedError, a timeout: the scheduler is gone (its cancelled futures say it too)
            raise _scheduler_lost(address) from None
        if workers:
            alone_since = None
            continue
        now = time.monotonic()
        if alone_since is None:
            alone_since = now
            print(f"pairplay sweep: the Dask scheduler at {escaped(address)} has no worker to run the cells; waiting up "
                  f"to {NO_WORKER_S:g} s for one (`dask worker {command_word(address)}` starts one)", file=sys.stderr, flush=True)
        elif now - alone_since >= NO_WORKER_S:
            finished = kept()  # none: the empty folder is removed on the way out, so no folder is named
            said = (f"{finished} of {counted(total, 'cell')} finished, kept in {cells}: start a worker (`dask worker "
                    f"{command_word(address)}`) and the same command resumes from them") if finished else \
                (f"0 of {counted(total, 'cell')} finished (none kept): start a worker (`dask worker "
                 f"{command_word(address)}`) and run the same command again")
            raise OptionError(f"the Dask scheduler there has had no worker for {NO_WORKER_S:g} s; {said}",
                              f"--scheduler {address}")


def _scheduler_lost(address: str) -> WorkerLost:
    return WorkerLost(f"the Dask scheduler at {address} stopped answering (connection lost)")


def _cell_result(future, address: str, by_id: dict[str, Cell]) -> tuple[str, dict]:
    """A Dask cell's (id, measures); each way the cluster can lose it is WorkerLost in our words (Dask's
    were two tracebacks, exit 1): the scheduler gone (the future cancelled, "scheduler-connection-lost"),
    a cell whose workers died one after another (KilledWorker: the cell is named, it may need more memory
    than a worker has), or the cell's own exception on a worker (out of memory there, say: its type and
    message, and which cell; `check_cluster_pairplay` has refused a worker without this pairplay before)."""
    from distributed.client import FutureCancelledError
    from distributed.scheduler import KilledWorker

    cell = by_id.get(str(future.key).removeprefix("pairplay-cell-"))
    which = f"cell {cell.id} ({setting_label(cell.setting)}, seed {cell.seed})" if cell else f"task {future.key}"
    try:
        return future.result()
    except FutureCancelledError:
        raise _scheduler_lost(address) from None
    except KilledWorker:
        raise WorkerLost(f"{which} killed every Dask worker that ran it (Dask's KilledWorker: it may need more "
                         "memory than a worker has)") from None
    except Exception as err:  # noqa: BLE001 - raised on a worker: said, with where it ran (never a bug of ours here)
        why = folded(err)[:ERROR_SAID]
        raise WorkerLost(f"{which} failed on a Dask worker: {type(err).__name__}{': ' + why if why else ''} "
                         "(its traceback is in the worker's log)") from None


# what each Dask worker evaluates before any cell: the module a cell runs in, and the version that answers
WORKER_LOADS = "__import__('pairplay.report.sweep').__version__"


def check_cluster_pairplay(client, address: str) -> None:
    """OptionError naming --scheduler unless every worker of the cluster loads this pairplay (README: the
    workers need it installed). A worker that could not (not installed there, or broken) failed to read
    its first cell and died, its error only in its own log; the sweep then waited, saying nothing, or
    that the cluster had no worker (a trial). Asked with `eval` of WORKER_LOADS, a builtin a worker
    unpickles without pairplay; another version is refused too: its cells would not be this one's."""
    from pairplay import __version__

    try:
        said = client.run(eval, WORKER_LOADS, on_error="return")
    except OSError:
        raise _scheduler_lost(address) from None
    for worker, got in sorted(said.items()):
        if isinstance(got, BaseException):
            why = folded(got)[:ERROR_SAID]
            what = f"cannot load pairplay ({type(got).__name__}{': ' + why if why else ''})"
        elif got != __version__:
            what = f"has pairplay {shown(got)}, not this {__version__}"
        else:
            continue
        raise OptionError(f"the Dask worker {worker} {what}: install pairplay {__version__} where the workers run "
                          "(pip install -e '.[cluster]'), then the same command", f"--scheduler {address}")


@contextlib.contextmanager
def _dask_quiet() -> Iterable[None]:
    """Dask's own log lines off the terminal while a sweep waits on its cluster: a scheduler lost printed
    Dask's ERROR traceback before the sweep's one line (`_cell_result` says what happened)."""
    def not_dasks(record: logging.LogRecord) -> bool:
        return record.name.partition(".")[0] not in ("distributed", "tornado")

    # on the handlers, not the loggers: Dask's config gives its loggers levels of their own (distributed.client)
    handlers = list(logging.root.handlers)
    for handler in handlers:
        handler.addFilter(not_dasks)
    try:
        yield
    finally:
        for handler in handlers:
            handler.removeFilter(not_dasks)


def run_sweep(grid: Grid, out: str | Path, *, scheduler: str | None = None, workers: int = 1,
              progress: Callable[[int], None] | None = None) -> SweepRun:
    """Compute every cell of `grid` that `out`/cells/ does not hold yet; see the module rule.

    `scheduler`: a Dask distributed scheduler address (tcp://host:port), or None to
    run here (`workers` > 1: that many local processes)."""
    if scheduler is None:
        check_workers(workers)  # before anything is written
        check_sweep_memory(grid, workers)
    out = Path(out)
    (out / "cells").mkdir(parents=True, exist_ok=True)
    cells = grid.cells()
    done, invalid = read_cells(out, grid)
    for path, why in invalid.items():  # said, then computed again (it was done without a word, or not at all)
        log.warning("%s: %s: computing the cell again", path, why)
    todo = [c for c in cells if c.id not in done]
    by_id = {c.id: c for c in cells}
    start = time.perf_counter()

    def store(cid: str, measures: dict) -> None:
        cell = by_id[cid]
        _write_json_atomic(out / "cells" / f"{cid}.json",
                           {"setting": [list(kv) for kv in cell.setting], "seed": cell.seed, "measures": measures})
        if progress:
            progress(1)

    if scheduler:
        from dask.distributed import Client
        check_scheduler(scheduler)  # the whole handshake within the timeout (Client's covers the connect only)
        try:
            client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
        except OSError:  # it answered the check a moment ago (a new user's trial: "Timed out trying to connect ..." alone)
            raise _scheduler_refused(scheduler, "the Dask scheduler there stopped answering") from None
        with _dask_quiet(), client:
            check_cluster_pairplay(client, scheduler)  # before any cell: a worker without it dies on its first
            futures = [client.submit(_run_cell, grid, c, key=f"pairplay-cell-{c.id}", pure=True) for c in todo]
            for future in _finished_while_workers(client, scheduler, futures, lambda: len(finished_cells(out, grid)),
                                                  len(cells), out / "cells"):
                store(*_cell_result(future, scheduler, by_id))
        where = f"dask {scheduler}"
    elif workers > 1:
        from concurrent.futures import as_completed as done_first
        with worker_pool(workers) as pool:
            for future in done_first([pool.submit(_run_cell_alone, grid, c) for c in todo]):
                store(*result_of(pool, future))  # a worker killed (out of memory): WorkerLost, not a traceback
        where = f"{counted(workers, 'local process', 'local processes')}"
    else:
        for c in todo:
            store(*_run_cell(grid, c))
        where = "this process"
    return SweepRun(len(cells), len(todo), time.perf_counter() - start, where)


def t975(n: int) -> float:
    """Student t quantile 0.975 for a mean of n values (n - 1 degrees of freedom; 1.96 beyond the table)."""
    return T975[n - 2] if 2 <= n <= len(T975) + 1 else 1.96


# the bounds of a mean of picks per round: no round takes fewer than 18 picks (a perfect one), so an interval of
# such a mean stops there (report/counterfactual.py's module rule says why a clip keeps the interval's coverage)
PICKS = (float(PERFECT_PICKS), math.inf)
PICKS_MEASURES = ("learned", "oracle", "first50", "last50")  # the per-persona measures counted in picks per round


def measure_bounds(measure: str) -> tuple[float, float]:
    """The values a sweep measure can take: PICKS for a count of picks per round, 0 and above for a ratio of two
    (learned / oracle), any for a difference (reuse_gain)."""
    kind = measure.split("/")[-1]
    return PICKS if kind in PICKS_MEASURES else (0.0, math.inf) if kind == "ratio" else (-math.inf, math.inf)


def summarise(grid: Grid, results: dict[str, dict]) -> list[dict]:
    """One row per (setting, measure): the setting's values, measure, n, mean, sd, ci95_low, ci95_high.

    Rows are in the grid's order, measures sorted; sd is the sample sd (n - 1)."""
    rows = []
    for setting in grid.settings():
        per_seed = [results[Cell(setting, s).id] for s in grid.seeds]
        for measure in sorted(set().union(*per_seed)):
            values = np.array([m[measure] for m in per_seed if measure in m], dtype=float)
            n = len(values)
            mean = float(values.mean())
            sd = float(values.std(ddof=1)) if n > 1 else 0.0
            half = t975(n) * sd / math.sqrt(n) if n > 1 else 0.0
            floor, ceiling = measure_bounds(measure)
            rows.append({**dict(setting), "measure": measure, "n": n, "mean": mean, "sd": sd,
                         "ci95_low": max(mean - half, floor), "ci95_high": min(mean + half, ceiling)})
    return rows


def setting_label(setting: Iterable[tuple[str, object]]) -> str:
    return ", ".join(f"{k}={v}" for k, v in setting) or "(no grid)"


def windows_note(grid: Grid) -> str:
    """What first50 and last50 average in the cells shorter than 100 rounds ("" if none is): a 40-round
    study's first50 and last50 were both its 40 rounds, the same value under two names (a trial)."""
    n = FIRST_ROUNDS
    short = sorted({s.rounds for s in map(grid.study_settings, grid.cells()) if s.rounds < 2 * n})
    if not short:
        return ""
    said = "; ".join(f"rounds = {r}: the first and last {min(r, n)} of {r}" + (" (both all of them: one value)"
                                                                               if r <= n else "") for r in short)
    return f" first{n} and last{n} average the first and last {counted(n, 'training round')}, fewer in a shorter cell: {said}."


# the summary's files (pairplay/outputs.py `owned`) and its manifest, the ones a run wrote: the summary is written
# whole each time, so an earlier run's that this one does not write again are removed (a forced sweep of another
# grid left the first grid's figures beside the new ones), never a user's file of such a name
SWEEP_OUTPUTS = ("sweep.csv", "cells.csv", "sweep.md", "figures/*.png")
MANIFEST = manifest_name("sweep")


def write_sweep(out: str | Path, grid: Grid, results: dict[str, dict], run: SweepRun,
                keep: Iterable[str] = ()) -> list[Path]:
    """sweep.csv (the summary), cells.csv (every cell and seed), one figure per measure, sweep.md: all
    written beside `out` and moved in together (pairplay.outputs.output_folder, `among_others`: cells/ and
    grid.toml stay), so a signal or a full disk part way leaves the earlier summary whole, never a new
    sweep.csv beside an old sweep.md; the figures an earlier summary drew that this one does not (another
    grid's measures) are removed (`SWEEP_OUTPUTS`, `MANIFEST`). `keep`: summary files (relative paths) that
    stay as they are in `out` (a resume with nothing to compute writes again only what is missing or
    unreadable, `summary_to_write`: sweep.md keeps what the run that did the work said); each is copied
    into the staged summary, so it is one of this run's files, not an earlier run's stale one."""
    import shutil

    out = Path(out)
    with output_folder(out, force=True, owned=SWEEP_OUTPUTS, among_others=True, manifest=MANIFEST) as staged:
        written = _write_summary(staged, grid, results, run)
        for rel in keep:
            if (out / rel).is_file() and (staged / rel).is_file():
                shutil.copy2(out / rel, staged / rel)  # its bytes and time, as they were
    return [out / p.relative_to(staged) for p in written]


PNG = b"\x89PNG\r\n\x1a\n"  # the first bytes of every PNG file


def _header_line(row: list[str]) -> str:
    import io

    text = io.StringIO(newline="")
    csvcell.writer(text).writerow(row)
    return text.getvalue()


def summary_files(grid: Grid, results: dict[str, dict]) -> dict[str, Callable[[bytes], bool]]:
    """The files `write_sweep` writes for `results` (relative paths), each with the test its bytes pass
    when it can be read as what it is: a table's header row, sweep.md's title, a figure's PNG signature."""
    keys = list(grid.axes)
    files: dict[str, Callable[[bytes], bool]] = {
        "sweep.csv": lambda b: b.startswith(_header_line(
            [*keys, "measure", "n", "mean", "sd", "ci95_low", "ci95_high"]).encode()),
        "cells.csv": lambda b: b.startswith(_header_line(["cell", *keys, "seed", "measure", "value"]).encode()),
        "sweep.md": lambda b: b.startswith(b"# pairplay sweep\n"),
    }
    for measure in sorted({r["measure"] for r in summarise(grid, results)}):
        files[f"figures/{figure_name(measure)}"] = lambda b: b.startswith(PNG)
    return files


def summary_to_write(out: Path, grid: Grid, results: dict[str, dict]) -> list[str]:
    """The summary files of a finished sweep in `out` that a resume writes again: those missing, or that
    cannot be read as what they are (no permission to read, a junk sweep.md, a truncated figure); the
    others stay as they are (a resume with all of them there said "nothing to do"; one with a figure
    deleted said so too, and the figure stayed missing)."""
    redo = []
    for rel, readable in summary_files(grid, results).items():
        try:
            ok = (out / rel).is_file() and readable((out / rel).read_bytes())
        except OSError:
            ok = False
        if not ok:
            redo.append(rel)
    return redo


def figure_name(measure: str) -> str:
    """The file of `measure`'s figure in figures/ (`all/ratio`: all-ratio.png)."""
    return measure.replace("/", "-") + ".png"


def _write_summary(out: Path, grid: Grid, results: dict[str, dict], run: SweepRun) -> list[Path]:
    from pairplay.report import plots

    rows = summarise(grid, results)
    keys = list(grid.axes)
    written = [out / "sweep.csv", out / "cells.csv", out / "sweep.md"]
    with output_file(out / "sweep.csv", "w", force=True, newline="") as f:
        w = csvcell.writer(f)
        w.writerow([*keys, "measure", "n", "mean", "sd", "ci95_low", "ci95_high"])
        for r in rows:
            w.writerow([*(r[k] for k in keys), r["measure"], r["n"], f"{r['mean']:.6f}", f"{r['sd']:.6f}",
                        f"{r['ci95_low']:.6f}", f"{r['ci95_high']:.6f}"])
    with output_file(out / "cells.csv", "w", force=True, newline="") as f:
        w = csvcell.writer(f)
        w.writerow(["cell", *keys, "seed", "measure", "value"])
        for cell in grid.cells():
            for measure, value in sorted(results[cell.id].items()):
                w.writerow([cell.id, *(dict(cell.setting)[k] for k in keys), cell.seed, measure, f"{value:.6f}"])
    measures = sorted({r["measure"] for r in rows})
    figures = []
    for measure in measures:
        # a measure of one persona exists only in the settings that train it (a `personas` axis)
        mine = [r for r in rows if r["measure"] == measure]
        labels = [setting_label((k, r[k]) for k in keys) for r in mine]
        path = out / "figures" / figure_name(measure)
        path.parent.mkdir(exist_ok=True)
        plots.sweep_measure(labels, [r["mean"] for r in mine], [r["ci95_low"] for r in mine],
                            [r["ci95_high"] for r in mine], path, measure, len(grid.seeds))
        figures.append(path)
    md = ["# pairplay sweep", "",
          f"{counted(len(grid.settings()), 'setting')} x {counted(len(grid.seeds), 'seed')} = {counted(run.cells, 'cell')}; computed {run.computed} "
          f"in {run.wall_s:.1f} s ({run.where}); fixed settings: "
          + (", ".join(f"{k}={v}" for k, v in grid.base.items()) or "the study's defaults") + "."
          + (" reuse_last, not given, is the study's default: 50, or rounds // 4 for 50 rounds or fewer."
             if grid.reuse and "reuse_last" not in {**grid.base, **grid.axes} else ""), "",
          "Each row: the mean over seeds, the sample sd, and the 95% confidence interval of the mean "
          "(Student's t; a picks-per-round measure's stops at 18, which no round goes below, a ratio's at 0). "
          "Picks per round: 18 is perfect play, lower is better; ratio: learned / oracle."
          + windows_note(grid), "",
          "| setting | measure | n | mean | sd | 95% CI |", "|---|---|---|---|---|---|"]
    md += [f"| {setting_label((k, r[k]) for k in keys)} | {r['measure']} | {r['n']} | {r['mean']:.3f} | "
           f"{r['sd']:.3f} | {r['ci95_low']:.3f} to {r['ci95_high']:.3f} |" for r in rows]
    md += ["", *[f"![{p.stem}](figures/{p.name})" for p in figures], ""]
    write_text(out / "sweep.md", "\n".join(md), force=True)
    return written + figures
