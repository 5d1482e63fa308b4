"""The `hapticop` command line: compose, validate, patch, graph, devices, bench."""

import signal
import sys


def _interrupted_while_loading(_signum, _frame):
    """Ctrl+C while the command's modules load: leave quietly with the interrupted status."""
    print("hapticop: interrupted", file=sys.stderr)
    raise SystemExit(130)


# Loading the command takes a noticeable moment (numpy, pydantic, networkx); a Ctrl+C in it is
# an answer, not a traceback. Only the main thread may set handlers (an import from elsewhere
# skips this), and the one before is put back: `main` handles Ctrl+C from there on. A Ctrl+C
# ignored by inheritance (a job a shell started in the background) is taken all the same, as a
# run takes it once it runs: ignored only until then, it was lost while the run's processes started.
try:
    _previous = signal.signal(signal.SIGINT, _interrupted_while_loading)
except ValueError:
    _previous = None
try:
    from hapticop.cli.main import app, main
finally:
    if _previous is not None:
        signal.signal(signal.SIGINT, _previous if callable(_previous) else signal.default_int_handler)

__all__ = ["app", "main"]
