"""The ground floor every package of the toolkit stands on.

Small pieces that ``strain2d``, ``surface_strain``, ``stereo``, ``mpm3d`` and
``sample_data_synth`` share, so that each exists once:

* :mod:`tissue_core.errors` - the exceptions for errors a user can cause;
* :mod:`tissue_core.outputs` - output folders and files written atomically,
  with the marker (folders) and the ledger (files) that record what the
  toolkit wrote, so that ``--overwrite`` replaces nothing else, and scratch
  named by its owner, so that what a killed run left is removed later;
* :mod:`tissue_core.interrupt` - Ctrl-C (and SIGTERM, SIGHUP) held back where
  Python cannot raise it cleanly (compiled kernels, imports, finalizers);
* :mod:`tissue_core.progress` - timestamped progress on stderr;
* :mod:`tissue_core.resources` - whether what an option asks for fits the
  memory and the disk, checked before it is made;
* :mod:`tissue_core.cli` - the command runner: one error line and exit
  status 2, exit 130 on Ctrl-C (143 on SIGTERM, 129 on SIGHUP), warnings as
  one line each;
  :mod:`tissue_core.main` - ``python -m PACKAGE``;
* :mod:`tissue_core.csvtext` - CSV files written with every text cell inert
  in a spreadsheet (no formula from a name), and read back as they were;
* :mod:`tissue_core.images` - image files read whole or refused (NumPy, OpenCV),
  and what OpenCV prints on stderr kept off the terminal;
* :mod:`tissue_core.tiff_files` - TIFF files cut short or damaged refused in one
  line, what tifffile logs about them kept off the terminal;
* :mod:`tissue_core.filenames` - file and folder names that are not UTF-8:
  a UTF-8 alias for the libraries that need one, and the names shown in text;
* :mod:`tissue_core.tiff_units` - the pixel sizes TIFF files record (ImageJ,
  OME, resolution tags);
* :mod:`tissue_core.html` - the self-contained `report.html` every package
  writes, and the checksums of the inputs it names;
* :mod:`tissue_core.lazy` - package names loaded on first use;
  :mod:`tissue_core.version` - the toolkit's version.

It imports none of the toolkit's packages; only :mod:`tissue_core.images`
needs more than the standard library.
"""

from tissue_core.errors import InputError, SourceError
from tissue_core.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {"tissue_core.version": ["__version__"]})[:2]


__all__ = ["InputError", "SourceError", "__version__"]
