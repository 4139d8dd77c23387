"""A key an older pairplay's file holds and this one retired is refused saying so, with what replaced it.

An old robot config with `iristk_subscriber_wait_s` (retired when IrisTK events nobody subscribes to became held
for `give_up_s`) was refused as a typo: "did you mean `iristk_subscribe`?", a key of another meaning, which a
researcher would have "fixed" into a broken filter. Retired keys are data (a Struct's `RETIRED` table,
schemas/jsonfile.py `retired_key`); every retired key of every file kind is checked here, and a typo still gets
its did-you-mean.
"""

from __future__ import annotations

import json

import msgspec
import pytest

from pairplay.schemas.robot import RobotConfig
from pairplay.services.robot.backends import load_robot_config


@pytest.mark.parametrize("key, value", [("iristk_subscriber_wait_s", 5.0), ("iristk_wait_for_subscriber", True)])
def test_a_retired_robot_config_key_is_refused_as_retired_naming_its_replacement(tmp_path, key, value):
    (tmp_path / "old.json").write_text(json.dumps({"ack_timeout_s": 10.0, key: value}))
    with pytest.raises(ValueError) as err:
        load_robot_config(str(tmp_path / "old.json"))
    line = str(err.value)
    assert "\n" not in line and "did you mean" not in line, line
    assert f"the key `{key}` was retired" in line and "`give_up_s`" in line and "remove it from the file" in line, line


def test_the_verb_says_it_in_one_line(tmp_path, pairplay_cli):
    (tmp_path / "old.json").write_text('{"iristk_subscriber_wait_s": 5.0}\n')
    r = pairplay_cli("robot", "--try", "3", "--robot-config", "old.json", cwd=tmp_path)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "old.json" in lines[0] and "`iristk_subscriber_wait_s` was retired" in lines[0], lines[0]


def test_every_retired_key_is_no_key_of_today_and_a_typo_still_gets_its_suggestion(tmp_path):
    """A retired key that is a field again would never reach the table: the table would lie."""
    fields = {f.encode_name for f in msgspec.structs.fields(RobotConfig)}
    assert RobotConfig.RETIRED and not set(RobotConfig.RETIRED) & fields
    (tmp_path / "typo.json").write_text('{"iristk_subscrbe": "monitor.**"}')
    with pytest.raises(ValueError, match=r"no key `iristk_subscrbe` is known here \(did you mean `iristk_subscribe`\?\)"):
        load_robot_config(str(tmp_path / "typo.json"))
