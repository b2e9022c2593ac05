"""The toolkit's version, from the installed package's metadata."""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # a source tree that is not installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
