"""The ground floor every package of the toolkit stands on.

Small, dependency-free pieces that ``strain2d``, ``surface_strain``,
``stereo``, ``mpm3d`` and ``sample_data_synth`` share, so that each exists
once:

* :mod:`tissue_core.errors` - the exceptions for errors a user can cause;
* :mod:`tissue_core.outputs` - output folders and files written atomically,
  with the marker that says a folder is a result of this toolkit (and so may
  be replaced with ``--overwrite``);
* :mod:`tissue_core.interrupt` - Ctrl-C held back while compiled code runs;
* :mod:`tissue_core.progress` - timestamped progress on stderr;
* :mod:`tissue_core.cli` - the command runner: one error line and exit
  status 2, exit 130 on Ctrl-C, warnings as one line each.

It imports none of the toolkit's packages.
"""

from importlib import metadata as _metadata

from tissue_core.errors import InputError, SourceError

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # a source tree that is not installed
    __version__ = "0+unknown"

__all__ = ["InputError", "SourceError", "__version__"]
