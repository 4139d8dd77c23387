"""The view's fold: what a researcher sees after each event, without rerun."""

import msgspec
import numpy as np

from pairplay.core.geometry import card_of
from pairplay.schemas import events as ev
from pairplay.bench.view import scripted_events
from pairplay.services.view.model import Cell, Change, ViewModel, suggestion_parts


def fold(events):
    model = ViewModel()
    for e in events:
        model.apply(e)
    return model


def test_a_round_starts_covered_and_cards_turn_up_then_match_or_turn_back():
    events, _ = scripted_events(rounds=1, seed=3)
    model = ViewModel()
    for e in events[:2]:  # SessionStarted, RoundStarted
        model.apply(e)
    assert (model.cells() == Cell.COVERED).all()
    first_reveal = next(i for i, e in enumerate(events) if isinstance(e, ev.CardRevealed))
    for e in events[2:first_reveal + 1]:
        model.apply(e)
    card = events[first_reveal].card
    assert model.cells().flat[card] == Cell.FACE_UP
    resolved = next(i for i, e in enumerate(events) if isinstance(e, ev.TurnResolved))
    for e in events[first_reveal + 1:resolved + 1]:
        model.apply(e)
    turn = events[resolved]
    expected = Cell.MATCHED if turn.matched else Cell.COVERED
    assert model.cells().flat[turn.first] == expected and model.cells().flat[turn.second] == expected
    assert model.observed == -1 and model.candidates == 0  # highlights go with the turn


def test_the_whole_session_ends_with_every_card_matched_and_the_learners_q_table():
    events, q = scripted_events(rounds=2, seed=1)
    model = fold(events)
    assert (model.cells() == Cell.MATCHED).all()
    assert np.array_equal(model.q, q)
    assert not model.q_partial
    assert sorted(model.picks_per_round) == [0, 1] and all(p >= 18 for p in model.picks_per_round.values())
    assert model.ended == "completed"


def test_a_suggestion_reads_in_words_with_the_spoken_position_of_the_matching_card():
    # code 33 = hearing part 3 ("Try at row x and column y") with no visual part
    parts = suggestion_parts(33, target=card_of(1, 4))
    assert parts == {"speech": '"Try at row 2 and column 5"', "facial": "no expression",
                     "head": "head still", "gaze": "no gaze"}
    events, _ = scripted_events(rounds=1, seed=2)
    made = next(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade))
    exact = msgspec.structs.replace(events[made], action=33)
    model = fold(events[:made] + [exact])
    text = model.suggestion_text()
    row, col = exact.target // 6 + 1, exact.target % 6 + 1
    assert f'speech: "Try at row {row} and column {col}"' in text and "action 33" in text
    assert model.epsilon == 0.9 and model.alpha == 0.5
    assert model.candidates == 1 << exact.target  # the exact position names the matching card alone


def test_a_reported_candidate_set_replaces_the_computed_one():
    events, _ = scripted_events(rounds=1, seed=2)
    made = next(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade))
    model = fold(events[:made + 1])
    perceived = msgspec.structs.replace(events[made + 1], candidate_mask=0b101)
    changes, _ = model.apply(perceived)
    assert Change.HIGHLIGHT in changes and model.candidates == 0b101 and model.candidates_reported


def test_malformed_events_change_nothing_and_come_back_as_notes():
    events, _ = scripted_events(rounds=1, seed=0)
    model = fold(events[:3])
    before = (model.cells().copy(), model.q.copy())
    bad = [
        ev.CardRevealed(round=0, turn=0, card=99, face=0, pick=0),
        ev.SuggestionMade(round=0, turn=0, attempt=0, state=7, action=88, chosen_by="greedy", epsilon=0.1,
                          alpha=0.5, psi=0.0, observed=1, target=2),
        ev.QUpdated(round=0, turn=0, attempt=0, state=24, action=0, alpha=0.5, reward=1.0, q_before=0.0, q_after=0.5),
        ev.RoundStarted(round=1, faces=[0, 1]),
    ]
    for e in bad:
        changes, note = model.apply(e)
        assert changes == {Change.NOTE} and note.startswith("ignored")
    assert np.array_equal(model.cells(), before[0]) and np.array_equal(model.q, before[1])


def test_a_view_that_joins_late_says_its_q_table_is_partial():
    model = ViewModel()
    model.apply(ev.QUpdated(round=3, turn=2, attempt=0, state=5, action=40, alpha=0.5, reward=1.0,
                            q_before=0.4, q_after=0.7))
    assert model.q_partial and model.q[5, 40] == 0.7


def test_a_paced_recording_follows_the_envelope_times_scaled_by_speed(tmp_path):
    from pairplay.bench.view import write_recording
    from pairplay.services.view.sources import recording_items

    events, _ = scripted_events(rounds=1, seed=9, step_ns=10_000_000)  # 10 ms apart
    mcap = write_recording(events, tmp_path / "paced.mcap")
    now = [0.0]
    waits = []

    def sleep(s):
        waits.append(s)
        now[0] += s

    items = list(recording_items(mcap, speed=2.0, sleep=sleep, clock=lambda: now[0]))
    assert [e for e, _ in items] == events
    assert len(waits) == len(events) - 1 and np.allclose(waits, 0.005)  # 10 ms at twice the speed
    assert list(recording_items(mcap, speed=0.0, sleep=sleep.__call__)) and len(waits) == len(events) - 1


def test_no_event_content_makes_the_fold_or_its_drawing_raise():
    from hypothesis import given, settings, strategies as st

    any_int = st.integers(min_value=-2**40, max_value=2**40)
    event = st.one_of(
        st.builds(ev.CardRevealed, round=any_int, turn=any_int, card=any_int, face=any_int, pick=any_int),
        st.builds(ev.CardObserved, round=any_int, turn=any_int, card=any_int, observed_source=st.text(max_size=5)),
        st.builds(ev.SuggestionRequested, round=any_int, turn=any_int, attempt=any_int, state=any_int,
                  observed=any_int, match=any_int, covered_mask=any_int),
        st.builds(ev.SuggestionMade, round=any_int, turn=any_int, attempt=any_int, state=any_int, action=any_int,
                  chosen_by=st.text(max_size=5), epsilon=st.floats(), alpha=st.floats(), psi=st.floats(),
                  observed=any_int, target=any_int),
        st.builds(ev.SuggestionPerceived, round=any_int, turn=any_int, attempt=any_int, considered=st.booleans(),
                  consistent=st.booleans(), candidate_size=any_int, candidate_mask=any_int),
        st.builds(ev.TurnResolved, round=any_int, turn=any_int, first=any_int, second=any_int,
                  matched=st.booleans(), round_over=st.booleans()),
        st.builds(ev.QUpdated, round=any_int, turn=any_int, attempt=any_int, state=any_int, action=any_int,
                  alpha=st.floats(), reward=st.floats(), q_before=st.floats(), q_after=st.floats()),
        st.builds(ev.RoundStarted, round=any_int, faces=st.lists(any_int, max_size=20)),
        st.builds(ev.RoundEnded, round=any_int, turns=any_int, matches=any_int),
    )

    import rerun as rr

    from pairplay.services.view.rerun_logger import RerunView

    rec = rr.RecordingStream("pairplay-test")
    rec.memory_recording()  # nothing leaves the process

    any_time = st.integers(min_value=-2**63, max_value=2**63 - 1)
    stamped_event = st.tuples(event, any_time, any_int).map(
        lambda t: msgspec.structs.replace(t[0], time_ns=t[1], seq=t[2]))

    @settings(max_examples=300, deadline=None)
    @given(st.lists(stamped_event, max_size=12))
    def fold_never_raises(events):
        view = RerunView(rec)  # the fold and the drawing of it
        for e in events:
            view.handle(e)
        view.close()
        view.model.cells()
        view.model.suggestion_text()

    fold_never_raises()


def test_an_lspi_sample_shows_its_entry_and_an_out_of_range_one_is_a_note():
    model = ViewModel()
    changes, _ = model.apply(ev.LSPIUpdated(round=0, turn=1, attempt=0, state=5, action=40, reward=1.0, samples=10,
                                            improved=True, q_before=0.0, q_after=0.8, weights="ab"))
    assert changes == {Change.Q} and model.q[5, 40] == 0.8 and model.q_updates == 1
    bad = msgspec.structs.replace(ev.LSPIUpdated(round=0, turn=1, attempt=0, state=5, action=40, reward=1.0,
                                                 samples=11, improved=False, q_before=0.8, q_after=0.8), state=24)
    changes, note = model.apply(bad)
    assert changes == {Change.NOTE} and note.startswith("ignored LSPIUpdated") and model.q_updates == 1
