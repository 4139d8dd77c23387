"""The simulated study's report: policy files, CSV tables, figures and report.md.

Rule: `run_study(settings, out)` runs the study of thesis chapter 6 through
`pairplay.core.study` and writes, reproducibly by seed, one report folder:
  policies/<persona>/game-NN.json   one policy file per game (schemas/policy.py)
  curves.csv, curves_summary.csv    picks per round per game; mean/sd/min/max per round
  learning_curves.png               figure 6.4 (memory, focus, impairment)
  evaluation.csv, evaluation.png    user alone vs learned vs oracle, picks per round
  profiles.csv, profiles.png        algorithm 3 per persona beside its features (figure 6.5)
  merged/<name>.json, merged.png    merged policies (algorithm 4) and figure 6.6
  merged_evaluation.csv             every merged policy on every persona
  reuse.csv, reuse.png              held-out persona: Q-learning from scratch vs pi-reuse
  speed.csv, speed.png              (--algorithm lspi) LSPI beside Q-learning on the same games:
                                    learning curves and rounds to 1.10x the oracle
  action_profiles.csv, action_merges.csv/.png   future work 1 (report/future_actions.py)
  frames.csv, frames.png            future work 2: merging across mirrored users, with and without calibration
  report.md                         the tables and figures, with the run's settings
It returns the tables it wrote, so a caller (the CLI, a notebook) can print them.
A study written with force into a folder that holds an earlier one removes the
earlier one's files of these names that it does not write itself (STUDY_OUTPUTS:
the sections of a persona not in this study, the speed-up's tables after a
--train-only run...), so no stale file looks current, only those its manifest
(STUDY_MANIFEST) says a study wrote; no other file is touched (a user's notes
named like a game file stay).
"""

from __future__ import annotations

import contextlib
import hashlib
import time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from types import SimpleNamespace
from typing import Callable, Collection

import numpy as np

from pairplay import __version__, csvcell
from pairplay.core import kernels, study
from pairplay.core.geometry import PICKS_UNIT
from pairplay.core.oracle import oracle_policies
from pairplay.core.personas import PERSONAS, persona
from pairplay.core.policies import to_policy_file
from pairplay.core.reward import BONUS_RULE_TEXT
from pairplay.core.rng import GAME_INDEX_RANGE, SEED_RANGE
from pairplay.core.simulate import MEMORY_LIMIT, batch_bytes, gigabytes
from pairplay.arguments import at, checked_dataclass, flag_argument, given, instance_argument, is_integer, path_argument
from pairplay.errors import OptionError, OutputError, command_word
from pairplay.lists import comma_items, repeated
from pairplay.numbers import counted, shown, type_name
from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, REWARD_BONUS_RULES, lspi_unused
from pairplay.outputs import manifest_name, output_folder
from pairplay.processes import off_main_thread, process_pool, result_of, stop_pool
from pairplay.schemas.policy import write_policy

from pairplay.report import future, plots
from pairplay.report.future_frames import frames_lines


MEMORY_COUNTS = ("games", "rounds", "eval_rounds", "reuse_seeds")  # the settings that size the study's memory
LSPI_SETTINGS = ("lspi_ridge", "lspi_every")  # the settings only algorithm lspi takes
REUSE_SETTINGS = ("psi", "psi_decay", "reuse_last", "reuse_seeds")  # the settings only the speed-up takes
EVAL_GAMES_PER_GAME = 12  # evaluation games per training game: comparison 3, own + merged policies, future work


@checked_dataclass  # a caller's mistake in the project's words (pairplay/arguments.py)
@dataclass
class StudySettings:
    """Everything that decides a study's results (the `pairplay study` options)."""
    seed: int = 0
    personas: str = ",".join(PERSONAS)  # comma-separated persona keys
    games: int = 10
    rounds: int = 500
    eval_rounds: int = 200
    reward_bonus: str = DEFAULT_REWARD_BONUS
    trained_updates: int = 50
    reuse_seeds: int = 10
    psi: float = 1.0
    psi_decay: float = 0.95
    reuse_last: int = 50
    train_only: bool = False
    algorithm: str = "q-learning"  # or "lspi" (core/lspi.py)
    lspi_ridge: float = LSPIConfig().ridge
    lspi_every: int = LSPIConfig().improve_every

    def __post_init__(self) -> None:
        """Each setting checked alone where a script makes it (`check_values`), naming
        `pairplay.StudySettings(<setting>)`: `rounds="20"`, `rounds=0`, `personas=""` were taken and said only
        by run_study, as "(rounds)" (a new user's trial). What depends on the whole study (its memory, the
        settings only LSPI or the speed-up take) is `check`'s, when the study is known."""
        try:
            self.check_values()
        except SettingError as err:
            err.where = at("StudySettings", err.key)
            raise

    def lspi(self) -> LSPIConfig | None:
        """LSPI's settings when the study learns by LSPI (ValueError if they cannot run)."""
        if self.algorithm != "lspi":
            return None
        return LSPIConfig(ridge=self.lspi_ridge, improve_every=self.lspi_every)

    def persona_list(self):
        """The personas named, in order (SettingError for none, an unknown one or one named twice)."""
        if not self.personas.strip():
            raise SettingError("personas", f"names no persona: give one or more of {', '.join(PERSONAS)}")
        try:
            names = comma_items(self.personas)
        except ValueError as exc:  # `a,,b` ran a and b without a word
            raise SettingError("personas", str(exc)) from None
        chosen = []
        for name in names:
            try:
                chosen.append(persona(name))
            except KeyError as exc:
                raise SettingError("personas", exc.args[0]) from None
        # by key, a name and its key being one persona: trained twice, its policy files would collide
        if twice := repeated(p.key for p in chosen):
            raise SettingError("personas", f"names {twice} twice: each persona is trained once")
        return chosen

    def check_kinds(self) -> None:
        """SettingTypeError for the first setting not of its field's kind (a script's `rounds="20"` was a
        comparison's TypeError, `personas=["blind"]` an AttributeError 'strip'): an integer is never a
        bool nor a float, a number is an int or a float, a flag True or False, text a str."""
        for f in fields(self):
            value, kind = getattr(self, f.name), type(getattr(StudySettings, f.name))
            ok = (isinstance(value, bool) if kind is bool else is_integer(value) if kind is int
                  else isinstance(value, (int, float)) and not isinstance(value, bool) if kind is float
                  else isinstance(value, kind))
            if not ok:
                want = "persona keys as one text, comma-separated ('blind,deaf')" if f.name == "personas" else type_name(kind)
                raise SettingTypeError(f.name, f"must be {want}, got {given(value)}")

    def runs_speed_up(self) -> bool:
        """Whether run_study runs the speed-up (algorithm 5): it holds each persona out of the others."""
        return not self.train_only and len(self.persona_list()) >= 2

    def check_values(self) -> list:
        """The personas, once each setting alone is of its kind and in its range (SettingError, `key` the
        field, for the first that is not); run at construction and by `check`."""
        self.check_kinds()
        personas = self.persona_list()
        lo, hi = SEED_RANGE
        if not lo <= self.seed <= hi:
            raise SettingError("seed", f"a seed is {lo}..{hi}, got {self.seed}")
        for key, low in (("games", 1), ("rounds", 1), ("eval_rounds", 1), ("reuse_seeds", 1),
                         ("trained_updates", 0), ("reuse_last", 0)):
            if getattr(self, key) < low:
                raise SettingError(key, f"must be at least {low}, got {getattr(self, key)}")
        # a state's updates are counted in 64 bits (core/combine.py trained_states): a larger threshold
        # (`--trained-updates 1e23`) was met by no state, and the study ran on without a word
        if self.trained_updates > UPDATES_MAX:
            raise SettingError("trained_updates", f"must be 0..{UPDATES_MAX} (a state's updates are counted in "
                               f"64 bits), got {self.trained_updates}")
        # game g of a persona is stream game g, and its evaluation EVAL_GAME_OFFSET + g (core/study.py):
        # both must be game indices core/rng.py takes (`--games 99999999999999999999` grew a list until
        # memory ran out)
        top = GAME_INDEX_RANGE[1] + 1 - study.EVAL_GAME_OFFSET
        for key in ("games", "reuse_seeds"):
            if getattr(self, key) > top:
                raise SettingError(key, f"must be 1..{top} (each game is a game index of core/rng.py), "
                                   f"got {getattr(self, key)}")
        for key in ("psi", "psi_decay"):
            if not 0 <= getattr(self, key) <= 1:  # also refuses nan
                raise SettingError(key, f"must be between 0 and 1, got {shown(getattr(self, key))}")
        if self.reward_bonus not in REWARD_BONUS_RULES:
            raise SettingError("reward_bonus", f"must be one of {', '.join(REWARD_BONUS_RULES)}, got {self.reward_bonus!r}")
        if self.algorithm not in study.LEARNING_ALGORITHMS:
            raise SettingError("algorithm", f"must be one of {', '.join(study.LEARNING_ALGORITHMS)}, got {self.algorithm!r}")
        try:
            self.lspi()
        except ValueError as exc:
            raise SettingError("lspi_ridge" if "ridge" in str(exc) else "lspi_every", str(exc)) from None
        return personas

    def check(self, speed_up: bool | None = None, spell: Callable[[str], str] = str,
              compare_learners: bool | None = None, given: Collection[str] = ()) -> list:
        """The personas, once every setting is known to make the study asked for; raises SettingError
        (its `key`, the setting's field name) for the first that core cannot run or that would run
        something else. `speed_up`: whether the speed-up runs (default: as run_study decides; a sweep
        says `reuse`). `compare_learners`: whether LSPI is compared with Q-learning by snapshots (default: as
        run_study decides, lspi without train_only; a sweep's cells do not). `spell` names a setting in
        the message (the CLI's `--reuse-last`). `given`: the settings the user gave (the options on the
        command line, the keys of a sweep's cell), for those that only some algorithm takes."""
        personas = self.check_values()
        self.check_memory(personas, speed_up if speed_up is not None else self.runs_speed_up(),
                          self.algorithm == "lspi" and not self.train_only if compare_learners is None
                          else compare_learners, spell)
        unused = lspi_unused(self.algorithm, [spell(k) for k in LSPI_SETTINGS if k in given], spell("algorithm"))
        if unused:  # (session's rule: Q-learning would ignore them)
            raise SettingError("algorithm", unused)
        if compare_learners is None:
            compare_learners = self.algorithm == "lspi" and not self.train_only
        if compare_learners and self.rounds < SPEED_EVERY:  # no snapshot: the comparison was dropped silently
            raise SettingError("rounds", f"must be at least {SPEED_EVERY} with {spell('algorithm')} lspi (it is "
                               f"compared with Q-learning by greedy snapshots every {SPEED_EVERY} rounds); "
                               f"got {self.rounds}")
        when = "" if speed_up is not None else f" (2+ personas without {spell('train_only')})"
        runs_it = speed_up if speed_up is not None else self.runs_speed_up()
        idle = [k for k in REUSE_SETTINGS if k in given]
        if idle and not runs_it:  # ignored without a word, as LSPI's settings were (a trial: exit 0, cells alike)
            how = "reuse = true" if speed_up is not None else f"2+ personas without {spell('train_only')}"
            raise SettingError(idle[0], f"{'/'.join(spell(k) for k in idle)} set the speed-up experiment (pi-reuse), "
                               f"which does not run here: it needs {how}")
        if runs_it:
            every = study.REUSE_SNAPSHOT_EVERY
            if self.rounds < every:  # no snapshot of the greedy policy, so no 'rounds to 1.10x the oracle'
                raise SettingError("rounds", f"must be at least {every} when the speed-up runs{when}: its greedy "
                                   f"snapshots are taken every {counted(every, 'round')}; got {self.rounds}")
            if self.psi <= 0:  # psi 0: the bias is never taken, the pi-reuse arm would be Q-learning
                raise SettingError("psi", f"must be above 0 when the speed-up runs{when}: pi-reuse with psi 0 never "
                                   f"takes the bias policy's action (its arm would be Q-learning), got {shown(self.psi)}")
            if self.reuse_last >= self.rounds:  # reuse_rounds 0: the pi-reuse arm would be Q-learning
                raise SettingError("reuse_last", f"must be below {spell('rounds')} {self.rounds} (0.."
                                   f"{self.rounds - 1}: the last N rounds of pi-reuse use the new policy alone; "
                                   f"N >= rounds leaves no round of reuse), got {self.reuse_last}")
        return personas

    def memory_bytes(self, personas: int, speed_up: bool, compare_learners: bool) -> int:
        """About the bytes the study holds at its peak (core/simulate.py batch_bytes): training (twice with
        LSPI compared), the speed-up's runs, and every evaluation game of the one batch (each at the
        longest's rounds: the comparison, the merged policies, future work, one per speed-up snapshot)."""
        games = personas * self.games
        total = batch_bytes(games, self.rounds, lspi=self.algorithm == "lspi")
        if compare_learners:
            total += batch_bytes(games, self.rounds)
        if self.train_only:
            return total
        evals = EVAL_GAMES_PER_GAME * games
        if speed_up:
            runs = 2 * personas * self.reuse_seeds
            total += batch_bytes(runs, self.rounds)
            evals += runs * (self.rounds // study.REUSE_SNAPSHOT_EVERY)
        return total + batch_bytes(evals, max(self.eval_rounds, study.FIRST_ROUNDS), fixed=True)

    def check_memory(self, personas: list, speed_up: bool, compare_learners: bool,
                     spell: Callable[[str], str] = str) -> None:
        """SettingError if the study would hold more than MEMORY_LIMIT (`--games 1000000000` grew lists until
        the system killed it), naming the count whose default would shrink it most."""
        need = self.memory_bytes(len(personas), speed_up, compare_learners)
        if need <= MEMORY_LIMIT:
            return
        default = StudySettings()
        shrink = {k: self.memory_bytes(len(personas), speed_up, compare_learners) if getattr(self, k) <= getattr(default, k)
                  else replace(self, **{k: getattr(default, k)}).memory_bytes(len(personas), speed_up, compare_learners)
                  for k in MEMORY_COUNTS}
        key = min(shrink, key=shrink.get)
        sizes = ", ".join(f"{spell(k)} {getattr(self, k)}" for k in MEMORY_COUNTS if k != "reuse_seeds" or speed_up)
        raise SettingError(key, f"the study would hold about {gigabytes(need)} of memory ("
                           f"{counted(len(personas), 'persona')}, {sizes}), over the {gigabytes(MEMORY_LIMIT)} "
                           f"allowed: give fewer games, rounds or personas; got {getattr(self, key)}")

    def rerun_command(self) -> str:
        """`pairplay study ...` with every setting that differs from the default (seed, games, rounds and
        the reward rule always): the same study again. The options are the fields' names."""
        shown = ("seed", "games", "rounds", "reward_bonus")
        default = StudySettings()
        words = ["pairplay", "study"]
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in shown and value == getattr(default, f.name):
                continue
            option = "--" + f.name.replace("_", "-")
            if isinstance(value, bool):
                words.append(option)  # a flag: only ever shown when set (the default is False)
            else:
                words += [option, command_word(repr(value) if isinstance(value, float) else value)]
        return " ".join(words)


def default_reuse_last(rounds: int) -> int:
    """reuse_last when a study or a sweep does not give it: 50 (StudySettings'), or a quarter of a study of
    50 rounds or fewer, where 50 would leave pi-reuse no round (`pairplay study --rounds 20` and a sweep's
    `rounds = 20` were refused for an option the user never gave; the Re-run line states it: it is not 50)."""
    default = StudySettings.reuse_last
    return default if rounds > default else rounds // 4


UPDATES_MAX = 2**63 - 1  # the top of a state's update count (int64); cli/args.py's (a test pins it)


class SettingError(OptionError):
    """A study setting that cannot run as asked; `key` is its StudySettings field name."""

    def __init__(self, key: str, what: str):
        super().__init__(what, key)
        self.key = key


class SettingTypeError(SettingError, TypeError):
    """A study setting of the wrong kind (StudySettings.check_kinds): a SettingError and a TypeError
    (pairplay/arguments.py's rule)."""


@dataclass
class StudyReport:
    """What run_study wrote: the folder, the phases' timings (s) and the tables (rows of strings)."""
    out: Path
    timings: dict[str, float]
    evaluation: list[list[str]] = field(default_factory=list)
    profiles: list[list[str]] = field(default_factory=list)
    merges: list[list[str]] = field(default_factory=list)
    reuse: list[list[str]] | None = None
    speed: list[list[str]] | None = None


def _no_bar(total: int, desc: str):
    return contextlib.nullcontext(_NullBar())


class _NullBar:
    def update(self, n: int) -> None:
        pass


def _progress(bar):
    last = [0]

    def update(done: int) -> None:
        bar.update(done - last[0])
        last[0] = done
    return update


def write_curves(out: Path, training: study.Training) -> dict[str, np.ndarray]:
    picks = training.result.picks
    curves: dict[str, list[np.ndarray]] = {}
    with open(out / "curves.csv", "w", newline="") as f:
        w = csvcell.writer(f)
        w.writerow(["persona", "game", "round", "picks", "inconsistent"])
        for row, (p, g) in enumerate(zip(training.personas, training.game_index)):
            curves.setdefault(p.key, []).append(picks[row])
            key, game = p.key, int(g)  # Python ints: the same text as before, without a conversion per cell
            w.writerows([key, game, r, n, inc] for r, (n, inc) in
                        enumerate(zip(picks[row].tolist(), training.result.inconsistent[row].tolist())))
    stacked = {k: np.stack(v) for k, v in curves.items()}
    with open(out / "curves_summary.csv", "w", newline="") as f:
        w = csvcell.writer(f)
        w.writerow(["persona", "round", "mean", "sd", "min", "max"])
        for key, c in stacked.items():
            for r in range(c.shape[1]):
                col = c[:, r]
                w.writerow([key, r, f"{col.mean():.3f}", f"{col.std():.3f}", int(col.min()), int(col.max())])
    return stacked


def write_policies(out: Path, training: study.Training, args, config: LearnerConfig) -> list[Path]:
    paths, lspi = [], args.lspi()
    for row, (p, g) in enumerate(zip(training.personas, training.game_index)):
        path = out / "policies" / p.key / f"game-{int(g):02d}.json"
        write_policy(path, to_policy_file(
            training.result.q[row], training.result.counts[row], training.greedy[row],
            algorithm=args.algorithm, participant=p.key, persona=p, seed=training.seeds[row], game=int(g),
            rounds=args.rounds, config=config, software=f"pairplay {__version__}", reward_bonus=args.reward_bonus,
            lspi=lspi))
        paths.append(path)
    return paths


def evaluation_table(cmp: study.Comparison) -> list[list[str]]:
    rows = [["persona", "focus", "user alone", "learned (mean \u00b1 sd)", "oracle", "learned/oracle"]]
    for i, key in enumerate(cmp.persona):
        rows.append([key, str(PERSONAS[key].focus), f"{cmp.alone[i]:.2f}",
                     f"{cmp.learned[i]:.2f} \u00b1 {cmp.learned_spread[i]:.2f}", f"{cmp.oracle[i]:.2f}",
                     f"{cmp.learned[i] / cmp.oracle[i]:.3f}"])
    return rows


def gap_section(cmp: study.Comparison, training: study.Training, threshold: float = 1.05) -> list[str]:
    """Report lines: for each persona above `threshold` x the oracle, the states that lose most."""
    from pairplay.core.actions import ACTION_NAMES
    from pairplay.core.geometry import STATE_NAMES
    lines = []
    for i, key in enumerate(cmp.persona):
        if cmp.learned[i] <= threshold * cmp.oracle[i]:
            continue
        rows = [["state", "learned: the plurality action (k of n policies)", "E[r]", "oracle", "E[r]", "mean loss"]]
        own = training.greedy[[j for j, p in enumerate(training.personas) if p.key == key]]
        for s, modal, v_modal, best, v_best, loss in study.policy_gaps(cmp, training, i):
            k = int((own[:, s] == modal).sum())
            rows.append([STATE_NAMES[s], f"{modal}: {ACTION_NAMES[modal]} ({k} of {len(own)})", f"{v_modal:+.2f}",
                         f"{best}: {ACTION_NAMES[best]}", f"{v_best:+.2f}", f"{loss:.2f}"])
        lines += [f"**{key}** ({cmp.learned[i] / cmp.oracle[i]:.3f} x the oracle): the states where its learned "
                  "policies lose most expected reward (given the suggestion is considered).", "",
                  markdown_table(rows), ""]
    if lines:
        lines = ["### Where learned policies stay above the oracle", ""] + lines
    return lines


def markdown_table(rows: list[list[str]]) -> str:
    head, *body = rows
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    return "\n".join(lines)


def text_table(rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.rjust(w) if j else c.ljust(w) for j, (c, w) in enumerate(zip(r, widths)))
                     for r in rows)


def profile_rows(personas, users: study.UserSet) -> list[list[str]]:
    from pairplay.core.combine import COMPARED_STATES
    from pairplay.core.geometry import STATE_NAMES
    rows = [["persona", "focus", "memory", "hearing", "sight", "speech %", "head %", "smile", "gaze",
             "Q updates per state (median)", "trained states: speech % / head % (of n)",
             "incompatible states (mean Q updates in them)"]]
    for p in personas:
        prof, upd, trained = users.profiles[p.key], users.updates[p.key].mean(0), users.trained[p.key]
        on_trained = "-" if trained is None else \
            f"{100 * trained.info.speech:.1f} / {100 * trained.info.head:.1f} ({trained.info.compared_states})"
        states = sorted(set(prof.speech_states) | set(prof.head_states))
        where = ", ".join(f"{STATE_NAMES[s]}{'(S)' if s in prof.speech_states else ''}"
                          f"{'(H)' if s in prof.head_states else ''} {upd[s]:.0f}" for s in states)
        rows.append([p.key, str(p.focus), str(p.memory), str(p.hearing), str(p.sight),
                     f"{100 * prof.info.speech:.1f}", f"{100 * prof.info.head:.1f}",
                     "yes" if prof.info.facial else "no", "yes" if prof.info.gaze else "no",
                     f"{np.median(upd[COMPARED_STATES]):.0f}", on_trained, where or "-"])
    return rows


MERGES = (("blind+deaf", ("blind", "deaf")), ("vincent+tatiana", ("vincent", "tatiana")), ("all", None))


def write_merges(out: Path, personas, users: study.UserSet, args, figures=None) -> dict:
    from pairplay.core.combine import combine
    from pairplay.core.geometry import N_STATES
    from pairplay.core.policies import combined_policy_file
    keys = [p.key for p in personas]
    merges, panels = {}, []
    for name, members in MERGES:
        members = keys if members is None else [m for m in members if m in keys]
        if len(members) < 2:
            continue
        chosen = [users.users[k] for k in members]
        merged = combine(chosen)
        merges[name] = merged
        write_policy(out / "merged" / f"{name}.json", combined_policy_file(
            merged, chosen, members, args.seed, software=f"pairplay {__version__}", reward_bonus=args.reward_bonus))
        inputs = {k: users.users[k].policy for k in members} if len(members) <= 3 else {}
        panels.append((name, inputs, merged.policy))
    if panels:
        (figures.draw if figures is not None else plots.draw)("merged_policies", panels, N_STATES - 1, out / "merged.png")
    return merges


TIMINGS_HEADING = "## Timings"

# Every file a study may write, as patterns of its relative path (pairplay.outputs.is_owned; the module
# rule lists them): a --force run removes those of an earlier study it does not write itself.
STUDY_OUTPUTS = ("policies/*/game-*.json", "merged/*.json", "report.md", "curves.csv", "curves_summary.csv",
                 "learning_curves.png", "evaluation.csv", "evaluation.png", "profiles.csv", "profiles.png",
                 "merged.png", "merged_evaluation.csv", "reuse.csv", "reuse.png", "speed.csv", "speed.png",
                 "action_profiles.csv", "action_merges.csv", "action_merges.png", "frames.csv", "frames.png",
                 "precombination.csv", "precombination.png")
STUDY_MANIFEST = manifest_name("study")  # the files a study wrote in its folder: --force removes only those


def output_digests(out: Path) -> dict[str, str]:
    """sha256 (hex) of every file a study wrote under `out` that its seed decides, by relative path.

    Figures (*.png: matplotlib's bytes are not ours to pin) are left out, and
    report.md is hashed up to its timings section (wall clock, not results).
    The manifest (STUDY_MANIFEST) is left out too: it is deterministic (sorted relative names, no time, no
    path), but it is bookkeeping for --force, not a result, and it only lists names the digests and the
    figures already give; the pinned set (tests/data/study_digests.json) stays the study's results.
    The study's equality contract (tests/test_study_digests.py) compares these.
    """
    digests = {}
    for path in sorted(Path(out).rglob("*")):
        if not path.is_file() or path.suffix == ".png" or path.relative_to(out).as_posix() == STUDY_MANIFEST:
            continue
        data = path.read_bytes()
        if path.name == "report.md":
            data = data.split(TIMINGS_HEADING.encode(), 1)[0]
        digests[path.relative_to(out).as_posix()] = hashlib.sha256(data).hexdigest()
    return digests


class _Figures:
    """Draws the figures in one child process while the study computes (matplotlib costs as much CPU
    as the whole compiled study); inline when `background` is False or no child can be started."""

    def __init__(self, background: bool):
        self._pool = None
        self._jobs: list = []
        if background:
            try:
                self._pool = process_pool(1)
                self._jobs.append(self._pool.submit(plots.draw, None))  # the child imports matplotlib now
            except BaseException as exc:  # a Ctrl-C while the child starts stops it too (the caller has no
                if self._pool is not None:  # _Figures to stop yet)
                    stop_pool(self._pool, abandon=True)
                    self._pool = None
                if not isinstance(exc, (OSError, ImportError)):
                    raise

    def draw(self, name: str, *args) -> None:
        if self._pool is None:
            plots.draw(name, *args)
        else:
            self._jobs.append(self._pool.submit(plots.draw, name, *args))

    def finish(self, abandon: bool = False) -> None:
        """Wait for every figure (a figure's error is raised here), or, when `abandon` (the study
        failed or was interrupted), stop the child without waiting for its figures."""
        try:
            if not abandon:
                for job in self._jobs:
                    result_of(self._pool, job)  # jobs are only the child's: a dead child is WorkerLost
        finally:
            if self._pool is not None:
                stop_pool(self._pool, abandon)
                self._pool = None
            self._jobs = []


def _info(i) -> SimpleNamespace:
    """A profile's user information as plain data (the figure process does not import core)."""
    return SimpleNamespace(speech=float(i.speech), head=float(i.head), facial=bool(i.facial), gaze=bool(i.gaze))


def run_study(args: StudySettings, out: Path, progress_bar: Callable = _no_bar, force: bool = False,
              figures_in_background: bool = True) -> StudyReport:
    """Run the study with `args` and write its report folder `out`.

    `progress_bar(total, desc)` returns a context manager whose value has `update(n)`
    (a tqdm bar, say): one per phase, counted in simulated rounds. Independent
    phases share a batch (core/study.py): the speed-up's two arms, and every
    evaluation (learned, oracle and user alone; merged policies; the speed-up's
    snapshots). Figures are drawn in a child process meanwhile.
    The folder is built beside `out` and renamed when complete (pairplay.outputs.output_folder):
    OutputError, before any work, if `out` exists with files in it and not `force`; with `force`,
    an earlier study's files there that this one does not write are removed (STUDY_OUTPUTS); an
    interrupted study leaves nothing; OutputError, before any work, for an `out` inside a people's study
    folder (`pairplay protocol init`'s: only protocol writes there). Raises SettingError (an OptionError), before any work, for a
    setting that cannot run as asked (StudySettings.check); ArgumentError for `args` that are no
    StudySettings, `out` no path, `force` not True or False (pairplay/arguments.py)."""
    instance_argument(args, StudySettings, "run_study", "args", "a StudySettings (pairplay.StudySettings(seed=1, ...))")
    out = path_argument(out, "run_study", "out")
    force = flag_argument(force, "run_study", "force")
    from pairplay.replay.studyroot import study_root
    if study_root(out) is not None:  # as `pairplay study --out` is refused there (cli/args.py check_study_folders):
        # the API wrote a report, figures and a policies/ folder beside a people's study's policy files (trial34 M)
        raise OutputError(f"inside a people's study folder ({study_root(out)}) only `pairplay protocol` writes; give "
                          "run_study's out elsewhere", out)
    personas = args.check()
    return_freed_memory()
    with output_folder(out, force, owned=STUDY_OUTPUTS, manifest=STUDY_MANIFEST) as tmp:
        report = _run_study(args, personas, tmp, progress_bar, figures_in_background)
    report.out = Path(out)
    return report


M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter (malloc.h)
MMAP_THRESHOLD = 128 * 1024  # glibc's default: blocks from this size on are mapped, and unmapped when freed


def return_freed_memory() -> bool:
    """Fix glibc's mmap threshold at its default, so a phase's big arrays go back to the system when freed.

    Why: glibc raises the threshold to the size of each mapped block freed (up to 32 MiB),
    so after the oracle freed its recorded turns, the next phases' arrays of that size
    came from the heap, which kept the oracle's peak resident: the study held 211 MiB
    where no phase needs more than 188 (measured; issue 16's goal is 200). Setting the
    threshold explicitly turns the raising off (mallopt(3)). Returns whether it was set
    (False off glibc: nothing to do there)."""
    import ctypes
    try:
        return bool(ctypes.CDLL(None).mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD))  # the process's own libc
    except (OSError, AttributeError):  # not glibc
        return False


def _run_study(args: StudySettings, personas, out: Path, progress_bar: Callable,
               figures_in_background: bool = True) -> StudyReport:
    config = LearnerConfig()
    names = {p.key: p.name for p in personas}
    timings: dict[str, float] = {}
    start = time.perf_counter()
    figures = _Figures(figures_in_background)
    try:
        report = _run(args, out, progress_bar, personas, config, names, timings, start, figures)
    except BaseException:
        figures.finish(abandon=True)
        raise
    figures.finish()
    return report


def _run(args, out, progress_bar, personas, config, names, timings, start, figures) -> StudyReport:
    # compiled off the main thread: a Ctrl-C must not land inside numba's compiler (pairplay/processes.py)
    seconds, compiled, _ = off_main_thread(kernels.warm_up)
    timings["kernels compiled (first run)" if compiled else "kernels loaded from cache"] = seconds

    t0 = time.perf_counter()
    lspi = args.lspi()
    # check() refused fewer rounds than SPEED_EVERY unless --train-only (which needs no snapshot)
    snapshot_every = SPEED_EVERY if lspi is not None and args.rounds >= SPEED_EVERY else None
    with progress_bar(len(personas) * args.games * args.rounds, "training") as bar:
        training = study.train(personas, args.games, args.rounds, args.seed, config, progress=_progress(bar),
                               reward_bonus=args.reward_bonus, algorithm=args.algorithm, lspi=lspi,
                               snapshot_every=snapshot_every)
    timings["training"] = time.perf_counter() - t0

    write_policies(out, training, args, config)
    curves = write_curves(out, training)
    figures.draw("learning_curves", curves, names, out / "learning_curves.png")
    if args.train_only:
        figures.finish()
        timings["total"] = time.perf_counter() - start
        return StudyReport(out, timings)

    t0 = time.perf_counter()
    oracle = oracle_policies(personas, 20, args.seed, 200, bonus=args.reward_bonus)
    timings["oracle"] = time.perf_counter() - t0
    q_training = None
    if snapshot_every:  # LSPI is compared with Q-learning trained with snapshots on the same games
        t0 = time.perf_counter()
        with progress_bar(len(personas) * args.games * args.rounds, "q-learning beside lspi") as bar:
            q_training = study.train(personas, args.games, args.rounds, args.seed, config, progress=_progress(bar),
                                     reward_bonus=args.reward_bonus, snapshot_every=snapshot_every)
        timings["q-learning beside lspi"] = time.perf_counter() - t0

    # Profiles (algorithm 3, figure 6.5) and merged policies (algorithm 4, figure 6.6).
    t0 = time.perf_counter()
    users = study.user_set(personas, training, args.seed, args.trained_updates)
    prof_rows = profile_rows(personas, users)
    with open(out / "profiles.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(prof_rows)
    figures.draw("profiles", [p.key for p in personas], names, [_info(users.profiles[p.key].info) for p in personas],
                 [(p.focus, p.memory, p.hearing, p.sight) for p in personas], out / "profiles.png",
                 [None if users.trained[p.key] is None else _info(users.trained[p.key].info) for p in personas],
                 args.trained_updates)
    merges = write_merges(out, personas, users, args, figures)
    own = {p.key: training.greedy[[i for i, q in enumerate(training.personas) if q.key == p.key]]
           for p in personas}
    timings["profiles and merges"] = time.perf_counter() - t0

    # Speed-up (thesis 3.3, 5.3): each persona held out, pi-reuse on the merge of the others (both arms, one batch).
    t0 = time.perf_counter()
    reuse_config = LearnerConfig(psi_start=args.psi, psi_decay=args.psi_decay,
                                 reuse_rounds=max(0, args.rounds - args.reuse_last))
    runs = None
    if len(personas) >= 2:
        with progress_bar(2 * len(personas) * args.reuse_seeds * args.rounds, "speed-up") as bar:
            runs = study.reuse_runs(personas, users, args.reuse_seeds, args.rounds, args.seed, reuse_config,
                                    progress=_progress(bar), reward_bonus=args.reward_bonus)
    timings["speed-up"] = time.perf_counter() - t0

    # Every evaluation in one batch: learned vs oracle vs alone, merged policies, the speed-up's snapshots.
    t0 = time.perf_counter()
    batch = study.Evaluations(args.seed)
    compared = study.add_comparison(batch, personas, training, args.eval_rounds, oracle)
    merged_pending = study.add_on_personas(batch, personas, {"own": own, **{k: m.policy for k, m in merges.items()}},
                                           args.games, args.eval_rounds)
    snapshots = study.add_snapshots(batch, runs) if runs is not None else None
    timings["evaluations"] = time.perf_counter() - t0
    # the future-work sections queue theirs in the same batch (report/future.py says how)
    t0 = time.perf_counter()
    state = future.Study(args, out, personas, names, training, users, figures, markdown_table)
    finishers = [f for f in (section(state, batch) for section in future.SECTIONS) if f is not None]
    future_seconds = time.perf_counter() - t0
    # future work 2 plays its own personas and games, whatever the study's: before the batch, so that
    # its figure is drawn while the batch plays (the figure process is the study's last to finish)
    t0 = time.perf_counter()
    frame_lines = frames_lines(out, args.seed, args.rounds, args.reward_bonus, markdown_table, figures.draw)
    timings["future work 2 (frame calibration)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with progress_bar(batch.total_rounds, "evaluations") as bar:
        batch.play(progress=_progress(bar))
    cmp = study.comparison(personas, training, oracle, batch.picks[compared])
    merged_eval = merged_pending(batch)
    timings["evaluations"] += time.perf_counter() - t0

    table = evaluation_table(cmp)
    with open(out / "evaluation.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(table)
    figures.draw("comparison_bars", cmp.persona, {"user alone": cmp.alone, "learned": cmp.learned, "oracle": cmp.oracle},
                 out / "evaluation.png", f"{PICKS_UNIT}, epsilon 0")
    oracle = dict(zip(cmp.persona, cmp.oracle))
    alone = dict(zip(cmp.persona, cmp.alone))
    speed_rows = speed_lines = None
    if q_training is not None:
        t0 = time.perf_counter()
        speed = study.learning_speed(personas, {"q-learning": q_training, "lspi": training}, oracle, args.seed)
        speed_rows, speed_lines = speed_section(speed, oracle, out, names, args, figures)
        timings["lspi beside q-learning: snapshots"] = time.perf_counter() - t0
    merge_rows = [["persona", "user alone", "own policies", *merges, "oracle"]]
    for p in personas:
        merge_rows.append([p.key, f"{alone[p.key]:.2f}", f"{merged_eval[('own', p.key)]:.2f}",
                           *[f"{merged_eval[(k, p.key)]:.2f}" for k in merges], f"{oracle[p.key]:.2f}"])
    with open(out / "merged_evaluation.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(merge_rows)

    first = first_rounds_text(args.rounds)  # "first 50 rounds", or all of a shorter game's
    reuse_rows = [["held-out persona", f"{first}: scratch", f"{first}: pi-reuse", "gain",
                   f"rounds to {1.10:.2f}x oracle: scratch", "pi-reuse"]]
    reuse = None
    if runs is not None:
        reuse = study.reuse_result(runs, oracle, batch.picks[snapshots])
        for i, key in enumerate(reuse.persona):
            f50, r2t = reuse.first50[i], reuse.rounds_to_target[i]
            reuse_rows.append([key, f"{f50[0].mean():.2f} \u00b1 {f50[0].std():.2f}",
                               f"{f50[1].mean():.2f} \u00b1 {f50[1].std():.2f}",
                               f"{f50[0].mean() - f50[1].mean():+.2f}", _rounds_text(r2t[0]), _rounds_text(r2t[1])])
        with open(out / "reuse.csv", "w", newline="") as f:
            csvcell.writer(f).writerows(reuse_rows)
        figures.draw("reuse_curves", reuse.persona, names, reuse.curves, [oracle[k] for k in reuse.persona],
                     out / "reuse.png")
    t0 = time.perf_counter()
    state.oracle, state.alone = oracle, alone
    future_lines = [line for finish in finishers for line in finish(state)] + future.not_run_lines(state)
    if finishers:
        timings["future work"] = future_seconds + time.perf_counter() - t0
    future_lines += frame_lines
    t0 = time.perf_counter()
    figures.finish()
    timings["waiting for figures"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - start

    first50 = {k: c[:, :study.FIRST_ROUNDS].mean() for k, c in curves.items()}
    last50 = {k: c[:, -study.FIRST_ROUNDS:].mean() for k, c in curves.items()}
    learner_text = "Q-learning with the thesis's schedules (epsilon 0.9 - 0.1/50 rounds, floor 0.1; alpha 0.5 - " \
        "0.05/50 rounds)" if lspi is None else \
        f"online LSPI (algorithm 2, core/lspi.py: {counted(lspi.tilings, 'tiling')} {lspi.tile_width:g} grid steps wide" \
        f"{' + one tile per state' if lspi.exact else ''}, ridge {lspi.ridge:g}, policy improvement every " \
        f"{counted(lspi.improve_every, 'sample')}, gamma {lspi.gamma:g}) with Q-learning's epsilon schedule"
    report = [
        "# pairplay study report", "",
        f"pairplay {__version__}, seed {args.seed}, {counted(len(personas), 'persona')} x {counted(args.games, 'game')} x "
        f"{counted(args.rounds, 'round')}, {learner_text}; the 1/|candidate set| bonus "
        f"{BONUS_RULE_TEXT[args.reward_bonus]} (rule `{args.reward_bonus}`). "
        f"Re-run: `{args.rerun_command()}`.", "",
        "## Learned policies against the references", "",
        f"Picks per round, each greedy policy played {counted(args.eval_rounds, 'round')} with epsilon 0; the oracle "
        "and the user alone play the same games (core/oracle.py documents the oracle).", "",
        markdown_table(table), "", "![evaluation](evaluation.png)", "",
        *gap_section(cmp, training),
        *(speed_lines or []),
        "## Learning curves (figure 6.4)", "",
        markdown_table([["persona", first, first.replace("first", "last")]] +
                       [[k, f"{first50[k]:.2f}", f"{last50[k]:.2f}"] for k in curves]), "",
        "![learning curves](learning_curves.png)", "",
        "## User information (algorithm 3, figure 6.5)", "",
        f"Over each persona's {counted(args.games, 'policy', 'policies')}, shares of the 23 spatial states; (S)/(H) mark speech/head "
        "incompatibilities, with the mean number of Q updates the state got in a game. Policies disagree "
        "where states are seldom trained (thesis 6.4: untrained states), hence the median updates per state, "
        f"and the same comparison over the n states every one of the persona's policies updated at least "
        f"{counted(args.trained_updates, 'time')} (`--trained-updates`).", "",
        markdown_table(prof_rows), "", "![profiles](profiles.png)", "",
        "## Merged policies (algorithm 4, figure 6.6)", "",
        "Each persona is represented by one of its policies, picked at random by the seed (thesis 6.2); "
        "picks per round with epsilon 0.", "",
        markdown_table(merge_rows), "",
        # one persona: nothing to merge, and no merged.png (the report showed a broken figure, no reason)
        *(["![merged](merged.png)", ""] if merges else
          [f"No merged policy: a merge (algorithm 4) needs at least 2 personas; this study has {len(personas)}.",
           ""]),
    ]
    for name, merged in merges.items():
        rules: dict[str, int] = {}
        for r in merged.rules:
            rules[r] = rules.get(r, 0) + 1
        report += [f"- {name}: merged info speech {100 * merged.info.speech:.1f}%, head "
                   f"{100 * merged.info.head:.1f}%, smile {merged.info.facial}, gaze {merged.info.gaze}; rules: "
                   + "; ".join(f"{k} x{v}" for k, v in sorted(rules.items(), key=lambda kv: -kv[1]))]
    if reuse is not None:
        gains = reuse.first50[:, 0].mean(1) - reuse.first50[:, 1].mean(1)
        report += ["", "## Policy reuse speed-up (algorithm 5)", "",
                   f"Each persona held out; bias = merge of the other personas. {counted(args.reuse_seeds, 'game')} each, "
                   f"psi {args.psi} decaying by {args.psi_decay} per suggestion, reset every round, the last "
                   f"{counted(args.reuse_last, 'round')} on the new policy alone. 'Rounds to 1.10x oracle': the first "
                   "multiple of 10 rounds after which the learner's greedy policy, played 20 rounds with "
                   "epsilon 0, needs at most 1.10x the oracle's picks.", "",
                   markdown_table(reuse_rows), "",
                   f"pi-reuse beats scratch on the {first} for {(gains > 0).sum()} of {len(gains)} "
                   f"held-out personas; median gain {np.median(gains):.2f} picks per round.", "",
                   "![reuse](reuse.png)", ""]
    else:  # one persona: left out without a word before
        report += ["", "## Policy reuse speed-up (algorithm 5)", "",
                   "Not run: each persona is held out and its bias policy merged from the others, so the "
                   f"speed-up needs at least 2 personas; this study has {len(personas)}.", ""]
    report += [TIMINGS_HEADING, "", markdown_table([["phase", "seconds"]] + [[k, f"{v:.2f}"] for k, v in timings.items()]), ""]
    # the future-work sections come after the timings, so that report.md up to its timings stays the
    # thesis's study, whose bytes tests/test_study_digests.py pins
    report += future_lines
    (out / "report.md").write_text("\n".join(report))

    return StudyReport(out, timings, table, prof_rows, merge_rows, reuse_rows if reuse is not None else None,
                       speed_rows)


SPEED_EVERY = 10  # rounds between greedy snapshots when two learners are compared


def first_rounds_text(rounds: int) -> str:
    """The label of the early-learning measure: 'first 50 rounds', or 'first 20 rounds (all)' of a shorter game
    (the measure averages the rounds there are: a 20-round run's report said 'first 50 rounds')."""
    n = study.FIRST_ROUNDS
    return f"first {counted(n, 'round')}" if rounds >= n else f"first {counted(rounds, 'round')} (all)"


def _rounds_text(x: np.ndarray) -> str:
    """Rounds to a target over games (nan: never reached) as 'mean \u00b1 sd (k never)'."""
    hit = x[~np.isnan(x)]
    never = int(np.isnan(x).sum())
    base = f"{hit.mean():.0f} \u00b1 {hit.std():.0f}" if hit.size else "-"
    return base + (f" ({never} never)" if never else "")


def speed_section(speed: study.Speed, oracle: dict[str, float], out: Path, names: dict, args,
                  figures: _Figures) -> tuple[list, list]:
    """speed.csv, speed.png and the report's lines: the learners side by side on the same games.

    `oracle` is the oracle's picks per round by persona key."""
    n = study.FIRST_ROUNDS
    rows = [["persona", "focus", *[f"rounds to {speed.target:.2f}x oracle: {a}" for a in speed.algorithms],
             *[f"{first_rounds_text(speed.curves.shape[-1])}: {a}" for a in speed.algorithms],
             *[f"last snapshot / oracle: {a}" for a in speed.algorithms]]]
    for i, key in enumerate(speed.persona):
        rows.append([key, str(PERSONAS[key].focus),
                     *[_rounds_text(speed.rounds_to_target[a, i]) for a in range(len(speed.algorithms))],
                     *[f"{speed.curves[a, i, :, :n].mean():.2f} \u00b1 {speed.curves[a, i, :, :n].mean(1).std():.2f}"
                       for a in range(len(speed.algorithms))],
                     *[f"{speed.snapshot_picks[a, i, :, -1].mean() / oracle[key]:.3f}"
                       for a in range(len(speed.algorithms))]])
    with open(out / "speed.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(rows)
    figures.draw("algorithm_curves", speed.curves, speed.algorithms, speed.persona, names,
                 [oracle[k] for k in speed.persona], out / "speed.png")
    lines = ["## LSPI beside Q-learning (same games, same exploration schedule)", "",
             f"Both learners train on the same {counted(args.games, 'game')} per persona (same deals and users); every "
             f"{counted(speed.every, 'round')} each learner's greedy policy plays 20 rounds with epsilon 0 on the same "
             f"evaluation games. 'Rounds to {speed.target:.2f}x oracle': the first such snapshot within "
             f"{speed.target:.2f}x the oracle's picks per round, mean \u00b1 sd over games.", "",
             markdown_table(rows), "", "![LSPI beside Q-learning](speed.png)", ""]
    return rows, lines
