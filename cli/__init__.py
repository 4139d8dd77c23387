"""The command line: `pairplay <verb>`.

Belongs here: `main` (the verb table) and one module per verb that parses its
arguments, calls a function that does the work, and prints. Does not belong
here: the work itself. A verb's work is a function in `core`, `replay`,
`report`, `services` or `bench` that a script can call without argparse.
This is the top of the import order; nothing imports `pairplay.cli` but
`pairplay.__main__` and the entry point.
"""
