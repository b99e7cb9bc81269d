"""flagtrack daemon: algorithm core, wire schema, services and the ``flagtrack`` command."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("flagtrack")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
