"""`pairplay profile`: see cli/combine.py (the two verbs share their loading)."""

from pairplay.cli.combine import add_profile_arguments as add_arguments, run_profile as run  # noqa: F401
