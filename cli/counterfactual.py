"""`pairplay counterfactual REC`: fit a simulated user to a recorded participant, then play other learners against it.

Rule: the recording's turns (replay/turns.py) give the fitted user
(core/userfit.py: maximum likelihood over the thesis's persona scale, with
95% sets); each arm of --policy (core/counterfactual.py) plays that user for
the recording's rounds on --seeds seeds; the recording and the arms are
compared on picks per round and the share of suggestions followed by a
match. Everything goes into the --out folder, written whole or not at all
(report/counterfactual.py); a non-empty folder is replaced only with --force,
checked before any work. A REC that is missing, empty, not MCAP, without a
session or without a resolved turn, an unknown arm, a policy file that cannot
be read (named with its arm, `--policy reuse:FILE: cannot read`), an arms' option
(--policy, --seeds, --seed, --rounds) given with --fit-only, which plays no arm:
one line, exit 2, nothing written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pairplay.cli.args import add_force, count, int_at_least, note_given, option_policy, output_folder, seed_number
from pairplay.errors import escaped
from pairplay.numbers import counted

ARMS_HELP = ("comma-separated arms: same (the recorded learner, replayed: checks the fit), q (Q-learning from "
             "scratch), final (the recorded learner's final policy, fixed), oracle (the best policy for the fitted "
             "user), alone (no suggestion), reuse:FILE (pi-reuse of a policy file), fixed:FILE (a policy file "
             "played as it is)")


EPILOG = ("The fitted user is the persona (focus, hearing, sight, memory on the thesis's 1..6 scale) of maximum "
          "likelihood for the recorded picks, each feature with its 95% profile-likelihood set; it is saved as "
          "OUT/<REC name>.usermodel.json. Each arm plays it on the same seeds (the same deals); OUT/counterfactual.md "
          "compares them with the recording (picks per round, turns whose second pick matched), with "
          "counterfactual.csv (every simulated round) and counterfactual.png. README: 'Walkthrough: "
          "counterfactual replay of a recorded participant'.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = EPILOG
    p.add_argument("recording", metavar="REC", help="MCAP recording of one session (a simulated user or a person)")
    p.add_argument("--fit-also", nargs="+", default=[], metavar="REC",
                   help="more recordings of the same participant (same observed-card source) whose turns join the "
                        "fit; the arms are still compared with REC")
    p.add_argument("--policy", default="same,final,oracle", help=ARMS_HELP)
    p.add_argument("--seeds", type=int_at_least(2), default=10, help="seeds per arm (the same deals in every arm)")
    p.add_argument("--seed", type=seed_number, default=0, help="names the arms' seeds")
    p.add_argument("--rounds", type=count, default=None,
                   help="rounds each arm plays (default: as many as the recording completed)")
    p.add_argument("--out", type=output_folder, default=None, help="output folder (default: out/counterfactual/<recording name>)")
    p.add_argument("--fit-only", action="store_true",
                   help="write the fitted user alone, play no arm (--policy, --seeds, --seed, --rounds refused)")
    add_force(p, "the files of a non-empty --out folder")
    for action in p._actions:  # the arms' options, refused with --fit-only rather than ignored (`refuse_fit_only`)
        if action.dest in ARM_OPTIONS:
            note_given(action)


ARM_OPTIONS = ("policy", "seeds", "seed", "rounds")  # what only the arms use: --fit-only plays none


def refuse_fit_only(args: argparse.Namespace) -> None:
    """OptionError naming the first arms' option given with --fit-only, which plays no arm (a new user's
    trial: `--fit-only --policy same` exited 0, the arm ignored without a word)."""
    from pairplay.errors import OptionError

    for dest, option in getattr(args, "_given", ()):
        if args.fit_only and dest in ARM_OPTIONS:
            raise OptionError(f"{option} {getattr(args, dest)} is not taken with --fit-only: it plays no arm; "
                              f"leave out one or the other", option)


def parse_arms(text: str) -> list[tuple[str, str]]:
    """[(name, policy file or '')] of a --policy list; OptionError for an unknown or repeated arm."""
    from pairplay.errors import OptionError
    from pairplay.report.counterfactual import ARM_TEXT

    from pairplay.lists import comma_items, repeated
    from pairplay.nearest import nearest

    arms: list[tuple[str, str]] = []
    try:
        items = comma_items(text)
    except ValueError as exc:
        raise OptionError(str(exc), "--policy") from None
    for item in items:
        kind, _, path = item.partition(":")
        if kind in ARM_TEXT and not path:
            arms.append((kind, ""))
        elif kind in ("reuse", "fixed") and path:
            arms.append((item, path))
        else:
            # the arm meant (pairplay/nearest.py): `sme` is same, `reus:p.json` reuse:p.json, `reuse` lacks its file
            meant = kind if kind in ("reuse", "fixed") else nearest(kind, [*ARM_TEXT, "reuse", "fixed"])
            if meant in ("reuse", "fixed"):
                meant = f"{meant}:{path or 'FILE'}"
            hint = f" (did you mean {meant!r}?)" if meant else ""
            raise OptionError(f"unknown arm {item!r}{hint}: give same, q, final, oracle, alone, reuse:FILE or fixed:FILE",
                              "--policy")
    if twice := repeated(a[0] for a in arms):
        raise OptionError(f"the arm {twice} is given twice: each arm is measured once", "--policy")
    return arms


def check_size(arms: int, seeds: int, rounds: int, lspi: int = 0) -> None:
    """OptionError if the arms' batches (`lspi` of them LSPI arms) would hold more than core/simulate.py
    MEMORY_LIMIT (`--rounds 100000000` was a MemoryError traceback), naming --seeds if the default 10 would fit."""
    from pairplay.core.counterfactual import arms_bytes
    from pairplay.core.simulate import MEMORY_LIMIT, gigabytes
    from pairplay.errors import OptionError

    need = arms_bytes(arms, seeds, rounds, lspi)
    where = (f"--seeds {seeds}" if seeds > 10 and arms_bytes(arms, 10, rounds, lspi) <= MEMORY_LIMIT
             else f"--rounds {rounds}")
    if need > MEMORY_LIMIT:
        raise OptionError(f"{counted(arms, 'arm')} x {counted(seeds, 'seed')} x {counted(rounds, 'round')} would hold about "
                          f"{gigabytes(need)} of memory (every turn is kept for counterfactual.csv), over the "
                          f"{gigabytes(MEMORY_LIMIT)} allowed: give fewer rounds, seeds or arms", where)


def run(args: argparse.Namespace) -> int:
    import msgspec
    import numpy as np

    from pairplay import __version__
    from pairplay.core import counterfactual as cf
    from pairplay.core.rng import game_seed
    from pairplay.core.userfit import fit_user, pooled
    from pairplay.errors import InputError
    from pairplay.outputs import check_output_folder, hold
    from pairplay.replay.check import check_recording, session_events
    from pairplay.replay.rebuild import output_stem, rebuild_events
    from pairplay.replay.turns import read_turns, turns_from_events
    from pairplay.report.counterfactual import (ARM_TEXT, COUNTERFACTUAL_MANIFEST, COUNTERFACTUAL_OUTPUTS, Recorded,
                                               console_text, write_counterfactual)
    from pairplay.schemas.session import MODE_OF_ALGORITHM

    refuse_fit_only(args)
    arms_wanted = parse_arms(args.policy)
    if args.rounds and not args.fit_only:  # before any work
        check_size(len(arms_wanted), args.seeds, args.rounds)
    rec = check_recording(args.recording)
    stem = output_stem(rec)
    out = Path(args.out) if args.out else Path("out") / "counterfactual" / stem
    hold(out, "counterfactual")  # one writer per output (pairplay/outputs.py)
    check_output_folder(out, args.force, COUNTERFACTUAL_OUTPUTS, COUNTERFACTUAL_MANIFEST)
    from pairplay.replay.copies import Copies
    # a study's recording fitted (or its policies played): a copy of its participant's data their deletion must know
    copies = Copies("counterfactual", [rec, *args.fit_also, *(path for _, path in arms_wanted if path)])
    copies.check([out])
    files = {path: option_policy(path, f"--policy {name}") for name, path in arms_wanted if path}

    # its events alone kept, not the file's records and their bytes (check.session_events): fitted in one pass, and
    # played again for the final policy (rebuild_events)
    log, events = session_events(rec)
    note = log.missing  # what its damage, cut and undecodable messages lost (reader.EventLog), as rebuild's
    turns = turns_from_events(events, str(rec), note)
    config = turns.config
    from pairplay.cli.main import left_journals, warn

    # warnings about the fit, on stderr, -q or not (cli/main.py: on stdout, -q hid them with the summary)
    for why in turns.skipped:
        warn("counterfactual", f"{rec}: turn left out of the fit: {why}")
    if note:
        warn("counterfactual", f"{rec}: not whole ({note}); fitting the "
                               f"{counted(len(turns.observations.first), 'turn')} of its intact parts")
    elif log.loss_free:  # damaged where no event was: fitted whole, the damage said (reader.EventLog.loss_free)
        warn("counterfactual", f"{rec}: {log.loss_free}")
    left_journals("counterfactual", [rec, *args.fit_also])  # what a cut one's journal holds beyond it
    seen = {rec.resolve()}
    for path in args.fit_also:
        if Path(path).resolve() in seen:
            raise InputError("given twice", path)
        seen.add(Path(path).resolve())
    others = [read_turns(path) for path in args.fit_also]
    from pairplay.replay.onesession import check_once, started_by
    # one session's turns twice (REC and its recovered copy, or a copy of it): counted double in the fit
    first = next(e for e in events if type(e).__name__ == "SessionStarted")  # (check.session_events: one is)
    check_once([(str(rec), started_by(first, log))] + [(other.source, other.started) for other in others])
    for other in others:
        if other.config.participant != config.participant or other.config.observed_source != config.observed_source:
            raise InputError(f"participant {other.config.participant} ({other.config.observed_source}) is not "
                             f"{config.participant} ({config.observed_source}) of {rec.name}: fit one participant "
                             "at a time", other.source)
        for why in other.skipped:
            warn("counterfactual", f"{other.source}: turn left out of the fit: {why}")
        if other.note:
            warn("counterfactual", f"{other.source}: not whole ({other.note}); fitting the "
                                   f"{counted(len(other.observations.first), 'turn')} of its intact parts")
    fit = fit_user(pooled([turns.observations] + [o.observations for o in others]), config.observed_source)
    model = cf.to_user_model(fit, recording=rec.name, fitted_on=[rec.name] + [Path(p).name for p in args.fit_also], session=config.session, participant=config.participant,
                             observed_source=config.observed_source, software=__version__)
    # the files carry what the fit lacked (a damaged or cut recording's intact parts), not only the console
    partial = "; ".join(f"{Path(t.source).name}: {t.note}" for t in [turns, *others] if t.note)
    model = msgspec.structs.replace(model, partial=partial)
    obs = turns.observations
    shown = obs.action >= 0
    recorded = Recorded(turns.picks_per_round, float((obs.second[shown] == obs.match[shown]).mean()) if shown.any()
                        else 0.0, int(shown.sum()))
    runs, texts = None, dict(ARM_TEXT)
    if not args.fit_only:
        rounds = args.rounds or len(turns.picks_per_round)
        if rounds < 1:
            raise InputError("completed no round: give --rounds for the arms to play", rec)
        same_mode = MODE_OF_ALGORITHM[config.algorithm]
        check_size(len(arms_wanted), args.seeds, rounds, int(same_mode == "lspi" and ("same", "") in arms_wanted))
        learner = config.learner_config()
        persona = model.persona
        arms = []
        for name, path in arms_wanted:
            if name == "same":
                table = np.asarray(config.policy_actions) if same_mode in ("reuse", "fixed") else None
                arms.append(cf.Arm(name, same_mode, learner, table,
                                   config.lspi_config() if same_mode == "lspi" else None))
            elif name == "q":
                arms.append(cf.Arm(name, "q", learner))
            elif name == "final":
                final = rebuild_events(events, str(rec)).policy.greedy
                arms.append(cf.Arm(name, "fixed", learner, np.asarray(final)))
            elif name == "oracle":
                arms.append(cf.Arm(name, "fixed", learner,
                                   cf.oracle_policy(persona, args.seed, config.reward_bonus)))
            elif name == "alone":
                arms.append(cf.Arm(name, "fixed", learner, cf.user_alone()))
            else:
                kind = name.partition(":")[0]
                arms.append(cf.Arm(name, kind, learner, np.asarray(files[path].greedy)))
                # a partial policy's arm says so where its results are (core/policies.py partial_inputs)
                partial = " (a partial policy)" if files[path].partial else ""
                texts[name] = f"{'pi-reuse of' if kind == 'reuse' else 'fixed'} {Path(path).name}{partial}"
        seeds = [game_seed(args.seed, f"counterfactual:{config.session}", i) for i in range(args.seeds)]
        runs = cf.run_arms(persona, arms, seeds, rounds, config.observed_source, config.reward_bonus)
    paths = write_counterfactual(out, stem, model, recorded, runs, texts, args.force,
                                 read_whole=f"{rec.name}: {log.loss_free}" if log.loss_free else "")
    copies.journal(paths)
    print("\n".join(escaped(line) for line in console_text(model, recorded, runs, texts).splitlines()))  # file names
    print(escaped("wrote " + ", ".join(str(p) for p in paths)))
    return 0
