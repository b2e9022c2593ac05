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

from tissue_core.errors import InputError, SourceError


def __getattr__(name: str):
    if name == "__version__":  # read from the package metadata only when asked
        from tissue_core.version import __version__

        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["InputError", "SourceError", "__version__"]
