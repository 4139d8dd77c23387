"""`pairplay profile`: see services/combine_cli.py (the two verbs share their loading)."""

from .combine_cli import add_profile_arguments as add_arguments, run_profile as run  # noqa: F401
