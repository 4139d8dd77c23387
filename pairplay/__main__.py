"""`python -m pairplay`: the command, as the `pairplay` console script runs it (cli/start.py:
its signal handlers first, before anything loads)."""

from pairplay.cli.start import entry

entry()
