"""The installed distribution's version, one place for ``mapupdate --version`` and reports."""

from importlib import metadata

DISTRIBUTION = "lidar-map-updating"

try:
    __version__ = metadata.version(DISTRIBUTION)
except metadata.PackageNotFoundError:      # run from a source tree that was never installed
    __version__ = "0+unknown"
