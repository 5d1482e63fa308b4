"""hapticop: declarative real-time dataflow for haptic teleoperation, driven by YAML compositions."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("hapticop")
except PackageNotFoundError:  # running from a checkout that was never installed
    __version__ = "0.0.0+unknown"
