"""tissue-strain in napari: readers for videos, stacks and run folders, and widgets that
run the toolkit's commands with a progress bar and a working cancel.

The plugin is declared in ``napari.yaml`` (npe2) and installed with the optional extra
``pip install -e ".[napari]"``; the core toolkit does not need Qt.  Open napari with
``napari`` (or ``python -m tissue_napari``, which opens it with both widgets docked).

The widgets run the same command a user would type (``python -m strain2d analyze ...``,
``python -m mpm3d analyze ...``) in a child process: the run folder is the command
line's, the command is shown to copy, the viewer stays responsive, and Cancel sends the
child an interrupt, after which the toolkit leaves no half-written folder.
"""

__all__ = ["read_path"]

from tissue_napari.readers import read_path
