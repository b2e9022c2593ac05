"""Writing VTK XML files, one way for every package.

VTK's writers take UTF-8 file names only and report failure by a return
value; :func:`write_polydata` reaches names that are not UTF-8 through
:func:`tissue_core.filenames.utf8_output` and turns a failed write into an
``OSError`` naming the file.

:func:`write_triangles` writes a triangle mesh with its arrays from NumPy
alone, in the file VTK's own writer makes of it (XML PolyData, inline
base64 binary, zlib blocks): a time series of a few hundred frames need not
load VTK nor build a ``vtkPolyData`` per frame.
"""

from __future__ import annotations

import base64
import tempfile
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from tissue_core.filenames import utf8_output

__all__ = ["write_polydata", "write_triangles", "write_triangles_streamed"]

#: VTK's names of the NumPy types an array may have
_VTK_TYPES = {
    "int8": "Int8", "uint8": "UInt8", "int16": "Int16", "uint16": "UInt16",
    "int32": "Int32", "uint32": "UInt32", "int64": "Int64", "uint64": "UInt64",
    "float32": "Float32", "float64": "Float64",
}  # fmt: skip
#: bytes of uncompressed data per zlib block (VTK's default)
_BLOCK = 32768

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


def _encoded(data: bytes, level: int) -> str:
    """``data`` as VTK's inline binary with zlib: the base64 of the block header
    (UInt32: blocks, block size, size of the last block, compressed sizes), then the
    base64 of the compressed blocks."""
    blocks = [zlib.compress(data[i : i + _BLOCK], level) for i in range(0, len(data), _BLOCK)]
    last = len(data) - _BLOCK * (len(blocks) - 1) if blocks else 0
    header = np.array([len(blocks), _BLOCK, last, *map(len, blocks)], dtype="<u4")
    return (base64.b64encode(header.tobytes()) + base64.b64encode(b"".join(blocks))).decode()


_HEAD = (
    '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1" '
    'byte_order="LittleEndian" header_type="UInt32" compressor="vtkZLibDataCompressor">\n'
    "<PolyData>\n"
)


def _empty_cells(level: int) -> str:
    """The empty vertex, line and strip cell arrays of a triangle mesh's piece."""
    return "".join(
        f"<{kind}>\n" + _data_array("connectivity", np.zeros(0, np.int64), level)
        + _data_array("offsets", np.zeros(0, np.int64), level) + f"</{kind}>\n"
        for kind in ("Verts", "Lines", "Strips")
    )  # fmt: skip


def _field_data(field_data: Mapping[str, Sequence], level: int) -> str:
    """The mesh's ``FieldData``: lists of text as string arrays, numbers as data arrays."""
    if not field_data:
        return ""
    arrays = [
        _strings(k, list(v), level) if len(v) and isinstance(v[0], str)
        else _data_array(k, np.asarray(v), level, tuples=len(v))
        for k, v in field_data.items()
    ]  # fmt: skip
    return "<FieldData>\n" + "".join(arrays) + "</FieldData>\n"


def _data_array(name: str, values: np.ndarray, level: int, tuples: int | None = None) -> str:
    values = np.asarray(values)
    if values.dtype == bool:
        values = values.astype(np.uint8)
    kind = _VTK_TYPES.get(values.dtype.name)
    if kind is None or values.ndim not in (1, 2):
        raise ValueError(f"array {name!r}: {values.dtype} of {values.ndim} dimensions")
    components = f' NumberOfComponents="{values.shape[1]}"' if values.ndim == 2 else ""
    if tuples is not None:  # a field data array: no points or cells say how many
        components += f' NumberOfTuples="{tuples}"'
    data = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes()
    return (
        f'<DataArray type="{kind}" Name="{_attribute(name)}"{components} format="binary">\n'
        f"{_encoded(data, level)}\n</DataArray>\n"
    )


def _attribute(text: str) -> str:
    return (
        text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")
    )


def _strings(name: str, texts: Sequence[str], level: int) -> str:
    """A ``vtkStringArray`` as VTK writes one: the UTF-8 strings, each ended by a 0 byte."""
    data = b"".join(t.encode("utf-8") + b"\0" for t in texts)
    return (
        f'<Array type="String" Name="{_attribute(name)}" NumberOfTuples="{len(texts)}" '
        f'format="binary">\n{_encoded(data, level)}\n</Array>\n'
    )


def write_triangles(
    path: str | Path,
    points: np.ndarray,
    triangles: np.ndarray,
    point_data: Mapping[str, np.ndarray] | None = None,
    cell_data: Mapping[str, np.ndarray] | None = None,
    field_data: Mapping[str, Sequence[str]] | None = None,
    *,
    level: int = 1,
) -> None:
    """Write a triangle mesh as VTK XML PolyData (``.vtp``), binary and zlib-compressed.

    Parameters
    ----------
    path : path
        The file (any name the file system takes); its folder must exist.
    points : (N, 3) float
    triangles : (M, 3) int
        Indices into ``points``.
    point_data, cell_data : dict of name -> (N,) / (M,) or (N, k) / (M, k) arrays
        Numbers (bool is written as UInt8); the first array of each is the active one
        (VTK's ``Scalars``).
    field_data : dict of name -> list of str
        String arrays of the whole mesh (units, say).
    level : int, keyword-only
        zlib's compression level (1, the fastest, by default).
    """
    point_data, cell_data, field_data = point_data or {}, cell_data or {}, field_data or {}
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {points.shape}")
    n, m = len(points), len(triangles)
    parts = [_HEAD, _field_data(field_data, level)]
    parts.append(
        f'<Piece NumberOfPoints="{n}" NumberOfVerts="0" NumberOfLines="0" '
        f'NumberOfStrips="0" NumberOfPolys="{m}">\n'
    )
    for tag, arrays, count in (("PointData", point_data, n), ("CellData", cell_data, m)):
        active = f' Scalars="{_attribute(next(iter(arrays)))}"' if arrays else ""
        parts.append(f"<{tag}{active}>\n")
        for name, values in arrays.items():
            if len(values) != count:
                raise ValueError(f"{tag} {name!r} has {len(values)} values for {count}")
            parts.append(_data_array(name, values, level))
        parts.append(f"</{tag}>\n")
    parts.append("<Points>\n" + _data_array("Points", points, level) + "</Points>\n")
    parts.append(_empty_cells(level))
    parts.append(
        "<Polys>\n"
        + _data_array("connectivity", triangles.ravel(), level)
        + _data_array("offsets", np.arange(3, 3 * m + 1, 3, dtype=np.int64), level)
        + "</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n"
    )
    Path(path).write_text("".join(parts), encoding="ascii", errors="xmlcharrefreplace")


class _Blocks:
    """One array's zlib blocks, written to ``body`` as its chunks come: the sizes of the
    blocks for the header VTK reads before them (:func:`write_triangles_streamed`)."""

    def __init__(self, body, level: int) -> None:
        self.body, self.level = body, level
        self.start = body.tell()
        self.sizes: list[int] = []
        self.pending = b""
        self.last = 0

    def add(self, values: np.ndarray, dtype: np.dtype) -> None:
        data = self.pending + np.ascontiguousarray(values, dtype=dtype).tobytes()
        whole = len(data) - len(data) % _BLOCK
        for i in range(0, whole, _BLOCK):
            self._block(data[i : i + _BLOCK])
        self.pending = data[whole:]

    def _block(self, data: bytes) -> None:
        packed = zlib.compress(data, self.level)
        self.body.write(packed)
        self.sizes.append(len(packed))
        self.last = len(data)

    def close(self) -> bytes:
        """The header (UInt32: blocks, block size, size of the last block, compressed
        sizes); the blocks lie in the body from :attr:`start`."""
        if self.pending:
            self._block(self.pending)
            self.pending = b""
        header = [len(self.sizes), _BLOCK, self.last if self.sizes else 0, *self.sizes]
        return np.array(header, dtype="<u4").tobytes()


def write_triangles_streamed(
    path: str | Path,
    n_points: int,
    n_triangles: int,
    points: Callable[[], Iterator[np.ndarray]],
    triangles: Callable[[], Iterator[np.ndarray]],
    point_data: Mapping[str, tuple[str, int, Callable[[], Iterator[np.ndarray]]]] | None = None,
    field_data: Mapping[str, Sequence[str] | np.ndarray] | None = None,
    *,
    normals: str | None = None,
    level: int = 1,
) -> None:
    """Write a triangle mesh too large to hold as VTK XML PolyData (``.vtp``), its arrays
    given a chunk at a time: zlib-compressed, appended after the XML (raw).

    Parameters
    ----------
    path : path
        The file (any name); its folder must exist.  The compressed arrays go to an
        unnamed temporary file in that folder first, then after the XML.
    n_points, n_triangles : int
    points : callable
        Yields the points as ``(k, 3)`` float32 chunks, in order (called once).
    triangles : callable
        Yields the triangles as ``(k, 3)`` chunks of point indices (called twice:
        the connectivity, then nothing but their count for the offsets).
    point_data : dict of name -> (NumPy type name, components, callable)
        Each array's chunks, ``n_points`` values in all.
    field_data : dict of name -> list of str or numbers
        Small arrays of the whole mesh (inline).
    normals : str, optional
        The point array that holds the normals (VTK's ``Normals`` attribute).
    level : int
        zlib's compression level.
    """
    point_data, field_data = point_data or {}, field_data or {}
    path = Path(path)
    arrays = []  # (tag, name, vtk type, components, header, start, end)
    # the compressed arrays wait in a file of no name beside the output (removed on close)
    with tempfile.TemporaryFile(dir=path.parent) as body:

        def encode(name, dtype, components, chunks, tag, expected):
            blocks = _Blocks(body, level)
            dt = np.dtype(dtype).newbyteorder("<")
            count = 0
            for chunk in chunks:
                chunk = np.asarray(chunk)
                count += len(chunk)
                blocks.add(chunk, dt)
            if count != expected:
                raise ValueError(f"{name!r}: {count} values for {expected}")
            header = blocks.close()
            kind = _VTK_TYPES[np.dtype(dtype).name]
            arrays.append((tag, name, kind, components, header, blocks.start, body.tell()))

        for name, (dtype, components, chunks) in point_data.items():
            encode(name, dtype, components, chunks(), "PointData", n_points)
        encode("Points", "float32", 3, points(), "Points", n_points)
        flat = (np.asarray(t).ravel() for t in triangles())
        encode("connectivity", "int64", 1, flat, "Polys", 3 * n_triangles)

        def offsets():
            done = 0
            for t in triangles():
                k = len(t)
                yield np.arange(3 * done + 3, 3 * (done + k) + 1, 3, dtype=np.int64)
                done += k

        encode("offsets", "int64", 1, offsets(), "Polys", n_triangles)
        offset, xml = 0, {}
        for tag, name, kind, components, header, start, end in arrays:
            comps = f' NumberOfComponents="{components}"' if components > 1 else ""
            xml.setdefault(tag, []).append(
                f'<DataArray type="{kind}" Name="{_attribute(name)}"{comps} '
                f'format="appended" offset="{offset}"/>\n'
            )
            offset += len(header) + end - start
        head = [_HEAD, _field_data(field_data, level)]
        head.append(
            f'<Piece NumberOfPoints="{n_points}" NumberOfVerts="0" NumberOfLines="0" '
            f'NumberOfStrips="0" NumberOfPolys="{n_triangles}">\n'
        )
        attribute = f' Normals="{_attribute(normals)}"' if normals else ""
        head.append(f"<PointData{attribute}>\n" + "".join(xml.get("PointData", []))
                    + "</PointData>\n<CellData>\n</CellData>\n")  # fmt: skip
        head.append("<Points>\n" + "".join(xml["Points"]) + "</Points>\n" + _empty_cells(level))
        head.append("<Polys>\n" + "".join(xml["Polys"]) + "</Polys>\n")
        head.append('</Piece>\n</PolyData>\n<AppendedData encoding="raw">\n_')
        with open(path, "wb") as out:
            out.write("".join(head).encode("ascii", errors="xmlcharrefreplace"))
            for *_, header, start, end in arrays:
                out.write(header)
                body.seek(start)
                left = end - start
                while left:
                    piece = body.read(min(left, 1 << 24))
                    out.write(piece)
                    left -= len(piece)
            out.write(b"\n</AppendedData>\n</VTKFile>\n")
