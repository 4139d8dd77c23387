"""Rebuild: recordings folded into policy files and learning curves.

Rule: a recording's policy is the fold of its QUpdated events (fold.py: the
learner's own update, bit for bit; an LSPI session's, of its LSPIUpdated samples) and its greedy actions use the study's
seeded tie-break (core.learning.greedy_policy seeded by the session's stream
seed, as core.study does), so a rebuilt policy file equals the one the
in-process study writes for the same seed and persona. Learning curves are per
round: turns (9 is perfect play), picks, total reward, learned updates and
inconsistent suggestions. A truncated recording rebuilds what it holds and
says so; a recording without SessionStarted is refused with the reason.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pairplay import __version__
from pairplay.core.learning import greedy_policy
from pairplay.core.personas import persona
from pairplay.core.policies import to_policy_file
from pairplay.schemas.policy import PolicyFile, write_policy
from pairplay.schemas.session import SessionConfig

from .fold import SessionFold, fold_events, stream_seed
from .reader import read_log


class RebuildError(ValueError):
    """A recording that cannot be rebuilt; the message says why."""


@dataclass
class Rebuilt:
    source: str
    config: SessionConfig
    fold: SessionFold
    policy: PolicyFile
    truncated: bool
    note: str = ""


def rebuild_events(events, source: str = "", truncated: bool = False, note: str = "") -> Rebuilt:
    fold = fold_events(events)
    if fold.config is None:
        raise RebuildError(f"{source or 'events'}: no SessionStarted: not a pairplay session recording")
    c = fold.config
    q = fold.q
    greedy = greedy_policy(q, np.random.default_rng(stream_seed(c)))
    who = None
    if c.participant.startswith("sim:"):
        try:
            who = persona(c.persona)
        except KeyError:
            who = None
    policy = to_policy_file(q, np.array(fold.visits), greedy, algorithm=c.algorithm,
                            participant=c.persona or c.participant, persona=who, seed=c.seed, game=c.game_index,
                            rounds=len(fold.rounds), config=c.learner_config(), software=__version__,
                            reward_bonus=c.reward_bonus, lspi=c.lspi_config() if fold.lspi is not None else None)
    return Rebuilt(source, c, fold, policy, truncated, note)


def rebuild_recording(path: str | Path) -> Rebuilt:
    log = read_log(path)
    note = f"truncated: {log.error}" if log.truncated else ""
    return rebuild_events((r.event for r in log.events), str(path), log.truncated, note)


CURVE_COLUMNS = ("round", "turns", "picks", "matches", "reward", "learned", "inconsistent")


def curve_rows(fold: SessionFold) -> list[dict]:
    return [{"round": r, "turns": s.turns, "picks": 2 * s.turns, "matches": s.matches, "reward": s.reward,
             "learned": s.learned, "inconsistent": s.inconsistent} for r, s in sorted(fold.rounds.items())]


def write_outputs(rebuilt: Rebuilt, out_dir: str | Path) -> list[Path]:
    """<session>.policy.json and <session>.curve.csv in `out_dir`."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = rebuilt.config.session
    policy_path = out_dir / f"{stem}.policy.json"
    write_policy(policy_path, rebuilt.policy)
    curve_path = out_dir / f"{stem}.curve.csv"
    with open(curve_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CURVE_COLUMNS)
        w.writeheader()
        w.writerows(curve_rows(rebuilt.fold))
    return [policy_path, curve_path]
