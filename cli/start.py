"""The `pairplay` command's first code: its signal handlers, then everything else.

Rule: the console script (pyproject [project.scripts]) and `python -m pairplay`
both run `entry`, which installs the SIGINT/SIGTERM handler before it imports
anything of weight (pairplay/signals.py `record`: it notes the signal and
raises nothing), then imports the command (cli/main.py: argparse and the rest,
0.1 s on an idle machine, seconds under load) and runs it. cli/main.py puts
its own handler in place (cli/interrupts.py: a Ctrl-C never lands inside
numba's compiler) and then ends the verb at once with its one line and 128 +
the signal's number if one came meanwhile, as at any later moment. Only the
interpreter's own start-up (site and the installed .pth files) comes before.

Before, the console script imported cli/main.py first: a SIGINT 0.05-0.1 s
after start printed importlib's KeyboardInterrupt traceback, and a SIGTERM
killed the process without a line (a new user's trial). A signal ignored at
start stays ignored (pairplay/signals.py says why).
"""

from __future__ import annotations

from pairplay import signals


def entry() -> None:
    signals.handle(signals.record)  # first of all (module rule)
    from pairplay.cli.main import entry as command

    command()
