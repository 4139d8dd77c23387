"""Participant ids after a deletion: never reused, never skipped (a new user's trial).

The rule (docs/study.md): p01, p02, ... in order of registration; an id is never reused, not even
after a deletion. The journal keeps no deleted id (the deletion rewrites it without their lines), so its
fold counts the ids given out: each registration left in it and each `ParticipantDeleted` (one
participant's). Before, a deletion added one to the next number on top of the highest id left, so
deleting p02 of p01..p03 made the next one p05 (p04 skipped); deleting the highest (p03) gave p04, right.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


@pytest.mark.parametrize("deleted, expected", [
    (["p02"], "p04"),  # not the highest: it was p05
    (["p01"], "p04"),  # the first: it was p05
    (["p03"], "p04"),  # the highest: never reused
    (["p02", "p03"], "p04"),  # it was p05 in memory after the first deletion
    (["p03", "p02", "p01"], "p04"),
])
def test_the_next_id_after_deletions_is_the_next_never_given(tmp_path, deleted, expected):
    data = StudyData.create(tmp_path / "study", STUDY)
    assert [data.register("phase1") for _ in range(3)] == ["p01", "p02", "p03"]
    for pid in deleted:
        data.delete_participant(pid)
        # the same number in the process that deleted and in a fresh read of the folder (the fold of the journal)
        assert f"p{data.state.next_number:02d}" == expected
        assert f"p{StudyData(data.folder).state.next_number:02d}" == expected
    assert data.register("phase1") == expected
    assert StudyData(data.folder).register("phase1") == f"p{int(expected[1:]) + 1:02d}"


def test_ids_after_deletion_and_registration_in_turn(tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    given = [data.register("phase1") for _ in range(4)]
    data.delete_participant("p02")
    given.append(data.register("phase1"))
    data.delete_participant("p05")
    data.delete_participant("p01")
    given.append(data.register("phase1"))
    assert given == ["p01", "p02", "p03", "p04", "p05", "p06"]
    assert sorted(StudyData(data.folder).state.participants) == ["p03", "p04", "p06"]
