"""One stack to a lumen surface, fold metrics and their files.

:func:`analyze_stack` is what ``python -m mpm3d analyze`` runs: read the
stack (:mod:`mpm3d.io`), find the surface (:mod:`mpm3d.heightmap`), mesh it
(:mod:`mpm3d.surface`), measure it (:mod:`mpm3d.metrics`) and, with
:func:`write_analysis`, write::

    OUT/metrics.json      every metric, the spacing, input, parameters, version
    OUT/folds.csv         one row per fold (height, position, width)
    OUT/crests.csv        one row per crest and profile
    OUT/surface.vtp       the isosurface (ParaView), points (x, y, depth) um, with a
                          height_um point array and its datum in the field data
    OUT/surface.ply       the same mesh for other tools
    OUT/heightmap.tif     float32 height (um) with its pixel size (ImageJ)
    OUT/surface_intensity.tif  float32: the tissue's surface seen from above (the
                          mean intensity over the few um below the surface), with
                          its pixel size: what ``multimodal register`` matches
                          against a camera's frame
    OUT/figures/          heightmap.png, surface3d.png, profiles.png, spectrum.png
    OUT/report.html       one self-contained page: inputs, parameters, results,
                          quality, figures, what was flagged

Every height (metrics, heightmap.tif, both height figures, the mesh's
``height_um``) is measured from one datum, the plane of the stack's deepest
slice (:data:`mpm3d.heightmap.HEIGHT_DATUM`), and the two height figures
share one colour scale.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mpm3d.errors import InputError
from mpm3d.heightmap import (
    HEIGHT_DATUM,
    SURFACE_LAYER_UM,
    HeightMap,
    height_map,
    surface_intensity,
)
from mpm3d.io import Stack, read_stack, select_channel
from mpm3d.metrics import FoldSpectrum, FoldTable, fold_metrics
from tissue_core.csvtext import csv_writer
from tissue_core.filenames import readable, utf8_output
from tissue_core.html import input_records
from tissue_core.jsonio import write_json
from tissue_core.outputs import recorded_command
from tissue_core.vtkio import write_polydata

__all__ = ["Analysis", "analyze_stack", "write_analysis"]

log = logging.getLogger(__name__)

METRICS_VERSION = 1


def _version() -> str:
    from mpm3d import __version__

    return __version__


@dataclass(eq=False)
class Analysis:
    """Everything measured on one stack.

    Attributes
    ----------
    metrics : dict
        The contents of ``metrics.json``.
    heightmap : HeightMap
    spectrum : FoldSpectrum
    folds : FoldTable
    surface : pyvista.PolyData, mpm3d.meshstream.DiskMesh or None
        The isosurface (None when not asked for). On the banded path (a stack
        larger than its memory limit, ``lazy``, ``tile_rows``) a
        :class:`mpm3d.meshstream.DiskMesh`: the same mesh in files, read a chunk
        at a time; ``.polydata()`` loads it whole where it fits, ``.save(path)``
        writes it.
    """

    metrics: dict
    heightmap: HeightMap
    spectrum: FoldSpectrum
    folds: FoldTable
    surface: object = None
    params: dict = field(default_factory=dict)
    surface_intensity: np.ndarray | None = None

    @property
    def height_um(self) -> np.ndarray:
        return self.heightmap.height_um


@contextlib.contextmanager
def _about(path: str) -> Iterator[None]:
    """Errors raised in the block name the stack ``path`` they are about."""
    try:
        yield
    except InputError as exc:
        if path in str(exc):
            raise
        raise InputError(f"{path}: {exc}") from exc


def analyze_stack(
    source: str | os.PathLike | Stack,
    *,
    channel: int | str | None = None,
    spacing: Sequence[float] | None = None,
    threshold: float | None = None,
    smooth_um: float | None = None,
    min_fold_height_um: float | None = None,
    surface: bool = True,
    iso_bin: int | None = None,
    band_um: float = 100.0,
    decimate: float = 0.0,
    memory_limit: int | str | None = None,
    lazy: bool = False,
    tile_rows: int | None = None,
    progress: Callable[[str], None] | None = None,
) -> Analysis:
    """Measure the lumen surface and its folds in one z-stack.

    Parameters
    ----------
    source : path or Stack
        A TIFF z-stack (see :func:`mpm3d.io.read_stack`), a mosaic's tile list
        (a CSV ``file,x_um,y_um``, see :mod:`mpm3d.mosaic`) or a stack already
        read.
    channel : int or str, optional
        Channel index or name; by default every channel, each scaled to its
        own range, combined by their maximum.
    spacing : (dz, dy, dx) um, optional
        Overrides the file's voxel spacing.
    threshold, smooth_um : see :func:`mpm3d.heightmap.height_map`
    min_fold_height_um : see :func:`mpm3d.metrics.fold_profiles`
    surface : bool
        Also build the isosurface mesh.
    iso_bin, band_um, decimate : see :func:`mpm3d.surface.isosurface`
    memory_limit : int or str, optional
        Bytes (or text such as ``"1.5GiB"``, see :func:`mpm3d.tiled.parse_memory`)
        the analysis may use; by default half the memory available now.  A
        stack whose in-memory working set would exceed it is read and
        analysed in bands of rows (:mod:`mpm3d.tiled`), with the same
        results.  Not used for a ``source`` already read.
    lazy : bool
        Read the stack in bands even when it would fit.
    tile_rows : int, optional
        Rows of pixels per band of the height map (the isosurface's bands
        are as many pixels, in binned rows); implies ``lazy``.  By default
        as many as the memory limit allows.
    progress : callable, optional
        Called with a short message before each step.  A
        :class:`tissue_core.progress.Progress` also counts the bands.

    Returns
    -------
    Analysis
        Its ``metrics`` also list the warnings the analysis raised
        (``warnings``; they are raised again, once the analysis is done).
    """
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            analysis = _analyze(
                source,
                channel=channel,
                spacing=spacing,
                threshold=threshold,
                smooth_um=smooth_um,
                min_fold_height_um=min_fold_height_um,
                surface=surface,
                iso_bin=iso_bin,
                band_um=band_um,
                decimate=decimate,
                memory_limit=memory_limit,
                lazy=lazy,
                tile_rows=tile_rows,
                progress=progress,
            )
    finally:  # raised again, even when the analysis failed: callers see them as before
        for record in caught:
            warnings.warn_explicit(record.message, record.category, record.filename, record.lineno)
    flagged = [str(r.message) for r in caught if issubclass(r.category, UserWarning)]
    analysis.metrics["warnings"] = flagged
    return analysis


def _analyze(
    source,
    *,
    channel,
    spacing,
    threshold,
    smooth_um,
    min_fold_height_um,
    surface,
    iso_bin,
    band_um,
    decimate,
    memory_limit,
    lazy,
    tile_rows,
    progress,
) -> Analysis:
    say = progress or (lambda message: None)
    if isinstance(source, Stack):
        stack, plan, mosaic = source, None, None
    else:
        stack, plan, mosaic = _open(
            source,
            spacing=spacing,
            channel=channel,
            surface=surface,
            iso_bin=iso_bin,
            memory_limit=memory_limit,
            lazy=lazy or tile_rows is not None,
            tile_rows=tile_rows,
        )
    tiled = plan is not None and plan.path == "tiled"
    with _about(stack.path), contextlib.ExitStack() as cleanup:  # the problem is this stack's
        if tiled:
            from mpm3d.tiled import StackBands, tiled_height_map

            cleanup.callback(stack.data.close)
            say("choosing the channel")
            index, channel_label = _lazy_channel(stack, channel)
            volume = StackBands(stack.data, index)
            say("finding the surface")
            hm = tiled_height_map(
                volume,
                spacing=stack.spacing,
                tile_rows=plan.tile_rows,
                threshold=threshold,
                smooth_um=smooth_um,
                progress=progress,
            )
        else:
            say("choosing the channel")
            volume, channel_label = select_channel(stack, channel)
            say("finding the surface")
            hm = height_map(volume, spacing=stack.spacing, threshold=threshold, smooth_um=smooth_um)
        say("reading the surface's intensity")
        projection = surface_intensity(
            volume, hm.depth_um, stack.spacing[0], rows=plan.tile_rows if tiled else None
        )
        say("measuring the folds")
        metrics, spectrum, folds = fold_metrics(
            hm.height_um,
            spacing=stack.spacing,
            mask=hm.valid,
            min_fold_height_um=min_fold_height_um,
            resolution_um=stack.spacing[0],
            overwrite=True,  # a new array: the metrics work in it
        )
        mesh = None
        if surface:
            from mpm3d.surface import add_height, isosurface

            say("building the isosurface")
            options = {
                "spacing": stack.spacing,
                "level": 0.5,
                "column_scale": (hm.background, hm.peak),
                "depth_um": hm.depth_um,
                "bin": iso_bin,
                "band_um": band_um,
                "decimate": decimate,
            }
            if tiled:
                from mpm3d.surface import default_bin
                from mpm3d.tiled import (
                    mesh_budget,
                    mesh_triangles,
                    plan_surface,
                    tiled_isosurface,
                )

                # the bands sized for the mesh these folds make (known from the height map)
                binning = iso_bin if iso_bin is not None else default_bin(stack.spacing)
                triangles = mesh_triangles(hm.depth_um, stack.spacing, binning)
                plan = plan_surface(plan, triangles, iso_bin=binning, streamed=not decimate)
                mesh = tiled_isosurface(
                    volume,
                    tile_rows=plan.surface_tile_rows,
                    piece_rows=plan.mesh_piece_rows,
                    max_triangles=mesh_budget(plan),
                    progress=progress,
                    expected_triangles=triangles,
                    **options,
                )
            else:
                from mpm3d.tiled import mesh_budget

                mesh = isosurface(volume, max_triangles=mesh_budget(plan), **options)
            add_height(mesh, hm.datum_depth_um, datum=_datum_text(hm))
    del volume
    params = {
        "channel": channel,
        "threshold": threshold,
        "smooth_um": smooth_um,
        "min_fold_height_um": min_fold_height_um,
        "surface": surface,
        "iso_bin": iso_bin,
        "band_um": band_um,
        "decimate": decimate,
        "memory": plan.record() if plan is not None else {"path": "in-memory", "given": "Stack"},
        # a mosaic's tiles and where each lies (None for one stack)
        "mosaic": mosaic,
    }
    # the height's range from the depth's (no map-sized copy): the same numbers, as the
    # height is the datum less the depth
    depth_range = (float(hm.depth_um.min()), float(hm.depth_um.max()))
    height_range = [hm.datum_depth_um - depth_range[1], hm.datum_depth_um - depth_range[0]]
    colour = list(height_range)
    if mesh is not None and mesh.n_points:
        from mpm3d.meshstream import bounds_of

        lo, hi = bounds_of(mesh)
        # as add_height makes height_um: the datum less the depth, in float64
        datum = np.float64(hm.datum_depth_um)
        mesh_range = [float(datum - np.float64(hi[2])), float(datum - np.float64(lo[2]))]
        colour = [min(colour[0], mesh_range[0]), max(colour[1], mesh_range[1])]
    record = {
        # names as text (figure titles, tables): bytes that are not UTF-8 as \xNN
        "input": readable(os.path.basename(stack.path)),
        "input_path": readable(stack.path),
        "inputs": input_records(
            [stack.path, *(p["file"] for p in mosaic["placements"])] if mosaic else [stack.path]
        ),
        **{k: metrics[k] for k in metrics},
        "spacing_um": {"z": stack.spacing[0], "y": stack.spacing[1], "x": stack.spacing[2]},
        "spacing_source": stack.spacing_source,
        "shape_zcyx": list(stack.shape),
        "channel": channel_label,
        "threshold": hm.threshold,
        "background": hm.background,
        "surface_level": hm.level,
        "surface_cut_fraction": hm.cut_fraction,
        "surface_coverage": hm.coverage,
        "surface_depth_range_um": list(depth_range),
        "n_surface_triangles": int(mesh.n_cells) if mesh is not None else None,
        "height_datum": {
            "datum": HEIGHT_DATUM,
            "depth_below_first_slice_um": hm.datum_depth_um,
            "unit": "um",
            "used_by": [
                "heightmap.tif",
                "figures/heightmap.png",
                "figures/surface3d.png",
                "surface.vtp point array height_um",
                "height_range_um",
            ],
        },
        "height_range_um": height_range,
        "mesh_height_range_um": mesh_range if mesh is not None and mesh.n_points else None,
        "height_colour_range_um": colour,
        "quality": _quality(hm, mesh),
        "conventions": {
            "height": "elevation above the deepest slice, um (crests high): the datum of "
            "heightmap.tif, both height figures and the mesh's height_um array",
            "orientation": "crest direction, degrees from the image x axis (columns) "
            "towards y (rows), in [0, 180)",
            "mesh": "points (x, y, depth below slice 0) in um, normals into the lumen; "
            "contoured at each column's half-maximum (background to surface peak); "
            "point arrays depth_um and height_um (above the deepest slice)",
            "fold_height_um": "median over folds of each fold's median crest-to-trough height",
            "fold_wavelength_um": "null with fewer than 2 fold periods in view: "
            "see fold_wavelength_note and fold_periods_in_view",
            "max_fold_height_um": "the highest fold's median crest-to-trough height",
            "roughness": "ISO 25178-2 on the height map with its least-squares plane removed",
        },
        "parameters": {**params, **hm.params},
        "software": {"package": "tissue-strain", "module": "mpm3d", "version": _version()},
        "command": recorded_command.get(),
        "metrics_version": METRICS_VERSION,
    }
    return Analysis(
        metrics=record, heightmap=hm, spectrum=spectrum, folds=folds, surface=mesh, params=params,
        surface_intensity=projection,
    )  # fmt: skip


def _open(source, *, spacing, channel, surface, iso_bin, memory_limit, lazy, tile_rows):
    """The stack, read in memory or opened for reading in bands, the plan that chose, and
    for a mosaic's tile list (:mod:`mpm3d.mosaic`) where its tiles lie (else None).

    The file's metadata are read first (:func:`mpm3d.lazyio.open_stack_lazily`);
    the stack is read whole only when :func:`mpm3d.tiled.plan_memory` says
    it fits.
    """
    from mpm3d.lazyio import open_stack_lazily
    from mpm3d.mosaic import is_tile_list, mosaic_record, open_mosaic
    from mpm3d.surface import default_bin
    from mpm3d.tiled import default_memory_limit, parse_memory, plan_memory

    if memory_limit is None:
        limit = default_memory_limit()
    elif isinstance(memory_limit, str):
        limit = parse_memory(memory_limit)
    else:
        limit = int(memory_limit)
        if limit < 1:
            raise InputError(f"memory_limit must be a positive number of bytes, got {memory_limit}")
    if tile_rows is not None and (isinstance(tile_rows, bool) or int(tile_rows) != tile_rows):
        raise InputError(f"tile_rows must be a whole number, got {tile_rows!r}")
    with warnings.catch_warnings(record=True) as held:  # raised by the reading that follows
        warnings.simplefilter("always")
        mosaic = is_tile_list(source)
        stack = (open_mosaic if mosaic else open_stack_lazily)(source, spacing=spacing)
    try:
        nc = stack.shape[1]
        combined = channel is None and nc > 1
        plan = plan_memory(
            stack.shape,
            stack.data.dtype.itemsize,
            limit=limit,
            combined=combined,
            channels_read=nc if combined else 1,
            surface=surface,
            bin=iso_bin if iso_bin is not None else default_bin(stack.spacing),
            lazy=lazy,
            tile_rows=tile_rows,
            copies=2 if mosaic else 1,
        )
        if memory_limit is not None and plan.path == "in-memory":
            # a limit above the memory there is reads the stack whole: into swap, or a failure
            from mpm3d.tiled import BASE_BYTES, format_bytes
            from tissue_core.resources import check_fits

            check_fits(
                f"--memory-limit {format_bytes(limit)} reads the stack whole, which",
                memory=plan.in_memory_bytes - BASE_BYTES,  # this process is running already
                remedy="give a --memory-limit within it (the stack is then read in bands)",
            )
    except BaseException:
        stack.data.close()
        raise
    record = mosaic_record(stack.data) if mosaic else None
    if plan.path == "in-memory" and not mosaic:
        stack.data.close()
        return read_stack(source, spacing=spacing), plan, None  # its warnings again
    for said in held:
        warnings.warn_explicit(said.message, said.category, said.filename, said.lineno)
    if plan.path == "in-memory":  # a mosaic stitched in memory, from the tiles read whole
        with stack.data as data:
            return dataclasses.replace(stack, data=data[:]), plan, record
    log.info("%s: analysed in bands (%s)", stack.path, plan)
    return stack, plan, record


def _lazy_channel(stack: Stack, channel) -> tuple[int | None, str]:
    """:func:`mpm3d.io.select_channel`'s choice for a stack read in bands: (index, label)."""
    from mpm3d.io import _channel_index

    names = stack.channel_names
    if channel is None:
        if len(names) == 1:
            return 0, names[0]
        return None, "max of " + ", ".join(names)
    index = _channel_index(channel, names)
    return index, names[index]


def _datum_text(hm: HeightMap) -> str:
    return (
        f"height_um: elevation in um above the stack's deepest slice "
        f"({hm.datum_depth_um:g} um below the first slice)"
    )


def _quality(hm: HeightMap, mesh) -> dict:
    """How well the surface was measured: coverage, segmentation, mesh (metrics.json)."""
    valid_cnr = hm.cnr[hm.valid]
    out = {
        "surface_coverage": hm.coverage,
        "dropouts": dict(hm.dropouts),
        "threshold": hm.threshold,
        "threshold_method": "given (--threshold)"
        if hm.params.get("threshold_given")
        else "Otsu on a subsample of the voxels",
        "background": hm.background,
        "background_noise": hm.noise,
        "otsu_separability": hm.separability,
        "median_surface_cnr": float(np.median(valid_cnr)) if valid_cnr.size else None,
        "min_cnr": hm.params.get("min_cnr"),
        "mesh": None,
        "mesh_vs_heightmap_um": None,
    }
    if mesh is not None and mesh.n_cells:
        from mpm3d.surface import mesh_quality, vertical_error_summary

        _, dy, dx = hm.spacing
        field = mesh.field_data
        lateral_bin = int(field["lateral_bin"][0]) if "lateral_bin" in field else 1
        q = mesh_quality(mesh, edge_um=2.0 * lateral_bin * max(dy, dx))
        q["developed_area_ratio"] = (
            q["area_um2"] / q["projected_area_um2"] if q["projected_area_um2"] > 0 else None
        )
        q["lateral_bin"] = lateral_bin
        out["mesh"] = q
        summary = vertical_error_summary(mesh, hm.depth_um, spacing=hm.spacing)
        if summary is not None:
            out["mesh_vs_heightmap_um"] = {
                **summary,
                "note": "depth of each mesh vertex minus the height map's at its (x, y); "
                "large on steep or overhanging flanks, where a column meets the surface "
                "more than once",
            }
    return out


def _write_table(path: Path, table: dict) -> None:
    keys = list(table)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv_writer(f)
        w.writerow(keys)
        for row in zip(*(table[k] for k in keys), strict=True):
            w.writerow([f"{v:.6g}" if isinstance(v, float | np.floating) else v for v in row])


def _save_vtp(mesh, path: Path) -> None:
    """XML PolyData, binary, LZ4-compressed (fast to write, read by ParaView 5.6+)."""
    write_polydata(mesh, path, compressor="lz4", appended=True)


def write_analysis(analysis: Analysis, folder: str | os.PathLike, *, figures: bool = True) -> None:
    """Write an :class:`Analysis` into an existing, empty ``folder``.

    The figures listed in ``metrics["figures"]`` and ``report.html`` come
    last; ``metrics.json`` records the colour range both height figures use.
    """
    import tifffile

    from mpm3d.report import write_analysis_report

    folder = Path(folder)
    hm = analysis.heightmap
    metrics = analysis.metrics
    _write_table(folder / "folds.csv", analysis.folds.folds)
    _write_table(folder / "crests.csv", analysis.folds.crests)
    _, dy, dx = hm.spacing
    # the two channels as float32, filled a band of rows at a time (no float64 copies)
    datum = hm.datum_depth_um
    planes = np.empty((2, *hm.depth_um.shape), np.float32)
    for a in range(0, planes.shape[1], 256):
        planes[0, a : a + 256] = datum - hm.depth_um[a : a + 256]
        planes[1, a : a + 256] = hm.valid[a : a + 256]
    tifffile.imwrite(
        folder / "heightmap.tif",
        planes,
        imagej=True,
        resolution=(1 / dx, 1 / dy),
        metadata={
            "unit": "um",
            "axes": "CYX",
            "Labels": ["height_um", "measured"],
            "info": "channel 0: surface height above the deepest slice (um; "
            f"{hm.datum_depth_um:g} um below the first slice); "
            "channel 1: 1 where measured, 0 where filled",
        },
    )
    del planes  # not alive while the figures are drawn
    if analysis.surface_intensity is not None:
        tifffile.imwrite(
            folder / "surface_intensity.tif",
            analysis.surface_intensity.astype(np.float32),
            imagej=True,
            resolution=(1 / dx, 1 / dy),
            metadata={
                "unit": "um",
                "info": "the mean intensity over the first "
                f"{SURFACE_LAYER_UM:g} um below the surface, per column",
            },
        )
    fig_dir = folder / "figures"
    if figures:
        fig_dir.mkdir()
    name = metrics["input"]
    mesh = analysis.surface
    clim = tuple(metrics["height_colour_range_um"])
    rendering: dict = {}

    def vtk_outputs() -> None:  # VTK work, in a thread beside the matplotlib figures
        from mpm3d.meshstream import DiskMesh

        if isinstance(mesh, DiskMesh):  # too large to hold: written a chunk at a time
            mesh.save_vtp(folder / "surface.vtp")
            mesh.save_ply(folder / "surface.ply")
        else:
            _save_vtp(mesh, folder / "surface.vtp")
            with utf8_output(folder / "surface.ply") as target:
                mesh.save(target, binary=True, recompute_normals=False)  # as it is
        if figures:
            from mpm3d.figures import render_surface

            rendering.update(
                render_surface(
                    mesh,
                    fig_dir / "surface3d.png",
                    datum_depth_um=hm.datum_depth_um,
                    clim=clim,
                    title=name,
                )
            )

    from mpm3d.meshstream import DiskMesh

    # a mesh too large to hold is written and drawn after the other figures, not beside
    # them: its chunks and the rendering would add to the figures' memory
    beside = mesh is not None and not isinstance(mesh, DiskMesh)
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(vtk_outputs) if beside else None
        if figures:
            from mpm3d import figures as fg

            fg.plot_height_map(
                hm.height_um,
                spacing=hm.spacing,
                valid=hm.valid,
                folds=analysis.folds,
                title=f"{name}: lumen surface height",
                clim=clim,
            ).savefig(fig_dir / "heightmap.png")
            fg.plot_profiles(analysis.folds).savefig(fig_dir / "profiles.png")
            fg.plot_spectrum(analysis.spectrum).savefig(fig_dir / "spectrum.png")
        if pending is not None:
            pending.result()
    if mesh is not None and not beside:
        vtk_outputs()
    if figures:
        listed = [
            (
                "heightmap.png",
                "Lumen surface height above the stack's deepest slice (µm), "
                "seen from the objective; shaded where no surface was measured (filled in); "
                "white dots: the crests found along each profile across the folds.",
            ),
            (
                "surface3d.png",
                "The isosurface mesh (surface.vtp) seen obliquely from the lumen, "
                "coloured on the height map's colour scale; axes and scale bar in µm, heights "
                "above the deepest slice (the grey rectangle).",
            ),
            ("profiles.png", "Height along profiles across the fold crests, form removed (µm)."),
            (
                "spectrum.png",
                "Power spectrum of the height map; the circled peak is the "
                "dominant fold frequency.",
            ),
        ]
        metrics["figures"] = [
            {"file": f"figures/{f}", "caption": c} for f, c in listed if (fig_dir / f).is_file()
        ]
        if rendering:
            metrics["surface3d_rendering"] = {
                "colour_range_um": list(rendering["clim"]),
                "scale_bar_um": rendering["scale_bar_um"],
                "simplified_for_display": rendering["simplified"],
                "triangles_drawn": rendering["triangles_drawn"],
            }
    write_json(folder / "metrics.json", metrics)
    write_analysis_report(folder, metrics)
