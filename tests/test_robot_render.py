"""The renderer turns every composite action into the robot commands the thesis describes."""

from __future__ import annotations

import json

import msgspec
import pytest

from pairplay.core.actions import N_ACTIONS, action, code_of_parts
from pairplay.core.geometry import card_of
from pairplay.schemas.robot import GESTURE_PRESETS, BoardCalibration, Point, RobotConfig
from pairplay.services.robot.backends import load_robot_config, parse_robot_url
from pairplay.services.robot.calibration import Board, CalibrationError, load_calibration
from pairplay.services.robot.render import Gesture, Look, Renderer, Say

CONFIG = RobotConfig()
BOARD = Board(load_calibration())


def xyz(p) -> tuple[float, float, float]:
    return (p.x, p.y, p.z)


def render(code: int, observed: int, target: int, gestures=GESTURE_PRESETS["iristk"]):
    return Renderer(BOARD, gestures, CONFIG).render(code, observed, target)


def commands(code: int, observed: int = card_of(1, 1), target: int = card_of(1, 4)):
    return [s.command for s in render(code, observed, target)]


def test_exact_position_speech_is_one_based_row_and_column_of_the_matching_card():
    steps = commands(code_of_parts(2, 0, 0, 0), target=card_of(1, 4))
    assert steps == [Say("Try at row 2 and column 5", abort=True)]


@pytest.mark.parametrize("speech, text", [(1, "It is the right card"), (3, "Maybe up"), (4, "Maybe down"),
                                          (5, "Maybe left"), (6, "Maybe right")])
def test_every_other_speech_says_its_table_text(speech, text):
    assert commands(code_of_parts(speech, 0, 0, 0)) == [Say(text)]


def test_smile_and_nod_use_the_configured_gesture_names():
    assert commands(code_of_parts(0, 1, 0, 0)) == [Gesture("smile")]
    thesis = [s.command for s in render(code_of_parts(0, 1, 1, 0), 3, 9, GESTURE_PRESETS["thesis"])]
    assert Gesture("smile_open") in thesis and Gesture("nod") in thesis
    today = [s.command for s in render(code_of_parts(0, 1, 1, 0), 3, 9, GESTURE_PRESETS["furhat"])]
    assert Gesture("BigSmile") in today and Gesture("Nod") in today


def test_nod_looks_at_the_observed_card_first():
    observed = card_of(0, 2)
    look, nod = commands(code_of_parts(0, 0, 1, 0), observed=observed)
    p = BOARD.card(observed)
    assert (look.x, look.y, look.z, look.head) == (p.x, p.y, p.z, False)
    assert nod == Gesture("nod")


def test_gaze_looks_at_the_matching_card():
    target = card_of(2, 5)
    (look,) = commands(code_of_parts(0, 0, 0, 1), target=target)
    p = BOARD.card(target)
    assert (look.x, look.y, look.z, look.head) == (p.x, p.y, p.z, False)


@pytest.mark.parametrize("head, rows, cols", [(2, 0, -1), (3, 0, 1), (4, -1, 0), (5, 1, 0),
                                              (6, -1, -1), (7, -1, 1), (8, 1, -1), (9, 1, 1)])
def test_head_turn_is_a_head_gaze_sequence_towards_the_direction_and_back(head, rows, cols):
    observed = card_of(1, 2)
    steps = render(code_of_parts(0, 0, head, 0), observed, card_of(0, 0))
    assert [s.at_s for s in steps] == [0.0, CONFIG.head_turn_lead_s, CONFIG.head_turn_lead_s + CONFIG.head_turn_hold_s]
    start, turn, back = (s.command for s in steps)
    assert all(isinstance(c, Look) and c.head for c in (start, turn, back))
    assert (start.x, start.y, start.z) == xyz(BOARD.card(observed))
    assert (back.x, back.y, back.z) == xyz(BOARD.rest)
    # the turn point lies towards the neighbouring card in that direction
    neighbour = xyz(BOARD.card(card_of(1 + rows, 2 + cols)))
    here = xyz(BOARD.card(observed))
    towards = sum((n - h) * (t - h) for n, h, t in zip(neighbour, here, (turn.x, turn.y, turn.z)))
    assert towards > 0


def test_head_turns_follow_the_board_not_the_robot_frame():
    """Mirror the board (the robot sits beside it): "left" still points to column 0."""
    mirrored = BoardCalibration(cards=[Point(-p.x, p.y, p.z) for p in BOARD.calibration.cards])
    renderer = Renderer(Board(mirrored), GESTURE_PRESETS["iristk"], CONFIG)
    turn = renderer.render(code_of_parts(0, 0, 2, 0), card_of(1, 3), 0)[1].command
    assert (turn.x - mirrored.cards[card_of(1, 3)].x) * (mirrored.cards[0].x - mirrored.cards[5].x) > 0


def test_speech_goes_first_and_every_action_renders():
    for code in range(N_ACTIONS):
        steps = render(code, card_of(1, 1), card_of(2, 4))
        parts = action(code)
        if parts.speech:
            assert isinstance(steps[0].command, Say)
        assert len(steps) == (parts.speech > 0) + parts.facial + (2 if parts.head == 1 else 3 if parts.head else 0) + parts.gaze


def test_off_board_cards_and_unknown_codes_are_refused():
    with pytest.raises(ValueError, match="off the board"):
        render(3, 18, 0)
    with pytest.raises(ValueError, match="outside"):
        render(88, 0, 1)


def test_default_calibration_has_18_cards_and_a_rest_point():
    assert len(BOARD.calibration.cards) == 18


@pytest.mark.parametrize("doc, reason", [
    ({"cards": [[0, 0, 1]] * 17}, "needs 18"),
    ({"cards": [[0.1 * i, 0, 1] for i in range(18)], "rest": [0, 0, 100]}, "metres"),
    ({"cards": [[0, 0, 1]] * 18}, "directions"),
    ({"cards": [[0, 0, 1]] * 18, "colour": "red"}, "not valid"),
])
def test_a_bad_calibration_file_is_refused_with_the_reason(tmp_path, doc, reason):
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibrationError, match=reason):
        load_calibration(path)


def test_a_corrupt_calibration_file_is_refused(tmp_path):
    path = tmp_path / "calibration.json"
    path.write_bytes(b'{"cards": [[0, 0')
    with pytest.raises(CalibrationError, match="not valid"):
        load_calibration(path)
    with pytest.raises(CalibrationError, match="cannot read"):
        load_calibration(tmp_path / "missing.json")


def test_robot_urls_choose_the_backend_and_its_gesture_names():
    scheme, host, port, config, _ = parse_robot_url("iristk://robot.local")
    assert (scheme, host, port, config.gestures) == ("iristk", "robot.local", 1932, GESTURE_PRESETS["iristk"])
    scheme, host, port, config, _ = parse_robot_url("furhat://10.0.0.5?key=abc")
    assert (scheme, port, config.realtime_key, config.gestures) == ("furhat", 9000, "abc", GESTURE_PRESETS["furhat"])
    _, _, port, config, _ = parse_robot_url("iristk://h:2000?ticket=lab&gestures=thesis")
    assert (port, config.iristk_ticket, config.gestures.smile) == (2000, "lab", "smile_open")
    assert parse_robot_url("virtual?time_scale=0.5")[4] == {"time_scale": 0.5}


@pytest.mark.parametrize("url, reason", [("ros://h", "unknown backend"), ("iristk://", "needs a host"),
                                         ("iristk://h:99999", "bad port"), ("furhat://h?colour=1", "unknown parameter"),
                                         ("iristk://h?gestures=odd", "gestures must be"),
                                         # before (a new user's trial): :0 became the default port without a word
                                         ("iristk://127.0.0.1:0", "bad port"), ("furhat://h:0", "bad port")])
def test_bad_robot_urls_are_refused(url, reason):
    with pytest.raises(ValueError, match=reason):
        parse_robot_url(url)


def test_robot_config_files_are_strict(tmp_path):
    path = tmp_path / "robot.json"
    path.write_bytes(msgspec.json.encode({"ack_timeout_s": 3.0, "gestures": {"smile": "grin", "nod": "bob"}}))
    config = load_robot_config(str(path))
    assert config.ack_timeout_s == 3.0 and config.gestures.smile == "grin"
    path.write_text('{"ack_timeout": 3}')
    with pytest.raises(ValueError, match="not valid"):
        load_robot_config(str(path))
    path.write_text('{"speech": {"exact": "Row {row}"}}')
    with pytest.raises(ValueError, match="column"):
        load_robot_config(str(path))
