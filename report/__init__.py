"""The study's report: tables, CSV files, figures and report.md.

Belongs here: turning results of `pairplay.core` (curves, evaluations,
profiles, merges, speed-ups) into files a researcher reads. Does not belong
here: computing those results (`core`), reading recordings (`replay`), or
argument parsing (`cli`). Imports `core`, `schemas` and `replay` only.
"""
