"""napari readers: videos and image folders as a time series, z-stacks with their voxel
size, and the run folders of every package as layers.

Each reader returns napari's layer data tuples ``(data, kwargs, layer_type)``; napari
is not imported here (the tuples are plain data), so the readers are tested without Qt.

What each source becomes:

* a video, a multi-page TIFF that is not a z-stack, or a folder of images: one image
  layer ``(T, H, W)`` (gray, as the trackers see it), its path in ``metadata["source"]``
  for the strain widget;
* a z-stack (a TIFF with a z axis, see :func:`mpm3d.io.read_stack`): an image layer per
  channel, scaled by the voxel size in um;
* a ``strain2d analyze`` run (``summary.json`` and ``strain_nodes.csv``): the tracks,
  the nodes coloured by strain (every component as a feature, frame by frame) and the
  mesh on the deformed frames, coloured by Exx; ``surface_strain`` and ``stereo --strain``
  runs the same in 3D;
* a ``stereo reconstruct`` run or a ``points3d.csv``: the 3D points over time;
* an ``mpm3d analyze`` run: the height map and the surface in um, the crests, the metrics
  in ``metadata``;
* a ``multimodal strain`` run: the mesh coloured by the strain along the surface.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["get_reader", "read_path"]

#: video containers OpenCV reads (and what strain2d opens)
VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".wmv", ".mpg", ".mpeg")
#: image files a folder of frames may hold
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: the strain components a run's nodes carry, in the order the layers list them
COMPONENTS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J")

LayerData = tuple  # (data, kwargs, layer_type)


def get_reader(path: str | list[str]) -> Callable[[str], list[LayerData]] | None:
    """napari's reader hook: a function that reads ``path``, or None where this plugin
    reads nothing there."""
    if isinstance(path, list):
        if len(path) != 1:
            return None
        path = path[0]
    return read_path if _kind(Path(path)) is not None else None


def read_path(path: str | list[str]) -> list[LayerData]:
    """The layers of ``path`` (see the module's notes)."""
    if isinstance(path, list):
        path = path[0]
    p = Path(path)
    kind = _kind(p)
    if kind is None:
        raise ValueError(f"{p}: not a video, image folder, z-stack or run folder")
    return _READERS[kind](p)


def _kind(p: Path) -> str | None:
    if p.is_dir():
        if (p / "metrics.json").is_file() and (p / "heightmap.tif").is_file():
            return "mpm3d"
        if (p / "fold_strain.csv").is_file():
            return "multimodal"
        if (p / "summary.json").is_file() and (p / "strain_nodes.csv").is_file():
            return "strain"
        if (p / "points3d.csv").is_file():
            return "stereo"
        if any(f.suffix.lower() in IMAGE_SUFFIXES for f in p.iterdir() if f.is_file()):
            return "frames"
        return None
    suffix = p.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return "frames"
    if p.name.lower().endswith("points3d.csv"):
        return "points3d"
    if suffix in (".tif", ".tiff") and p.is_file():
        return "stack" if _is_stack(p) else "frames"
    return None


def _is_stack(p: Path) -> bool:
    """A TIFF with a z axis (ImageJ slices, OME Z), not a time series."""
    import tifffile

    try:
        with tifffile.TiffFile(p) as tif:
            axes = tif.series[0].axes if tif.series else ""
    except Exception:  # an unreadable TIFF: the frames reader says why
        return False
    return "Z" in axes


# ----------------------------------------------------------------------------- sources


def _frames(p: Path) -> list[LayerData]:
    from strain2d import open_frames

    source = open_frames([str(p)], min_frames=1)
    # 8-bit sources stay 8-bit (a quarter of float32's memory); others as float32
    kind = np.uint8 if tuple(source.value_range) == (0.0, 255.0) else np.float32
    frames = np.empty((len(source), *source.shape), kind)
    for k, frame in enumerate(source):
        frames[k] = np.rint(frame) if kind is np.uint8 else frame
    meta = {"source": str(p), "kind": source.kind, "names": list(source.names)}
    name = p.stem if p.is_file() else p.name
    return [(frames, {"name": name, "metadata": meta, "colormap": "gray"}, "image")]


def _stack(p: Path) -> list[LayerData]:
    from mpm3d import read_stack

    stack = read_stack(p)
    dz, dy, dx = stack.spacing
    out = []
    for c, channel in enumerate(stack.channel_names):
        out.append(
            (
                np.asarray(stack.data[:, c]),
                {
                    "name": f"{p.stem} {channel}",
                    "scale": (dz, dy, dx),
                    "metadata": {"source": str(p), "spacing_um": stack.spacing},
                    "blending": "additive",
                    "colormap": ("magenta", "green", "cyan", "yellow")[c % 4],
                },
                "image",
            )
        )
    return out


# ----------------------------------------------------------------------------- runs


def _triangles(folder: Path) -> np.ndarray | None:
    """The mesh of a run: the first frame's triangles of ``strain_elements.csv``."""
    path = folder / "strain_elements.csv"
    if not path.is_file():
        return None
    rows = []
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(line for line in f if not line.startswith("#"))
        for row in reader:
            if row["frame"] != "0":
                break
            rows.append((int(row["p0"]), int(row["p1"]), int(row["p2"])))
    return np.array(rows, dtype=int).reshape(-1, 3)


def strain_layers(
    folder: str | os.PathLike, component: str = "Exx", *, name: str | None = None
) -> list[LayerData]:
    """A strain run's layers: tracks, nodes (coloured by ``component``), the mesh on the
    deformed frames (coloured by ``component``); their names start with ``name`` (the
    folder's name by default)."""
    from strain2d import load_run

    folder = Path(folder)
    run = load_run(folder)
    pos = run.positions  # (T, N, d) in run.unit
    n_frames, n_points, dim = pos.shape
    t = np.repeat(np.arange(n_frames), n_points)
    coords = pos.reshape(-1, dim)[:, ::-1]  # (y, x) or (z, y, x) for napari
    keep = run.visible.reshape(-1) & np.isfinite(coords).all(axis=1)
    features = {k: run.nodal[k].reshape(-1)[keep] for k in COMPONENTS if k in run.nodal}
    limit = _limit(run.nodal.get(component))
    name = name or folder.name
    meta = {"run": str(folder), "summary": run.summary, "unit": run.unit}
    layers = []
    track_ids = np.tile(np.arange(n_points), n_frames)
    tracks = np.column_stack([track_ids, t, coords])[keep]
    layers.append(
        (tracks, {"name": f"{name} tracks", "tail_length": 5, "metadata": meta}, "tracks")
    )
    points = np.column_stack([t, coords])[keep]
    layers.append(
        (
            points,
            {
                "name": f"{name} nodes ({component})",
                "features": features,
                "face_color": component,
                "face_colormap": "RdBu_r",
                "face_contrast_limits": (-limit, limit),
                "size": 6 if dim == 2 else 0.02 * _extent(coords),
                "metadata": meta,
            },
            "points",
        )
    )
    triangles = _triangles(folder)
    if triangles is not None and len(triangles) and component in run.nodal:
        # one copy of the mesh per frame at (t, y, x): the slider shows the mesh of each
        # frame on that frame, coloured by its nodal values
        vertices = np.column_stack([t, coords])
        faces = (triangles[None, :, :] + (np.arange(n_frames) * n_points)[:, None, None]).reshape(
            -1, 3
        )
        values = np.nan_to_num(run.nodal[component].reshape(-1), nan=0.0)
        good = np.isfinite(vertices).all(axis=1)
        vertices = np.where(good[:, None], vertices, 0.0)
        faces = faces[good[faces].all(axis=1)]
        layers.append(
            (
                (vertices, faces, values),
                {
                    "name": f"{name} mesh ({component})",
                    "colormap": "RdBu_r",
                    "contrast_limits": (-limit, limit),
                    "opacity": 0.7,
                    "metadata": {**meta, "component": component},
                },
                "surface",
            )
        )
    return layers


def _limit(values) -> float:
    if values is None:
        return 1.0
    finite = np.abs(values[np.isfinite(values)])
    return float(np.percentile(finite, 99)) if finite.size and finite.max() > 0 else 1.0


def _extent(coords: np.ndarray) -> float:
    finite = coords[np.isfinite(coords).all(axis=1)]
    return float(np.ptp(finite, axis=0).max()) if len(finite) else 1.0


def _points3d(p: Path) -> list[LayerData]:
    path = p / "points3d.csv" if p.is_dir() else p
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(line for line in f if not line.startswith("#"))
        rows = [r for r in reader if r.get("visible", "1") in ("1", "True", "true")]
    data = np.array(
        [(float(r["frame"]), float(r["Z"]), float(r["Y"]), float(r["X"])) for r in rows]
    ).reshape(-1, 4)
    ids = np.array([int(r["point"]) for r in rows])
    name = p.name if p.is_dir() else p.stem
    meta = {"source": str(path)}
    out = [
        (
            data,
            {"name": f"{name} points 3D", "size": 0.02 * _extent(data[:, 1:]), "metadata": meta},
            "points",
        ),
        (np.column_stack([ids, data]), {"name": f"{name} tracks 3D", "metadata": meta}, "tracks"),
    ]
    if p.is_dir() and (p / "strain" / "strain_nodes.csv").is_file():
        out += strain_layers(p / "strain", name=f"{name} strain")
    return out


def _mesh_of(path: Path, values: str) -> LayerData | None:
    if not path.is_file():
        return None
    import pyvista as pv

    mesh = pv.read(path)
    if mesh.n_cells == 0:
        return None
    faces = mesh.regular_faces
    vertices = np.asarray(mesh.points)[:, ::-1]  # (z, y, x)
    data = np.asarray(mesh.point_data[values]) if values in mesh.point_data else vertices[:, 0]
    return (vertices, faces, data)


def mpm3d_layers(folder: str | os.PathLike) -> list[LayerData]:
    """An mpm3d run's layers: the height map (um), the surface (um, coloured by height),
    the crests; ``metadata["metrics"]`` holds metrics.json."""
    import tifffile

    folder = Path(folder)
    metrics = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    spacing = metrics.get("spacing_um", {})
    dy, dx = float(spacing.get("y", 1.0)), float(spacing.get("x", 1.0))
    heights = tifffile.imread(folder / "heightmap.tif")
    height = heights[0] if heights.ndim == 3 else heights
    meta = {"run": str(folder), "metrics": metrics}
    name = folder.name
    layers = [
        (
            np.asarray(height, np.float32),
            {
                "name": f"{name} height (um)",
                "scale": (dy, dx),
                "colormap": "viridis",
                "metadata": meta,
            },
            "image",
        )
    ]
    surface = _mesh_of(folder / "surface.vtp", "height_um")
    if surface is not None:
        layers.append(
            (
                surface,
                {"name": f"{name} surface", "colormap": "viridis", "metadata": meta},
                "surface",
            )
        )
    crests = folder / "crests.csv"
    if crests.is_file():
        with open(crests, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
        if rows:
            yx = np.array([(float(r["y_um"]), float(r["x_um"])) for r in rows])
            layers.append(
                (
                    yx,
                    {
                        "name": f"{name} crests",
                        "size": 3 * max(dy, dx),
                        "face_color": "red",
                        "metadata": meta,
                    },
                    "points",
                )
            )
    return layers


def multimodal_layers(folder: str | os.PathLike) -> list[LayerData]:
    """A multimodal run's layers: the microscope's surfaces before and after, and the
    camera's mesh on them (see the run's ParaView files)."""
    folder = Path(folder)
    summary_path = folder / "summary.json"
    meta = {"run": str(folder)}
    if summary_path.is_file():
        meta["summary"] = json.loads(summary_path.read_text(encoding="utf-8"))
    layers = []
    for stem in ("surface_before", "surface_after"):
        surface = _mesh_of(folder / f"{stem}.vtp", "height_um")
        if surface is not None:
            layers.append(
                (
                    surface,
                    {
                        "name": f"{folder.name} {stem.replace('_', ' ')}",
                        "colormap": "gray",
                        "opacity": 0.6,
                        "metadata": meta,
                    },
                    "surface",
                )
            )
    for stem in ("mesh_before", "mesh_after"):
        path = folder / f"{stem}.vtp"
        if path.is_file():
            import pyvista as pv

            mesh = pv.read(path)
            faces = mesh.regular_faces
            points = np.asarray(mesh.points)[:, ::-1]  # (z, y, x)
            name = "Exx_surface" if "Exx_surface" in mesh.cell_data else None
            if name is None:  # no per-triangle strain: coloured by height
                data = (points, faces, points[:, 0])
            else:  # each triangle flat in its own value: its three corners of its own
                data = (
                    points[faces].reshape(-1, 3),
                    np.arange(3 * len(faces)).reshape(-1, 3),
                    np.repeat(np.asarray(mesh.cell_data[name], float), 3),
                )
            layers.append(
                (
                    data,
                    {
                        "name": f"{folder.name} {stem.replace('_', ' ')}",
                        "colormap": "RdBu_r",
                        "metadata": {**meta, "values": name or "height_um"},
                    },
                    "surface",
                )
            )
    return layers


_READERS = {
    "frames": _frames,
    "stack": _stack,
    "strain": strain_layers,
    "stereo": _points3d,
    "points3d": _points3d,
    "mpm3d": mpm3d_layers,
    "multimodal": multimodal_layers,
}
