"""Command line: ``python -m multimodal strain RUN --before B --after A --out DIR``.

Lifts a camera run (``strain2d analyze``) onto the microscope's height maps
of the same tissue before and after (``mpm3d analyze`` folders or height-map
TIFFs) and writes, per triangle, the camera's projected strain, the strain
along the folded surface where the maps cover the triangle, and the
statistics-only correction everywhere (``fold_strain.csv``), the surface's
tortuosity per direction (``tortuosity.csv``), ``summary.json`` and a
figure.  The camera and the microscope are registered by landmark pairs
(``--landmarks``, with their residual) or a given similarity
(``--transform``).  Errors a user can cause end with one line on stderr and
exit status 2.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tissue_core.errors import InputError

__all__ = ["main"]


def _build_parser():
    from tissue_core.cli import CommandLine

    cli = CommandLine("multimodal", "Camera and microscope together: fold-aware strain.")
    p = cli.command(
        "strain",
        _cmd_strain,
        help="membrane strain along the microscope's surface for a camera run's triangles",
    )
    p.add_argument(
        "run",
        help="a strain2d analyze output folder, or a stereo reconstruct one (with --strain)",
    )
    p.add_argument("--before", required=True, help="height map of the reference state "
                   "(an mpm3d analyze folder or a height-map TIFF, in um)")  # fmt: skip
    p.add_argument("--after", required=True, help="height map of the deformed state")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument(
        "--landmarks",
        help="CSV of landmark pairs: camera_x,camera_y (px, on the run's reference frame), "
        "microscope_x,microscope_y (um)",
    )
    how.add_argument(
        "--transform",
        help="camera px to microscope um: a JSON file (scale_um_per_px, angle_deg, shift_um, "
        "mirrored) or SCALE,ANGLE,SHIFT_X,SHIFT_Y; for a stereo run, the registration.json "
        "of multimodal register3d (the --before map on the run's frame 0)",
    )
    p.add_argument(
        "--transform-after",
        help="a stereo run: register3d's registration.json of the --after map on the run's "
        "--frame (default: --transform's, the microscope and the cameras kept still)",
    )
    p.add_argument(
        "--mirrored", action="store_true", help="the microscope sees the tissue mirrored"
    )
    p.add_argument(
        "--frame",
        type=int,
        help="the run's frame the --after map shows (default: the run's contraction endpoint)",
    )
    p.add_argument(
        "--path",
        choices=["geodesic", "chord"],
        default="geodesic",
        help="how an edge runs on the surface: the shortest path near its chord (default), "
        "or the chord itself",
    )
    p.add_argument(
        "--pixel-um", type=float, help="the height maps' pixel size, um (overrides the files')"
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "register",
        _cmd_register,
        help="the camera-to-microscope similarity from the images, found automatically",
    )
    p.add_argument("camera", help="the camera's video, image or image folder (its first frame)")
    p.add_argument(
        "microscope",
        help="the microscope's surface-intensity projection: an mpm3d analyze folder (its "
        "surface_intensity.tif), a TIFF with its pixel size, or any image with --pixel-um",
    )
    p.add_argument("--pixel-um", type=float, help="the microscope image's pixel size, um")
    p.add_argument(
        "--mirrored", action="store_true", help="the microscope sees the tissue mirrored"
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "register3d",
        _cmd_register3d,
        help="the microscope's surface onto a stereo run's: landmarks, refined by ICP",
    )
    p.add_argument("camera", help="a stereo reconstruct output folder (its points3d.csv)")
    p.add_argument(
        "microscope", help="the microscope's height map: an mpm3d analyze folder or a TIFF"
    )
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument(
        "--landmarks",
        help="CSV of landmark pairs: camera_x,camera_y,camera_z (the stereo run's units), "
        "microscope_x,microscope_y (um) and microscope_z (the height, um)",
    )
    how.add_argument(
        "--transform",
        help="a start instead of landmarks: a JSON file with scale_per_um, rotation and "
        "shift (this command's registration.json)",
    )
    p.add_argument(
        "--frame", type=int, default=0, help="the stereo run's frame the map shows (default 0)"
    )
    p.add_argument(
        "--scale",
        type=float,
        metavar="PER_UM",
        help="the stereo run's units per micrometre when known (0.001 for mm): kept, not fitted",
    )
    p.add_argument(
        "--mirrored", action="store_true", help="the microscope sees the tissue mirrored"
    )
    p.add_argument("--pixel-um", type=float, help="the height map's pixel size, um")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    return cli


def _camera_surface(folder: Path, frame: int):
    """A stereo run's points at ``frame`` (visible ones), its mesh among them, its unit."""
    import json

    from surface_strain import delaunay_triangles, read_points3d

    points_file = folder / "points3d.csv"
    if not points_file.is_file():
        raise InputError(f"{folder}: no points3d.csv; give a stereo reconstruct output folder")
    tracks = read_points3d(points_file)
    if not 0 <= frame < tracks.n_frames:
        raise InputError(f"--frame {frame} is outside the run's frames 0..{tracks.n_frames - 1}")
    unit = "camera units"
    try:
        found = json.loads((folder / "summary.json").read_text(encoding="utf-8"))["unit"]
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        found = None
    if isinstance(found, str) and 0 < len(found) <= 20 and found.isprintable():
        unit = found
    points = tracks.positions[frame]
    seen = tracks.visible[frame] & np.isfinite(points).all(axis=1)
    if seen.any() and np.abs(points[seen]).max() >= 1e9:
        raise InputError(f"{folder}: a point lies beyond 1e9 {unit}: not a plausible position")
    elements = folder / "strain" / "strain_elements.csv"
    if elements.is_file():
        triangles = _triangles(folder / "strain", tracks.n_points)
        triangles = triangles[seen[triangles].all(axis=1)]
    else:  # reconstructed without --strain: a mesh of the points seen
        kept = np.flatnonzero(seen)
        try:
            triangles = kept[delaunay_triangles(points[kept])] if len(kept) >= 3 else kept[:0]
        except ValueError as exc:
            raise InputError(f"{folder}: its points at frame {frame} make no mesh: {exc}") from None
    if len(triangles) < 2:
        raise InputError(f"{folder}: fewer than 2 triangles with every point seen at frame {frame}")
    V = points[triangles]
    area = 0.5 * np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=1)
    edge = np.linalg.norm(V[:, 1] - V[:, 0], axis=1)
    if not area.sum() > 1e-6 * np.sum(edge**2):
        raise InputError(f"{folder}: its mesh at frame {frame} has no area (its points on a line)")
    return points, triangles, unit, [points_file, *([elements] if elements.is_file() else [])]


def _cmd_register3d(args) -> int:
    from multimodal.geometry import SurfaceMap
    from multimodal.io import read_landmarks3d
    from multimodal.run import _surface_mesh, _surface_step
    from multimodal.surface3d import (
        Similarity3D,
        _normals,
        closest_points_on_mesh,
        heightmap_points,
        refine_icp,
    )
    from tissue_core.csvtext import number_cell
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import atomic_dir, check_writable
    from tissue_core.progress import Progress
    from tissue_core.version import __version__

    say = Progress(quiet=args.quiet)
    landmarks = args.landmarks is not None
    if args.scale is not None and not (np.isfinite(args.scale) and args.scale > 0):
        raise InputError(f"--scale must be a positive number, got {args.scale}")
    if not landmarks and (args.scale is not None or args.mirrored):
        flag = "--scale" if args.scale is not None else "--mirrored"
        raise InputError(
            f"{flag} goes with --landmarks: a --transform gives its own scale and says whether "
            "it is mirrored"
        )
    folder = Path(args.camera)
    vertices, triangles, unit, camera_files = _camera_surface(folder, args.frame)
    surface = _named_map("microscope", args.microscope, args.pixel_um)
    if not isinstance(surface, SurfaceMap):
        raise InputError(f"{args.microscope}: give one height map, not a mosaic's tiles")
    # the folders too: no output inside the run or the microscope's folder
    inputs = [folder, *camera_files, *_map_files(surface)]
    inputs += [Path(args.microscope)] if Path(args.microscope).is_dir() else []
    inputs += [Path(p) for p in (args.landmarks, args.transform) if p and Path(p).is_file()]
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    residual = None
    if landmarks:
        camera_lm, microscope_lm = read_landmarks3d(args.landmarks)
        _landmarks_on_map(microscope_lm, surface)
        start, residual = Similarity3D.from_landmarks(
            microscope_lm, camera_lm, mirrored=args.mirrored, scale=args.scale
        )
    else:
        start = _start_transform(args.transform)
    step = max(1, int(np.ceil(np.sqrt(np.isfinite(surface.height_um).sum() / 40_000))))
    points = heightmap_points(surface, step=step)
    if len(points) < 10:
        raise InputError(
            f"{args.microscope}: only {len(points)} of its pixels have a measured height; the "
            "registration needs 10 or more"
        )
    say(
        f"{folder}: {len(vertices)} points, {len(triangles)} triangles at frame {args.frame} "
        f"({unit}); microscope: {len(points)} points of {args.microscope} (every {step})"
    )
    found = refine_icp(points, vertices, triangles, start, fit_scale=args.scale is None)
    t = found.transform
    fixed = [k for k, v in found.fixed_by_surfaces.items() if v >= 0.5]
    loose = [k for k, v in found.fixed_by_surfaces.items() if v < 0.5]
    flags = []
    if loose:
        flags.append(
            "the surfaces' shapes do not fix " + ", ".join(loose) + ": they are the landmarks' "
            "(or the start's), as good as those are"
        )
    if found.fitness < 0.5:
        flags.append(
            f"only {found.fitness:.0%} of the microscope's points were paired with the camera's "
            "surface: the surfaces may not correspond"
        )
    if not found.converged:
        flags.append(f"ICP stopped after {found.iterations} iterations without converging")
    flags += _registration_flags(points, start, found, residual, camera_lm if landmarks else None,
                                 unit)  # fmt: skip
    per_um = 1.0 / t.scale  # um per camera unit
    summary = {
        "software": {"name": "multimodal", "version": __version__},
        "camera": str(folder),
        "frame": args.frame,
        "camera_unit": unit,
        "microscope": str(args.microscope),
        "microscope_pixel_um": list(surface.pixel_um),
        "microscope_points_used": len(points),
        "transform": t.as_dict(),
        "start": start.as_dict(),
        "landmarks": None
        if residual is None
        else {
            "pairs": len(residual),
            "residual_rms": float(np.sqrt(np.mean(residual**2))),
            "residual_max": float(residual.max()),
            "unit": unit,
        },
        "icp": {
            **found.as_dict(),
            "rms_before_um": found.rms_before * per_um,
            "rms_after_um": found.rms_after * per_um,
            "unit": unit,
            "scale_fitted": args.scale is None,
        },
        "flags": flags,
    }
    # the microscope's surface in the camera's frame, for one ParaView scene with the run: the
    # mesh multimodal strain draws, its (x, y, height) as (x, y, depth)
    mesh_points, mesh_triangles = _surface_mesh(surface)
    k = _surface_step(surface)
    height = surface.height_um[::k, ::k].ravel()
    moved = t.apply(mesh_points * [1.0, 1.0, -1.0])
    closest, _, which, outside = closest_points_on_mesh(moved, vertices, triangles)
    # signed: positive towards the cameras (the stereo frame's origin), as a height is
    normals = _normals(vertices, triangles)
    normals[np.einsum("ij,ij->i", normals, vertices[triangles[:, 0]]) > 0] *= -1
    distance = np.einsum("ij,ij->i", normals[which], moved - closest)
    distance = np.where(outside | ~np.isfinite(height), np.nan, distance)
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        from tissue_core.vtkio import write_triangles

        write_json(tmp / "registration.json", summary)
        units = {"length_unit": [unit]}
        write_triangles(
            tmp / "microscope_surface.vtp",
            moved,
            mesh_triangles,
            {"height_um": height, "above_camera_surface": distance},
            field_data=units,
        )
        write_triangles(tmp / "camera_surface.vtp", vertices, triangles, field_data=units)
        if residual is not None:
            rows = ["camera_x,camera_y,camera_z,microscope_x,microscope_y,microscope_z,residual"]
            for c, m, r in zip(camera_lm, microscope_lm, residual, strict=True):
                values = (*c, m[0], m[1], -m[2], r)
                rows.append(",".join(number_cell(float(v)) for v in values))
            (tmp / "landmarks.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
        (tmp / "figures").mkdir()
        _distance_figure(
            tmp / "figures" / "registration3d.png", surface, k, distance * per_um, summary
        )
    say(
        f"microscope onto camera: {t.scale:.6g} {unit}/um, turned {t.angle_deg:.4g} deg; "
        + (
            ""
            if residual is None
            else f"landmarks {summary['landmarks']['residual_rms']:.3g} {unit} RMS; "
        )
        + f"ICP {found.rms_before * per_um:.3g} to {found.rms_after * per_um:.3g} um RMS off "
        f"the camera's surface, {found.fitness:.0%} paired"
    )
    say("fixed by the surfaces: " + (", ".join(fixed) or "none"))
    for flag in flags:
        say(f"flagged: {flag}")
    say(f"results in {args.out} (open microscope_surface.vtp with the run's strain/strain.pvd)")
    return 0


def _start_transform(path: str):
    """``--transform``: register3d's registration.json, or a JSON of the transform."""
    return _registration3d(path, "--transform")[0]


def _landmarks_on_map(microscope: np.ndarray, surface) -> None:
    """Refuse landmarks that are not on the height map (wrong units, or pixel size)."""
    dy, dx = surface.pixel_um
    x0, y0 = surface.origin_um
    ny, nx = surface.height_um.shape
    x1, y1 = x0 + (nx - 1) * dx, y0 + (ny - 1) * dy
    off = (
        (microscope[:, 0] < x0 - dx)
        | (microscope[:, 0] > x1 + dx)
        | (microscope[:, 1] < y0 - dy)
        | (microscope[:, 1] > y1 + dy)
    )
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise InputError(
            f"landmark {k + 1} ({microscope[k, 0]:.6g}, {microscope[k, 1]:.6g} um) is not on the "
            f"height map ({x0:.6g}..{x1:.6g}, {y0:.6g}..{y1:.6g} um): are the landmarks in um, "
            "and the map's pixel size right?"
        )


#: camera units per micrometre of the units a stereo run may be in
_UNITS_PER_UM = {"mm": 1e-3, "cm": 1e-4, "m": 1e-6, "um": 1.0, "µm": 1.0, "nm": 1e3}


def _registration_flags(points, start, found, residual, camera_lm, unit: str) -> list[str]:
    """What makes a registration doubtful though it ran: a microscope upside down, landmarks
    that disagree with each other, a scale the run's unit does not give, or ICP moving the
    patch far from where the start put it."""
    flags = []
    t = found.transform
    moved = t.apply(points)
    centre = moved.mean(axis=0)
    size = float(np.sqrt(np.mean(np.sum((moved - centre) ** 2, axis=1))))
    if np.dot(t.rotation[:, 2], centre) < 0:
        flags.append(
            "the microscope's depth points towards the cameras: right if it imaged the tissue "
            "from the other side; otherwise check the landmarks' columns and --mirrored"
        )
    if residual is not None:
        spread = float(np.sqrt(np.mean(np.sum((camera_lm - camera_lm.mean(axis=0)) ** 2, 1))))
        rms = float(np.sqrt(np.mean(residual**2)))
        if rms > 0.2 * spread:
            flags.append(
                f"the landmarks disagree: {rms:.3g} {unit} RMS off their fit, "
                f"{rms / spread:.0%} of their spread (a pair mismatched, or a unit?)"
            )
    expected = _UNITS_PER_UM.get(unit)
    if expected is not None and not 0.8 < t.scale / expected < 1.25:
        flags.append(
            f"the scale is {t.scale:.4g} {unit} per um where the units make {expected:g}: "
            "check the landmarks' units and the map's pixel size"
        )
    shift = float(np.linalg.norm(centre - start.apply(points).mean(axis=0)))
    landmark_rms = float(np.sqrt(np.mean(residual**2))) if residual is not None else 0.0
    if shift > max(5 * landmark_rms, 0.25 * size):
        times = f", {shift / landmark_rms:.0f} times the landmarks' residual" * bool(landmark_rms)
        flags.append(
            f"ICP moved the patch {shift:.3g} {unit} from where the start put it{times}: do the "
            "landmarks, the height map and --frame belong together?"
        )
    return flags


def _distance_figure(path: Path, surface, step: int, distance_um, summary: dict) -> None:
    """The microscope's surface seen from above, coloured by its height above the camera's
    surface once registered (its folds, and what the registration left)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    z = surface.height_um[::step, ::step]
    grid = np.reshape(distance_um, z.shape)  # the mesh's points: a pixel each, row by row
    dy, dx = surface.pixel_um
    x0, y0 = surface.origin_um
    extent = (x0 - step * dx / 2, x0 + (z.shape[1] - 0.5) * step * dx,
              y0 + (z.shape[0] - 0.5) * step * dy, y0 - step * dy / 2)  # fmt: skip
    fig = Figure(figsize=(6.4, 5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    top = float(np.nanmax(np.abs(grid))) if np.isfinite(grid).any() else 1.0
    shown = ax.imshow(grid, extent=extent, cmap="RdBu_r", vmin=-top, vmax=top,
                      interpolation="nearest")  # fmt: skip
    fig.colorbar(shown, ax=ax, label="height above the camera's surface (um)")
    icp = summary["icp"]
    ax.set_title(
        f"microscope on the camera's surface: {icp['rms_after_um']:.3g} um RMS, "
        f"{icp['fitness']:.0%} paired",
        fontsize=10,
    )
    ax.set_xlabel("x (um)")
    ax.set_ylabel("y (um)")
    fig.savefig(path, dpi=100)


def _cmd_register(args) -> int:
    from multimodal.io import read_microscope_image
    from multimodal.registration import register_images
    from strain2d import open_frames
    from tissue_core.csvtext import number_cell
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import atomic_dir, check_writable
    from tissue_core.progress import Progress

    inputs = [Path(args.camera), Path(args.microscope)]
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    say = Progress(quiet=args.quiet)
    source = open_frames(args.camera, min_frames=1)
    frame = next(iter(source))
    image, size = read_microscope_image(args.microscope, pixel_um=args.pixel_um)
    found = register_images(frame, image, size, mirrored=args.mirrored)
    record = {**found.as_dict(), "camera": str(args.camera), "microscope": str(args.microscope),
              "microscope_pixel_um": size}  # fmt: skip
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        write_json(tmp / "transform.json", record)
        rows = ["camera_x,camera_y,microscope_x,microscope_y,residual_um"]
        for c, m, r in zip(found.camera_px, found.microscope_um, found.residual_um, strict=True):
            rows.append(",".join(number_cell(float(v)) for v in (*c, *m, r)))
        (tmp / "matches.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
        (tmp / "figures").mkdir()
        _registration_figure(tmp / "figures" / "registration.png", frame, image, size, found)
    t = found.transform
    say(
        f"camera to microscope: {t.scale:.5g} um/px, {t.angle_deg:.4g} deg, shift "
        f"({t.shift_um[0]:.5g}, {t.shift_um[1]:.5g}) um; {len(found.residual_um)} of "
        f"{found.n_matches} matches kept, residual {record['residual_um_rms']:.3g} um RMS"
    )
    say(f"results in {args.out} (give transform.json to multimodal strain --transform)")
    return 0


def _checkerboard(a: np.ndarray, b: np.ndarray, tiles: int = 8) -> np.ndarray:
    """Alternating square tiles of ``a`` and ``b`` (each stretched over 0-1; NaN of ``b``
    shows ``a``): features run on across the tiles' edges where the two are registered."""

    def unit(x):
        x = np.asarray(x, dtype=float)
        lo, hi = np.nanpercentile(x, [1, 99])
        return np.clip((x - lo) / max(hi - lo, 1e-12), 0, 1)

    a, b = unit(a), unit(b)
    side = max(1, max(a.shape) // tiles)
    rows, cols = np.indices(a.shape) // side
    use_b = ((rows + cols) % 2 == 1) & np.isfinite(b)
    return np.where(use_b, b, a)


def _registration_figure(path: Path, frame, image, size: float, found) -> None:
    """The microscope's image with the camera's frame drawn over it where the transform
    puts it (edges in colour), and the kept matches."""
    import cv2
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t = found.transform
    A = t.matrix / size  # camera px -> microscope px
    b = np.asarray(t.shift_um) / size
    frame = np.asarray(frame, dtype=np.float32)
    warped = cv2.warpAffine(
        frame, np.column_stack([A, b]).astype(np.float64), (image.shape[1], image.shape[0]),
        flags=cv2.INTER_LINEAR, borderValue=float("nan"),
    )  # fmt: skip
    fig = Figure(figsize=(10, 5), layout="constrained")
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2, sharex=True, sharey=True)
    left.imshow(image, cmap="gray")
    left.plot(*(found.microscope_um / size).T, "+", color="tab:orange", ms=4, mew=0.8)
    left.set_title(f"microscope: the {len(found.residual_um)} matches kept", fontsize=10)
    right.imshow(_checkerboard(image, warped), cmap="gray", vmin=0, vmax=1)
    right.set_title("tiles: microscope, and camera registered onto it", fontsize=10)
    for ax in (left, right):
        ax.set_xlabel("x (microscope px)")
    left.set_ylabel("y (microscope px)")
    fig.savefig(path, dpi=100)


def _triangles(run_dir: Path, n_points: int) -> np.ndarray:
    """The run's mesh (the first frame's rows of its strain_elements.csv), checked against its
    points."""
    from tissue_core.tables import read_number_columns

    file = run_dir / "strain_elements.csv"
    table = read_number_columns(file, ("frame", "p0", "p1", "p2"), what="elements")
    first = table[table[:, 0] == table[:, 0].min(), 1:] if len(table) else table[:, 1:]
    if not len(first) or not np.all(first == np.round(first)):
        raise InputError(f"{file}: no triangles of whole point numbers")
    triangles = first.astype(np.intp)
    if triangles.min() < 0 or triangles.max() >= n_points:
        raise InputError(f"{file}: a triangle names a point outside 0..{n_points - 1}")
    if (np.diff(np.sort(triangles, axis=1), axis=1) == 0).any():
        raise InputError(f"{file}: a triangle names one point twice")
    return triangles


def _map_files(surface) -> list[Path]:
    """The files a height map was read from: its own, or a mosaic's CSV and its tiles'."""
    tiles = getattr(surface, "tiles", [])
    return [Path(p.source) for p in [surface, *tiles] if p.source]


def _cmd_strain(args) -> int:
    from multimodal.geometry import Similarity
    from multimodal.io import read_landmarks, read_transform
    from multimodal.run import fold_strain_run, write_fold_run
    from strain2d import load_run
    from tissue_core.outputs import atomic_dir, check_writable
    from tissue_core.progress import Progress

    say = Progress(quiet=args.quiet)
    run_dir = Path(args.run)
    if (run_dir / "strain" / "strain_nodes.csv").is_file() and not (
        run_dir / "strain_nodes.csv"
    ).is_file():  # a stereo reconstruct folder: its strain run
        run_dir = run_dir / "strain"
    run = load_run(run_dir)
    stereo = run.positions.shape[-1] == 3
    if args.transform_after and not stereo:
        raise InputError("--transform-after is for a stereo run; a 2D run has one transform")
    frame = run.endpoint if args.frame is None else args.frame
    if not 0 < frame < run.n_frames:
        raise InputError(f"--frame {frame} is outside the run's frames 1..{run.n_frames - 1}")
    triangles = _triangles(run_dir, run.n_points)
    before = _named_map("--before", args.before, args.pixel_um)
    after = _named_map("--after", args.after, args.pixel_um)
    residual = None
    registration = None
    if stereo:
        run, transform, registration = _on_microscope_plane(run, frame, args)
    elif args.landmarks:
        camera, microscope = read_landmarks(args.landmarks)
        transform, residual = Similarity.from_landmarks(camera, microscope, mirrored=args.mirrored)
    else:
        transform = read_transform(args.transform)
        if args.mirrored:
            transform = Similarity(
                transform.scale, transform.angle_deg, transform.shift_um, mirrored=True
            )
    # the folders too: no output inside the run or a height map's folder
    inputs = [Path(args.run), run_dir, run_dir / "summary.json", run_dir / "strain_elements.csv"]
    inputs += [*_map_files(before), *_map_files(after)]
    inputs += [Path(m) for m in (args.before, args.after) if Path(m).is_dir()]
    given = (args.landmarks, args.transform, args.transform_after)
    inputs += [Path(p) for p in given if p and Path(p).is_file()]
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    fit = "" if residual is None else f", landmarks {np.sqrt(np.mean(residual**2)):.3g} um RMS"

    def started(message: str) -> None:  # the inputs hold: what the run is, then the long step
        how = (
            "registered in 3D (register3d)"
            if stereo
            else f"camera to microscope: {transform.scale:.4g} um/px, "
            f"{transform.angle_deg:.3g} deg{fit}"
        )
        say(
            f"{args.run}: {run.n_points} nodes, {len(triangles)} triangles; frame {frame} "
            f"against frame 0; {how}"
        )
        say(message)

    result = fold_strain_run(
        run, triangles, frame, before, after, transform, path=args.path, progress=started
    )
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        summary = write_fold_run(
            tmp, result, run=run, frame=frame, before=before, after=after,
            transform=transform, residual=residual, path=args.path,
            inputs=[p for p in inputs if p.is_file()], registration=registration,
        )  # fmt: skip
    means = summary["mean_strain"]

    def shown(value) -> str:
        return "-" if value is None else f"{value:.4f}"

    say(
        f"{summary['coverage']['on_maps']} of {len(triangles)} triangles on both height maps; "
        f"mean Exx projected {shown(means['projected']['Exx'])}, along the surface "
        f"{shown(means['fold_aware']['Exx'])} (statistics only "
        f"{shown(means['corrected']['Exx'])})"
    )
    for flag in summary["flags"]:
        say(f"flagged: {flag}")
    say(f"results in {args.out}")
    return 0


def _registration3d(path: str, option: str):
    """register3d's transform from its registration.json (or a JSON of the transform), and
    the file's record."""
    import json

    from multimodal.surface3d import Similarity3D

    if not Path(path).is_file():
        raise InputError(
            f"{option} {path}: no such file; a stereo run needs the 3D registration that "
            "multimodal register3d writes (its registration.json)"
        )
    try:
        record = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise InputError(f"{option} {path}: {exc.strerror or exc}") from None
    except (ValueError, UnicodeDecodeError, RecursionError):
        raise InputError(f"{option} {path}: not a readable JSON file") from None
    if not isinstance(record, dict):
        raise InputError(f"{option} {path}: not a JSON object")
    inner = record.get("transform", record)
    if not isinstance(inner, dict) or "rotation" not in inner:
        raise InputError(
            f"{option} {path}: a stereo run needs the 3D registration of multimodal "
            "register3d (its registration.json), not a 2D transform"
        )
    try:
        return Similarity3D.from_dict(inner), record
    except InputError as exc:
        raise InputError(f"{option} {path}: {exc}") from None


def _on_microscope_plane(run, frame: int, args):
    """A stereo run's nodes in the microscope's x-y (um): frame 0 through --transform's 3D
    registration, ``frame`` through --transform-after's (or the same); the run as a 2D one
    in micrometres, the identity as its transform, and what summary.json records."""
    from dataclasses import replace

    from multimodal.geometry import Similarity

    if args.landmarks or args.mirrored:
        raise InputError(
            "a stereo run is registered in 3D: run multimodal register3d first (with your "
            "landmarks) and give its registration.json with --transform"
        )
    first, record = _registration3d(args.transform, "--transform")
    then, record_after = first, record
    if args.transform_after:
        then, record_after = _registration3d(args.transform_after, "--transform-after")
    # a registration.json says which of the run's frames it placed the map on
    for option, rec, wanted in (
        ("--transform", record, 0),
        ("--transform-after", record_after if args.transform_after else None, frame),
    ):
        made = rec.get("frame") if isinstance(rec, dict) else None
        if isinstance(made, int) and not isinstance(made, bool) and made != wanted:
            raise InputError(
                f"{option}: its registration was made on the run's frame {made}, not "
                f"{wanted}; run register3d with --frame {wanted}"
            )
    planar = np.empty((*run.positions.shape[:2], 2))
    for k in range(run.n_frames):
        planar[k] = (then if k == frame else first).inverse(run.positions[k])[:, :2]
    registration = {
        "before": {"file": str(args.transform), "frame": 0, **first.as_dict()},
        "after": {
            "file": str(args.transform_after or args.transform),
            "frame": int(frame),
            **then.as_dict(),
        },
        "icp": {"before": record.get("icp"), "after": record_after.get("icp")},
        "note": "the stereo run's nodes in the microscope's x-y (um): 'projected' strain is "
        "that of the triangles projected on the microscope's plane"
        + (
            ""
            if args.transform_after
            else "; the --after map placed by the --before map's registration (the "
            "microscope and the cameras kept still)"
        ),
    }
    return replace(run, positions=planar), Similarity(1.0), registration


def _named_map(option: str, text: str, pixel_um: float | None):
    """The height map ``option`` names; its errors say which map."""
    from multimodal.io import read_surface_map

    try:
        return read_surface_map(text, pixel_um=pixel_um)
    except InputError as exc:
        message = str(exc)
        raise InputError(message if text in message else f"{option} {text}: {message}") from None


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    return run_command("multimodal", _build_parser(), argv)


def entry() -> None:
    """The console script ``multimodal``: like ``python -m multimodal``."""
    from tissue_core.cli import run_module

    run_module(__name__)
