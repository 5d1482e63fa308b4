"""The observation wing: what watches a run without taking part in it (above the runtime, below the CLI).

The recorder and its sources (the loops' timing, the log files), the taps the live view reads,
and `hapticop view`. A run reaches it only through `runtime.observer.Observer`.
"""
