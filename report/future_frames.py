"""The study report's section on frame-of-reference calibration (thesis chapter 8, future work 2).

Rule: like report/future.py, one function takes the result of the core
experiment (core/frame_study.py), writes its CSV (frames.csv) and its figure
(frames.png, through `draw`, the study's figure process) into the report folder
and returns the section's markdown lines. Picks per round (18 = perfect play;
lower is better), mean and standard deviation over the replicates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pairplay import csvcell
from pairplay.core.frame_study import frame_experiment
from pairplay.core.frames import FRAME_PERSONAS, FRAMES
from pairplay.numbers import counted


def frames_lines(out: Path, seed: int, rounds: int, reward_bonus: str, markdown_table, draw) -> list[str]:
    """Run the experiment on the frame personas (core/data/frame_personas.json) and write its section."""
    exp = frame_experiment(list(FRAME_PERSONAS.values()), seed, rounds=rounds, reward_bonus=reward_bonus)
    return frames_section(out, exp, markdown_table, draw)


def _cell(x: np.ndarray) -> str:
    return f"{x.mean():.2f} \u00b1 {x.std():.2f}"


def frames_section(out: Path, exp, markdown_table, draw) -> list[str]:
    """Future work 2 from a core.frame_study.FrameExperiment; `draw(name, *args)` draws a report/plots.py figure."""
    picks = exp.picks  # (arms, replicates, personas)
    R = picks.shape[1]
    names = [FRAME_PERSONAS[k].persona.name for k in exp.persona]
    without, with_ = exp.arms.index("merge without calibration"), exp.arms.index("merge with calibration")
    rows = [["persona (frame)", *exp.arms, "with minus without"]]
    for j, name in enumerate(names):
        rows.append([name, *[_cell(picks[k, :, j]) for k in range(len(exp.arms))],
                     f"{(picks[with_, :, j] - picks[without, :, j]).mean():+.2f}"])
    mirrored = exp.frame != 0
    for label, cols in (("mean, all users", slice(None)), ("mean, mirrored users", mirrored),
                        ("mean, robot's-frame users", ~mirrored)):
        per_rep = picks[:, :, cols].mean(axis=2)  # (arms, replicates)
        rows.append([label, *[_cell(per_rep[k]) for k in range(len(exp.arms))],
                     f"{(per_rep[with_] - per_rep[without]).mean():+.2f}"])
    with open(out / "frames.csv", "w", newline="") as f:
        csvcell.writer(f).writerows(rows)
    acc_rows = [["persona (frame)", *[counted(n, "suggestion") for n in exp.lengths]]]
    acc_rows += [[name, *[f"{100 * a:.1f}%" for a in acc]] for name, acc in zip(names, exp.accuracy)]
    draw("frame_calibration", names, {arm: picks[k] for k, arm in enumerate(exp.arms)}, list(exp.lengths),
         exp.accuracy, out / "frames.png", R, exp.accuracy_sessions)
    all_diff = picks[with_].mean(axis=1) - picks[without].mean(axis=1)  # (replicates,)
    mir_diff = picks[with_][:, mirrored].mean(axis=1) - picks[without][:, mirrored].mean(axis=1)
    enough = [n for n, a in zip(exp.lengths, exp.accuracy.min(axis=0)) if a >= 0.95]
    needs = f"{counted(enough[0], 'suggestion')} are right in at least 95% of rounds for every user" if enough else \
        "no round length measured is right in 95% of rounds for every user"
    frames = ", ".join(f"{FRAMES[f]}" for f in range(len(FRAMES)))
    return [
        "## Frame-of-reference calibration (future work 2)", "",
        "The human study (7.3) saw users count columns from the right and read the head turned up or down the "
        f"other way round; chapter 8 proposes a preliminary test of the user's frame. Five personas of their "
        f"own table (core/data/frame_personas.json; frames: {frames}) each learn alone with Q-learning, "
        f"the robot speaking and turning its head in its own frame, so a mirrored user's policy is right only "
        f"in that user's frame. Per replicate ({R}, disjoint games) one policy a user; all five are merged "
        "with algorithm 4 as they are ('without calibration'), and again after a calibration round of "
        f"{counted(exp.trials, 'suggestion')} with known answers at the start of each session inferred each user's frame, "
        "moved every policy to the robot's frame before the merge and the merge back into each user's "
        "inferred frame when played ('with calibration'). Every column plays the same evaluation games "
        f"({counted(exp.eval_rounds, 'round')} per user and replicate, epsilon 0); picks per round, lower is better.", "",
        markdown_table(rows), "",
        f"With minus without calibration: {all_diff.mean():+.2f} \u00b1 {all_diff.std():.2f} picks per round over "
        f"all users, {mir_diff.mean():+.2f} \u00b1 {mir_diff.std():.2f} over the mirrored ones (mean \u00b1 sd "
        f"over the {R} replicates). States the merge settled by Q (an Error of the algebra): "
        f"{exp.errors_resolved[0].mean():.1f} without, {exp.errors_resolved[1].mean():.1f} with calibration. "
        f"{100 * exp.calibrated_right:.1f}% of the experiment's calibration rounds inferred the right frame. "
        "A mirrored user's own policy stays behind the merge with calibration: 'Try at row x and column y' "
        "names a wrong card to it until the robot says the coordinates in its frame.", "",
        f"The calibration round alone ({counted(exp.accuracy_sessions, 'simulated round')} per user and length; "
        "suggestions alternate 'Try at row x and column y' with a card in the top or bottom row and a diagonal "
        f"head turn; ties go to the robot's frame): {needs}.", "",
        markdown_table(acc_rows), "",
        "![frames](frames.png)", "",
    ]
