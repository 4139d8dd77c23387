"""pairplay: robot-assisted Memory, learned suggestions, combined policies.

The code lives in the repository's top-level folders, installed as subpackages
of this one: ``pairplay.schemas`` (the bus contract), ``pairplay.core`` (the
science, pure numpy), ``pairplay.replay`` (the MCAP event log) and
``pairplay.services`` (processes on the Zenoh bus and the CLI).
"""

__version__ = "0.2.0"
