"""`pairplay study`: the virtual study of thesis chapter 6, end to end (report/study.py does the work).

Rule: one command, reproducible by seed, writes the report folder that report/study.py
describes (policy files, CSV tables, figures 6.4-6.6, report.md).
The folder is built beside --out and renamed when complete: an --out that holds
files is refused unless --force, and Ctrl-C leaves nothing (exit 130). Every
option's range is checked before any work; the printed tables say their unit
(picks per round, 18 = perfect).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pairplay.cli.args import (add_force, count, fraction, non_negative, output_folder, positive_number, seed_number,
                               update_count)
from pairplay.core.geometry import PICKS_UNIT
from pairplay.core.personas import PERSONAS
from pairplay.errors import OptionError, escaped
from pairplay.schemas.config import DEFAULT_REWARD_BONUS, REWARD_BONUS_RULES as BONUS_RULES

# the study's modules load in run(): `pairplay --help` stays quick


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=seed_number, default=0, help="study seed (default 0)")
    p.add_argument("--personas", default=",".join(PERSONAS),
                   help="comma-separated persona keys (default: all of appendix A)")
    p.add_argument("--games", type=count, default=10, help="games per persona (thesis: 10)")
    p.add_argument("--rounds", type=count, default=500, help="rounds per game (thesis: 500)")
    p.add_argument("--eval-rounds", type=count, default=200,
                   help="rounds each greedy policy is evaluated with epsilon 0 (default 200)")
    p.add_argument("--reward-bonus", choices=BONUS_RULES, default=DEFAULT_REWARD_BONUS,
                   help="when the 1/|candidate set| bonus is paid: when the candidate set holds the match "
                        "(correct, default), on every consistent suggestion (consistent, SPEC's literal reading) "
                        "or on a match only (see README: the reward bonus)")
    p.add_argument("--trained-updates", type=update_count, default=50,
                   help="profiles are also given over the states every policy of a persona updated at least "
                        "this many times (default 50; thesis 6.4: untrained states)")
    p.add_argument("--reuse-seeds", type=count,
                   help="games per held-out persona in the speed-up experiment (default 10)")
    p.add_argument("--psi", type=fraction, help="pi-reuse: psi at the start of each round (default 1)")
    p.add_argument("--psi-decay", type=fraction, help="pi-reuse: v, psi's decay per suggestion (default 0.95)")
    p.add_argument("--reuse-last", type=non_negative, default=None,
                   help="pi-reuse: the last N rounds use the new policy alone (default 50; a quarter of "
                        "--rounds when --rounds is 50 or fewer)")
    p.add_argument("--algorithm", choices=("q-learning", "lspi"), default="q-learning",
                   help="the learner: Q-learning (thesis 5.1.1, default) or online LSPI (algorithm 2, core/lspi.py); "
                        "with lspi, Q-learning also trains on the same games for the side-by-side comparison")
    # no default here (StudySettings' is used): given with another algorithm, they are refused, not ignored
    p.add_argument("--lspi-ridge", type=positive_number, help="lspi: delta, the ridge penalty (default 1)")
    p.add_argument("--lspi-every", type=count, help="lspi: K, samples between policy improvements (default 10)")
    p.add_argument("--out", type=output_folder, default=Path("out/study"),
                   help="report folder (default out/study); refused if it holds files, unless --force")
    add_force(p, "the files of an existing report folder")
    p.add_argument("--train-only", action="store_true",
                   help="stop after training: policy files, curves and figure 6.4 only (for sweeps)")


def _bar(quiet: bool):
    from pairplay.cli.progress import bar as progress

    def bar(total: int, desc: str):
        return progress(total, desc, "round", quiet, leave=False)  # on a terminal only (cli/progress.py)
    return bar


def option(key: str) -> str:
    """A StudySettings field's option: reuse_last -> --reuse-last (the two are one table: every field is
    an option of this verb, tests/test_study_options.py)."""
    return "--" + key.replace("_", "-")


def settings_of(args):
    """The one config object (report/study.py StudySettings) from the parsed options, checked: an
    OptionError naming the option and its allowed range for a combination core cannot run or would run
    as something else (no persona, one twice, fewer rounds than the speed-up's snapshot interval...)."""
    from pairplay.report.study import (LSPI_SETTINGS, REUSE_SETTINGS, SettingError, StudySettings,
                                      default_reuse_last)

    given = {k: getattr(args, k) for k in StudySettings.__dataclass_fields__}
    # the settings only LSPI or only the speed-up takes are refused where they would be ignored
    # (StudySettings.check): their options default to None (not given), then to StudySettings' defaults
    optional = (*LSPI_SETTINGS, *REUSE_SETTINGS)
    named = [k for k in optional if given[k] is not None]
    if given["reuse_last"] is None:  # not given: the default must fit a short study (`--rounds 20` was refused
        given["reuse_last"] = default_reuse_last(given["rounds"])  # for the default's 50: a new user's trial)
    try:  # each setting alone is checked as StudySettings is made (its __post_init__), the rest by check
        settings = StudySettings(**{k: v for k, v in given.items() if not (k in optional and v is None)})
        settings.check(spell=option, given=named)
    except SettingError as exc:
        raise OptionError(f"{option(exc.key)}: {exc.what}", option(exc.key)) from None
    return settings


def run(args) -> int:
    from pairplay.outputs import check_output_folder, hold

    settings = settings_of(args)  # every option first, before anything is written
    from pairplay.report.study import STUDY_MANIFEST, STUDY_OUTPUTS, first_rounds_text, run_study, text_table

    hold(args.out, "study")  # one writer per output (pairplay/outputs.py): a second one is refused, not run twice
    check_output_folder(args.out, args.force, STUDY_OUTPUTS, STUDY_MANIFEST)  # a folder where a file of it goes: refused now

    report = run_study(settings, args.out, _bar(args.quiet), force=args.force)
    if settings.train_only:
        print(f"training: {report.timings['training']:.2f} s; policies and curves in {escaped(report.out)}")
        return 0
    print(f"learned policies against the references: {PICKS_UNIT}, epsilon 0")
    print(text_table(report.evaluation))
    print()
    print("user information (algorithm 3): incompatible states, % of the 23 spatial states")
    print(text_table([r[:9] for r in report.profiles]))
    print()
    print(f"merged policies (algorithm 4) on each persona: {PICKS_UNIT}, epsilon 0")
    print(text_table(report.merges))
    if report.speed is not None:
        print()
        print(text_table(report.speed))
    if report.reuse is not None:
        print()
        print(f"policy reuse (algorithm 5), each persona held out: {first_rounds_text(settings.rounds)} in {PICKS_UNIT}; "
              "rounds until the greedy policy is within 1.10x the oracle")
        print(text_table(report.reuse))
    print()
    print("  ".join(f"{k}: {v:.2f} s" for k, v in report.timings.items()))
    print(f"report: {escaped(report.out / 'report.md')}")
    return 0
