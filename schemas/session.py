"""The configuration of one session, recorded whole in its SessionStarted event.

Rule: everything a replay needs to reproduce a session is in this Struct: the
participant, the seed and game index that name the RNG streams, the algorithm
and its schedule, the bias or fixed policy itself (as greedy actions, not a
path: a recording must not depend on files beside it), and the software version.
New fields get defaults and go at the end.
"""

from __future__ import annotations

from typing import Union

import msgspec

from pairplay.numbers import counted, shown

from .config import LEARNER_RANGES, REWARD_BONUS_RULES, UNSTATED_REWARD_BONUS, LearnerConfig, LSPIConfig
from .policy import N_ACTIONS, N_STATES
from .public import FieldError, PublicStructMeta, check_kinds

SEED_RANGE = (0, 2**64 - 1)  # every seed here has its own streams (core/rng.py game_seed, derivation 2)
GAME_INDEX_RANGE = (0, 2**63 - 1)  # a game of a seed: core/rng.py hashes it as a signed 64-bit count
# The board's times in milliseconds (ignore_window_ms, turn_back_ms): 0 up to a minute. Checked by
# SessionConfig.validate, a study file's [study] (schemas/study.py) and the session options (cli/session.py):
# `ignore_window_ms = inf` passed `if value < 0` and the board page held a missed pair for ever.
MS_RANGE = (0.0, 60_000.0)
MS_FIELDS = ("ignore_window_ms", "turn_back_ms")
# Every algorithm and the learner mode that plays it (core/learning.py MODES, core/simulate.py run_games):
# the one table for the session's learner (services/learner.py) and the counterfactual's "same" arm
# (cli/counterfactual.py), whose own table had no "lspi" (a KeyError traceback on every LSPI recording).
MODE_OF_ALGORITHM = {"q-learning": "q", "pi-reuse": "reuse", "fixed": "fixed", "lspi": "lspi"}
ALGORITHMS = tuple(MODE_OF_ALGORITHM)
# Where the observed card (the one the user looks at before the second pick) comes from:
# "intended": the simulated participant reports the card it would pick unaided;
# "first-pick": the first card of the turn (the thesis's human study, 7.1.3);
# "gaze": an eye tracker's GazeFixated events (source "tracker"; docs/lab.md).
OBSERVED_SOURCES = ("intended", "first-pick", "gaze")
# How the learner decides that a suggestion was ignored (no reward, no update):
# "perceived": the simulated participant reports it (SuggestionPerceived);
# "time": the two picks of a turn came less than `ignore_window_ms` apart (thesis 7.1.2).
IGNORE_RULES = ("perceived", "time")
# Which clock times the two picks for the "time" rule: "server" (the picks' envelope
# times) or "page" (the board page's performance clock, CardPicked.page_time_ms;
# turns whose picks lack it fall back to the server's).
IGNORE_CLOCKS = ("server", "page")


class SessionConfig(msgspec.Struct, frozen=True, kw_only=True, metaclass=PublicStructMeta):  # (schemas/public.py)
    session: str
    participant: str  # "sim:<persona>" or "human:<id>"
    seed: int
    rounds: int
    persona: str = ""
    game_index: int = 0
    algorithm: str = "q-learning"
    observed_source: str = "intended"
    ignore_rule: str = "perceived"
    ignore_window_ms: float = 1500.0
    # Greedy action per state of the bias policy (pi-reuse) or the fixed policy.
    policy_actions: list[int] = []
    # The learner's schedule: the fields of schemas.config.LearnerConfig that
    # differ from its defaults (a plain mapping, so that a newer LearnerConfig
    # field never makes an old reader reject this event).
    learner: dict[str, Union[float, int, None]] = {}
    software_version: str = ""
    # When the simulated reward pays its 1/|candidate set| bonus (core/reward.py).
    # New sessions state it (DEFAULT_REWARD_BONUS); absent = a pairplay 0.1.0 recording.
    reward_bonus: str = UNSTATED_REWARD_BONUS
    # How the seed, the participant and the game index name the RNG streams (core.rng.game_seed):
    # 1 = pairplay <= 0.2 (the seed cut to 32 bits, ids by CRC-32; what a recording without the field
    # was made with), 2 = every seed 0..2**64-1 and every participant id its own streams. New sessions
    # state 2 (core.rng.STREAMS_VERSION).
    streams: int = 1
    ignore_clock: str = "server"
    # How long the board page leaves a missed pair face up before turning it back (ms).
    turn_back_ms: float = 1500.0
    # LSPI's settings (schemas.config.LSPIConfig fields that differ from its defaults),
    # for algorithm "lspi"; left out of other sessions' events (UNSET).
    lspi: Union[dict[str, Union[float, int, bool]], msgspec.UnsetType] = msgspec.UNSET
    # A protocol game a scripted player played instead of the person `participant` names (a dress rehearsal:
    # `protocol pilot`, `protocol serve --pilot`): the core persona that touched the board; "" for a person's
    # game, a simulated participant's (sim:, whose persona is `persona`) and every older recording.
    scripted: str = ""
    # The robot the session was started with, by kind (schemas/robot_url.py `robot_kind`: "virtual", "iristk",
    # "furhat"; "external" for a bridge in a process of its own, `session --external robot`, `run game --wait-for
    # robot`); "" for none and every older recording. A session that names one and holds no event of it is said
    # (replay/reader.py `unanswered`: "the robot sent nothing"): before, no verb noticed a robot absent altogether.
    robot: str = ""

    def lspi_config(self) -> LSPIConfig:
        """LSPI's settings as the strict Struct (ValueError if unknown keys or values that cannot run)."""
        try:
            return msgspec.convert({} if self.lspi is msgspec.UNSET else self.lspi, LSPIConfig)
        except (msgspec.ValidationError, ValueError) as err:
            raise ValueError(f"lspi settings {self.lspi!r}: {err}") from None

    def learner_config(self) -> LearnerConfig:
        """The learner's schedule as the strict config Struct (ValueError if unknown keys)."""
        try:
            return msgspec.convert(self.learner, LearnerConfig)
        except msgspec.ValidationError as err:
            raise ValueError(f"learner schedule {self.learner!r}: {err}") from None

    def __post_init__(self) -> None:
        """Each field alone, where the config is made or decoded (schemas/public.py rule): of its kind, and in its
        range or one of its values (FieldError; the constructor says it as `pairplay.SessionConfig(<field>)`, a
        recording's or a message's is malformed input). Not here: what depends on other fields, and what only
        running needs (`validate`): a learner key this pairplay does not know and LSPI's settings (plain mappings
        a newer pairplay may extend; the learner's known keys are in range here), and a stream derivation this
        pairplay does not know (read, not run)."""
        check_kinds(self)
        if not self.session or any(c in self.session for c in "/*$#?@ "):
            raise FieldError("session", f"session id {self.session!r} must be non-empty, without / * $ # ? @ or "
                             "spaces")
        if self.rounds < 1:
            raise FieldError("rounds", f"rounds must be >= 1, got {self.rounds}")
        if not SEED_RANGE[0] <= self.seed <= SEED_RANGE[1]:  # (stream derivation 1's narrower range: validate)
            raise FieldError("seed", f"seed {self.seed} is outside the accepted range {SEED_RANGE[0]}..{SEED_RANGE[1]}")
        if not GAME_INDEX_RANGE[0] <= self.game_index <= GAME_INDEX_RANGE[1]:
            raise FieldError("game_index", f"game index must be {GAME_INDEX_RANGE[0]}..{GAME_INDEX_RANGE[1]}, got "
                             f"{self.game_index}")
        for key, values in (("algorithm", ALGORITHMS), ("observed_source", OBSERVED_SOURCES),
                            ("ignore_rule", IGNORE_RULES), ("reward_bonus", REWARD_BONUS_RULES),
                            ("ignore_clock", IGNORE_CLOCKS)):
            if getattr(self, key) not in values:
                raise FieldError(key, f"{key} {getattr(self, key)!r} is not one of {values}")
        if self.policy_actions and (len(self.policy_actions) != N_STATES
                                    or not all(0 <= a < N_ACTIONS for a in self.policy_actions)):
            # checked here, not first by the learner: the game started a session its learner then refused
            raise FieldError("policy_actions", f"policy_actions must be {N_STATES} action codes 0..{N_ACTIONS - 1}, "
                             f"got {counted(len(self.policy_actions), 'code')}")
        for key in MS_FIELDS:
            if not MS_RANGE[0] <= getattr(self, key) <= MS_RANGE[1]:  # also refuses nan
                raise FieldError(key, f"{key} must be {MS_RANGE[0]:g}..{MS_RANGE[1]:g}, got "
                                 f"{shown(getattr(self, key))}")
        for key, value in self.learner.items():  # the schedule's known keys (an unknown one: validate's)
            low, high = LEARNER_RANGES.get(key, (None, None))
            if value is not None and low is not None and not low <= value <= high:  # also refuses nan
                raise FieldError("learner", f"learner {key} must be {low}..{high}, got {shown(value)}")

    def validate(self) -> None:
        """Raise ValueError with a clear reason if the config cannot run (each field alone was checked where
        it was made: `__post_init__`)."""
        if self.algorithm in ("pi-reuse", "fixed") and not self.policy_actions:
            raise ValueError(f"algorithm {self.algorithm!r} needs policy_actions (a bias or fixed policy)")
        if self.participant.startswith("sim:") and not self.persona:
            raise ValueError("a simulated participant needs a persona")
        if self.streams not in (1, 2):
            raise ValueError(f"stream derivation {self.streams} is not one this pairplay knows (1, 2)")
        if self.streams == 1 and not 0 <= self.seed <= 2**32 - 1:
            raise ValueError(f"seed {self.seed}: stream derivation 1 (pairplay <= 0.2) takes seeds 0..{2**32 - 1} "
                             "only (it cut them to 32 bits); use streams=2")
        if self.participant.startswith("sim:") and self.observed_source == "gaze":
            raise ValueError("a simulated participant reports its intended card: observed source 'gaze' is for "
                             "a person with an eye tracker")
        if self.participant.startswith("human:"):
            self._check_human()
        self.learner_config()
        if self.algorithm == "lspi":
            self.lspi_config()
        elif self.lspi is not msgspec.UNSET:
            raise ValueError(f"lspi settings given for algorithm {self.algorithm!r}")

    def _check_human(self) -> None:
        """Refuse what a person cannot do: a person reports no perception, and looks at
        cards only through an eye tracker (otherwise the session would wait for ever)."""
        if self.ignore_rule == "perceived":
            raise ValueError("ignore rule 'perceived' needs a simulated participant to report what it perceived; "
                             "a person's session uses 'time' (thesis 7.1.2)")
        if self.observed_source == "intended":
            raise ValueError("observed source 'intended' needs a simulated participant; a person's observed card "
                             "is the first pick ('first-pick', thesis 7.1.3) or an eye tracker's gaze ('gaze')")


def learner_overrides(config: LearnerConfig) -> dict[str, Union[float, int, None]]:
    """The fields of `config` that differ from LearnerConfig's defaults."""
    return _overrides(config, LearnerConfig())


def lspi_overrides(config: LSPIConfig) -> dict[str, Union[float, int, bool]]:
    """The fields of `config` that differ from LSPIConfig's defaults."""
    return _overrides(config, LSPIConfig())


def _overrides(config, default) -> dict:
    return {f: getattr(config, f) for f in config.__struct_fields__ if getattr(config, f) != getattr(default, f)}


def config_argument(config, function: str) -> SessionConfig:
    """`config` handed to a public function (pairplay/arguments.py): ArgumentError unless it is a
    SessionConfig (each of its fields was checked where it was made: `__post_init__`; rounds="20" or True got
    through msgspec's constructor, and was refused here only), InputError, naming the function, for one
    `validate` refuses."""
    from pairplay.arguments import at, instance_argument
    from pairplay.errors import InputError
    instance_argument(config, SessionConfig, function, "config", "a SessionConfig (pairplay.SessionConfig(session=..., ...))")
    try:
        config.validate()
    except ValueError as exc:
        raise InputError(f"config: {exc}", at(function, "config")) from None
    return config
