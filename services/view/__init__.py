"""The live view: the board, the suggestion and the Q-table in rerun.

Belongs here: the fold of events into what is drawn (`model`), the rerun
logging (`rerun_logger`), where the drawing goes (`output`: a file, a spawned
viewer, a served one), where events come from (`sources`: a recording or the
bus) and reading an `.rrd` back (`readback`). The view only subscribes; it
never publishes.
"""

# rerun's default ports, here so the command line can show them without loading rerun
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090


class RrdWriteFailed(RuntimeError):
    """rerun could not write the .rrd: its file could not be made, or its writer stopped (a full disk,
    `ulimit -f`; the flush raised RuntimeError("File-writer thread shut down prematurely"))."""
