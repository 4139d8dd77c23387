"""The study's evaluations are one batch (core/study.py Evaluations, report/future.py SECTIONS).

A row's result does not depend on what else is queued: rows repeating a game
(same persona, game index and policy) are played once, a shorter row reading
the first rounds of a longer one; and the study plays every evaluation, the
future-work sections' included, in a single batch.
"""

import numpy as np
import pytest

from pairplay.core import study
from pairplay.core.oracle import USER_ALONE
from pairplay.core.personas import persona


def _policy(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 88, 24)


def test_a_row_reads_the_same_picks_alone_or_sharing_its_game_with_longer_and_repeated_rows():
    blind, deaf = persona("blind"), persona("deaf")
    alone = study.evaluate([blind], _policy(1)[None], 30, 5)
    batch = study.Evaluations(5)
    long = batch.add([blind, deaf], np.stack([_policy(1), _policy(1)]), 70)
    short = batch.add([blind, blind, blind], np.stack([_policy(1), _policy(1), USER_ALONE]), 30, [0, 0, 0])
    assert batch.total_rounds == 70 + 70 + 30  # blind's game 0 under policy 1 is played once, for 70 rounds
    picks = batch.play()
    assert picks[short][0] == picks[short][1] == alone[0]
    assert picks[short][2] != picks[short][0]  # another policy: a game of its own
    assert picks[long][0] == study.evaluate([blind], _policy(1)[None], 70, 5)[0]
    assert picks[long][1] == study.evaluate([deaf], _policy(1)[None], 70, 5, [1])[0]


def test_nothing_is_queued_after_the_batch_has_played():
    batch = study.Evaluations(0)
    batch.add([persona("blind")], USER_ALONE[None], 5)
    batch.play()
    with pytest.raises(RuntimeError, match="queue every request before play"):
        batch.add([persona("blind")], USER_ALONE[None], 5)


def test_the_study_plays_every_evaluation_future_work_included_in_one_batch(tmp_path, monkeypatch):
    from pairplay.report.study import StudySettings, run_study
    played = []
    original = study.Evaluations.play

    def play(self, progress=None):
        played.append(len(self._rounds))
        return original(self, progress)
    monkeypatch.setattr(study.Evaluations, "play", play)
    run_study(StudySettings(personas="blind,deaf", games=5, rounds=30, eval_rounds=10, reuse_seeds=2,
                            reuse_last=5), tmp_path / "s", figures_in_background=False)
    assert len(played) == 1
    assert (tmp_path / "s" / "precombination.csv").exists() and (tmp_path / "s" / "precombination.png").exists()
