"""pairplay: robot-assisted Memory, learned suggestions, combined policies.

The code lives in the repository's top-level folders, installed as subpackages
of this one: ``pairplay.schemas`` (the bus contract), ``pairplay.core`` (the
science, pure numpy), ``pairplay.gym`` (the task as a Gymnasium
environment), ``pairplay.replay`` (the MCAP event log),
``pairplay.report`` (the study's report), ``pairplay.services`` (processes on
the Zenoh bus), ``pairplay.bench`` (benchmarks) and ``pairplay.cli`` (the
command line). Two small modules of the root serve every layer:
``pairplay.errors`` (the kinds of user mistake, each shown as one line) and
``pairplay.outputs`` (the one way a user's file is written: never replaced
without ``force``, a temporary file renamed when complete).

The public API a researcher scripts against is the names below, importable
from ``pairplay`` itself (loaded on first use, so ``import pairplay`` stays
cheap). Everything else may change between versions::

    import pairplay
    report = pairplay.run_study(pairplay.StudySettings(seed=1, games=2, rounds=100), "out/s1")
    log = pairplay.read_log("recordings/samples/sim-ashley-fmt2.mcap")   # events, channels, damage
    fold = pairplay.fold_events(e.event for e in log.events)      # rounds, Q-table, rewards
    policies = [pairplay.read_policy(p) for p in paths]
    users, profiles = pairplay.users_from_policies(policies, seed=0)   # algorithm 3
    merged = pairplay.combine(users)                                  # algorithm 4
    turns = pairplay.read_turns("recordings/samples/sim-helmut-fmt2.mcap")
    fit = pairplay.fit_user(turns.observations, turns.config.observed_source)   # fit.levels, fit.set95
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

# public name -> module that defines it
API: dict[str, str] = {
    # the simulated study (thesis ch. 6)
    "StudySettings": "pairplay.report.study",
    "run_study": "pairplay.report.study",
    # sessions on the bus
    "SessionConfig": "pairplay.schemas.session",
    "run_session": "pairplay.services.session",
    "verify_recording": "pairplay.services.verify",
    # recordings
    "read_log": "pairplay.replay.reader",
    "fold_events": "pairplay.replay.fold",
    "rebuild_recording": "pairplay.replay.rebuild",
    "recover": "pairplay.replay.recover",
    # policies, profiles, merges
    "read_policy": "pairplay.schemas.policy",
    "write_policy": "pairplay.schemas.policy",
    "users_from_policies": "pairplay.core.policies",
    "extract_info": "pairplay.core.combine",
    "combine": "pairplay.core.combine",
    "combined_policy_file": "pairplay.core.policies",
    # counterfactual replay: a simulated user fitted to a recorded participant
    "read_turns": "pairplay.replay.turns",
    "fit_user": "pairplay.core.userfit",
    "run_arms": "pairplay.core.counterfactual",
    "read_user_model": "pairplay.schemas.usermodel",
}

__all__ = ["__version__", *API]


def __getattr__(name: str):
    if name in API:
        value = getattr(importlib.import_module(API[name]), name)
        if not isinstance(value, type):  # a function: its refusals name its arguments, not a verb's options
            from pairplay.arguments import python_words
            value = python_words(value, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'pairplay' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
