"""The command line, ``mapupdate``: it parses arguments, calls the library (``robot``,
``scenarios``, ``studies``, ``evaluation``) and prints; nothing else lives here."""

from .main import main
from .version import __version__

__all__ = ["main", "__version__"]
