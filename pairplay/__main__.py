"""`python -m pairplay`: the command, with its signal handlers installed before anything loads.

A signal while the command's own modules load (a second or more on a loaded
machine) is then one line and 128 + its number, as at any later moment
(cli/main.py); only the interpreter's own start-up comes before this."""

from pairplay.cli.interrupts import DeferredInterrupt

DeferredInterrupt().install()
try:
    from pairplay.cli.main import entry
except KeyboardInterrupt:
    import signal
    import sys

    from pairplay.cli import interrupts

    signum = interrupts.received or signal.SIGINT
    how = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
    print(f"pairplay: interrupted ({how}) while loading; nothing was written", file=sys.stderr)
    sys.exit(128 + signum)

entry()
