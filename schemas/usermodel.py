"""The fitted-user file: a simulated user fitted to one recorded participant, documented and versioned.

Rule: a user-model file is JSON (keys in a fixed order, so the same recording
gives the same bytes) holding the persona that best explains a participant's
recorded picks (core/userfit.py: maximum likelihood over the thesis's 1..6
scale), each feature's profile likelihood and 95% set, p and q on a finer grid,
the lapse rate, what the session showed the user (the evidence), the recorded
perception count where a simulated participant reported it, and the
assumptions of the fit in words. `format` and `version` say what the file is;
a reader refuses anything else, and a key no Struct of the file
declares (schemas/jsonfile.py), with a clear error (UserModelFileError), never
a half-read model. Written only through pairplay.outputs (no clobber without
force, atomic).

Version 1 fields are below; later versions add fields with defaults at the end.
"""

from __future__ import annotations

import msgspec

from pairplay.errors import InputError

from .config import Persona
from .jsonfile import JsonFileKind

FORMAT = "pairplay.usermodel"
VERSION = 1


class UserModelFileError(InputError):
    """A user-model file that cannot be used; the message says why."""


class FeatureFit(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One feature of the persona (1..6): its estimate, profile log-likelihood and 95% set."""

    level: int  # the maximum-likelihood level
    means: str  # what the level is in the simulated user (a probability, a capacity, the channels seen)
    set95: list[int]  # levels not rejected by the likelihood-ratio test at 5%
    profile: list[float]  # max log-likelihood with the feature at level 1..6 (the others free)
    identified: bool  # False: every level is in the 95% set (the session cannot tell)


class RateFit(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A probability profiled on a 0.01 grid (the other features at their estimate)."""

    estimate: float
    low95: float
    high95: float


class CountedRate(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A rate counted from what a simulated participant reported (SuggestionPerceived), as a check."""

    count: int
    of: int
    rate: float
    low95: float  # Wilson score interval
    high95: float


class UserModelFile(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    format: str = FORMAT
    version: int = VERSION
    recording: str  # the recording's file name (the one the arms are compared with)
    session: str
    participant: str
    observed_source: str  # how the recording's observed card was chosen (it decides the unaided pick)
    persona: Persona  # the fitted simulated user (key "fit:<participant>")
    focus: FeatureFit
    hearing: FeatureFit
    sight: FeatureFit
    memory: FeatureFit
    p_consider: RateFit  # the chance a suggestion is considered, (focus - 1) * 0.2 on the scale
    q_hear: RateFit  # the chance speech is heard, (hearing - 1) * 0.2 on the scale
    lapse: float  # share of picks best explained as a uniform covered card (the simulator has none)
    loglik: float  # at the estimate
    picks: int  # picks the likelihood covers (first, second and the intended card where recorded)
    evidence: dict[str, int]  # turns, suggestions, considerable ones and the parts they showed
    considered_counted: CountedRate | None = None  # a simulated participant's own report of considering
    assumptions: list[str] = []
    software: str = ""
    fitted_on: list[str] = []  # every recording whose turns the fit used (file names; REC first)
    # what the fitted recordings lacked, "<file name>: <reader.EventLog.note>" joined by "; " ("" if all were
    # whole): a fit of a damaged or cut file's intact parts says so in the file, not only on stderr
    partial: str = ""

    def __post_init__(self) -> None:
        if self.format != FORMAT:
            raise UserModelFileError(f"not a pairplay user-model file (format {self.format!r})")
        if self.version > VERSION:
            raise UserModelFileError(f"user-model file version {self.version} is newer than this pairplay "
                                     f"(reads up to {VERSION}); upgrade pairplay")
        for name in ("focus", "hearing", "sight", "memory"):
            f = getattr(self, name)
            if len(f.profile) != 6 or not 1 <= f.level <= 6:
                raise UserModelFileError(f"{name}: a feature has a level 1..6 and a profile of 6 values")


FILE = JsonFileKind(UserModelFile, UserModelFileError, "user-model file")  # schemas/jsonfile.py
# decode (data, source), write (path, value, force=False), read (path): the codec, by the names callers know
encode_user_model, decode_user_model, write_user_model, read_user_model = FILE.encode, FILE.decode, FILE.write, FILE.read
