"""Writing VTK XML files, one way for every package.

VTK's writers take UTF-8 file names only and report failure by a return
value; :func:`write_polydata` reaches names that are not UTF-8 through
:func:`tissue_core.filenames.utf8_output` and turns a failed write into an
``OSError`` naming the file.
"""

from __future__ import annotations

from pathlib import Path

from tissue_core.filenames import utf8_output

__all__ = ["write_polydata"]

#: compressors VTK's XML writers offer, by the name used here
_COMPRESSORS = {"zlib": "SetCompressorTypeToZLib", "lz4": "SetCompressorTypeToLZ4"}


def write_polydata(mesh, path: Path, *, compressor: str = "zlib", appended: bool = False) -> None:
    """Write a ``vtkPolyData`` as VTK XML PolyData (``.vtp``), binary and compressed.

    Parameters
    ----------
    mesh : vtkPolyData
    path : Path
        The file; its folder must exist.
    compressor : {"zlib", "lz4"}, keyword-only
        zlib is read by every ParaView; LZ4 writes faster (ParaView 5.6 and later).
    appended : bool, keyword-only
        The arrays in one appended block after the XML (smaller, faster) instead of
        inline base64 blocks.
    """
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    if compressor not in _COMPRESSORS:
        raise ValueError(f"compressor must be one of {sorted(_COMPRESSORS)}, got {compressor!r}")
    writer = vtkXMLPolyDataWriter()
    writer.SetInputData(mesh)
    if appended:
        writer.SetDataModeToAppended()
    else:
        writer.SetDataModeToBinary()
    getattr(writer, _COMPRESSORS[compressor])()
    with utf8_output(path) as target:  # VTK takes UTF-8 names only
        writer.SetFileName(str(target))
        if not writer.Write():
            raise OSError(f"could not write {path}")
