"""Merging across mirrored users, with and without calibration (chapter 8, future work 2).

Rule: the personas of core/data/frame_personas.json (some read the board
mirrored, core/frames.py) each learn alone with Q-learning, the robot
rendering its actions as it always does (no calibration), so a mirrored user's
policy is right for that user in that user's frame. Per replicate (disjoint
games), one policy a user, all users are merged with algorithm 4 two ways:
  "merge without calibration": the policies as learned (the thesis's way),
      played to every user as they are;
  "merge with calibration": a calibration round at the start of each training
      session (core/calibration.py) gives the user's frame; each policy and Q-table
      is moved to the canonical frame by it before the merge (frames.to_frame),
      and each evaluation session starts with its own calibration round and
      renders the merged policy in the frame inferred there.
Beside them, "user alone" and "own policy" (each user's own learned policy, in
its own frame). Every arm plays the same evaluation games of each user (same
deals and user draws), epsilon 0. The calibration's accuracy is measured on
its own, by round length. Seeds: game g of persona P in replicate r is
game_seed(seed, "frames:" + key, r) for training and EVAL_GAME_OFFSET + g for
evaluation; the calibration rounds draw from generators seeded the same way.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig

from . import calibration
from .combine import User, combine, extract_info
from .frames import FramedPersona, frame_index, mismatch, to_frame
from .learning import greedy_policy
from .oracle import USER_ALONE
from .rng import game_seed
from .simulate import run_games
from .study import EVAL_GAME_OFFSET

ARMS = ("user alone", "own policy", "merge without calibration", "merge with calibration")
ACCURACY_LENGTHS = (1, 2, 3, 4, 6, 8)


class FrameExperiment(NamedTuple):
    persona: list[str]
    frame: np.ndarray  # (P,) each persona's true frame
    arms: tuple[str, ...]
    picks: np.ndarray  # (arms, replicates, personas): mean picks per round, epsilon 0
    trials: int  # suggestions in each calibration round of the experiment
    eval_rounds: int  # rounds each policy plays per user, replicate and evaluation game
    calibrated_right: float  # share of the experiment's calibration rounds (training and evaluation) that were right
    errors_resolved: np.ndarray  # (2, replicates): states the merge settled by Q (Errors), without / with calibration
    lengths: tuple[int, ...]  # calibration round lengths measured
    accuracy: np.ndarray  # (P, lengths): share of rounds whose inferred frame is right
    accuracy_sessions: int


def _rng(seed: int, label: str, index: int) -> np.random.Generator:
    return np.random.default_rng(game_seed(seed, label, index))


def _calibrate(personas, frames, trials: int, rng: np.random.Generator) -> np.ndarray:
    """The frame a calibration round of `trials` suggestions infers for each (persona, true frame) session."""
    design = calibration.design(len(personas), trials, rng)
    return calibration.infer(design, calibration.respond(personas, frames, design, rng))[0]


def frame_experiment(framed: Sequence[FramedPersona], seed: int, replicates: int = 5, rounds: int = 500,
                     eval_games: int = 1, eval_rounds: int = 60, trials: int = 6, accuracy_sessions: int = 200,
                     lengths: Sequence[int] = ACCURACY_LENGTHS, config: LearnerConfig = LearnerConfig(),
                     reward_bonus: str = DEFAULT_REWARD_BONUS) -> FrameExperiment:
    """Train, calibrate, merge and evaluate (see the module rule); one batch for training, one for evaluation."""
    personas = [fp.persona for fp in framed]
    truth = np.array([frame_index(fp.frame) for fp in framed], dtype=np.int64)
    P, R = len(personas), replicates
    # training: replicate-major, one game per persona and replicate, the robot's own rendering (frame = truth)
    flat = [p for _ in range(R) for p in personas]
    flat_truth = np.tile(truth, R)
    seeds = [game_seed(seed, "frames:" + p.key, r) for r in range(R) for p in personas]
    result = run_games(flat, seeds, rounds, config, frames=flat_truth, reward_bonus=reward_bonus)
    greedy = np.stack([greedy_policy(q, np.random.default_rng(s)) for q, s in zip(result.q, seeds)])
    inferred_train = _calibrate(flat, flat_truth, trials, _rng(seed, "frames:calibrate-training", 0))
    canon_policy, canon_q = to_frame(greedy, inferred_train, result.q)

    merged_raw, merged_canon, errors = [], [], np.zeros((2, R), dtype=np.int64)
    for r in range(R):
        rows = range(r * P, (r + 1) * P)
        for k, (pol, q, out) in enumerate(((greedy, result.q, merged_raw), (canon_policy, canon_q, merged_canon))):
            users = [User(flat[i].key, pol[i], q[i], extract_info(pol[i][None]).info) for i in rows]
            m = combine(users)
            out.append(m.policy)
            errors[k, r] = sum(":error->Q" in rule for rule in m.rules)

    # evaluation: arm-major, then replicate, persona, game; every arm plays the same games of a persona
    game = np.tile(np.arange(eval_games), len(ARMS) * R * P)
    who = np.tile(np.repeat(np.arange(P), eval_games), len(ARMS) * R)
    rep = np.tile(np.repeat(np.arange(R), P * eval_games), len(ARMS))
    arm = np.repeat(np.arange(len(ARMS)), R * P * eval_games)
    eval_personas = [personas[i] for i in who]
    n_eval = who.size
    inferred_eval = _calibrate(eval_personas, truth[who], trials, _rng(seed, "frames:calibrate-evaluation", 0))
    policy = np.empty((n_eval, USER_ALONE.size), dtype=np.int64)
    policy[arm == 0] = USER_ALONE
    policy[arm == 1] = greedy[(rep * P + who)[arm == 1]]
    policy[arm == 2] = np.array(merged_raw)[rep[arm == 2]]
    policy[arm == 3] = np.array(merged_canon)[rep[arm == 3]]
    rendered = np.where(arm == 3, inferred_eval, 0)  # only the calibrated arm renders in the user's frame
    eval_seeds = [game_seed(seed, "frames:" + p.key, EVAL_GAME_OFFSET + int(g)) for p, g in zip(eval_personas, game)]
    played = run_games(eval_personas, eval_seeds, eval_rounds, mode="fixed", policy=policy,
                       frames=mismatch(truth[who], rendered))
    per_game = played.picks.sum(axis=1, dtype=np.float64) / eval_rounds
    picks = per_game.reshape(len(ARMS), R, P, eval_games).mean(axis=3)

    right = np.concatenate([inferred_train == flat_truth, inferred_eval[arm == 3] == truth[who][arm == 3]])
    acc = calibration.accuracy(personas, truth, lengths, accuracy_sessions, _rng(seed, "frames:accuracy", 0))
    return FrameExperiment([p.key for p in personas], truth, ARMS, picks, trials, eval_rounds, float(right.mean()),
                           errors, tuple(lengths), acc, accuracy_sessions)
