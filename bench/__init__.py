"""Benchmarks: every speed and latency goal of pairplay, each measured beside
its raw reference in the same run (`pairplay bench`).

Belongs here: the measuring code of each row, grouped by what it measures
(core, bus, view, robot). Does not belong here: anything a session or the study
needs to run. Goals are never asserted in tests; they are rows with a verdict.
"""
