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
    p.add_argument("run", help="a strain2d analyze output folder")
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
        "mirrored) or SCALE,ANGLE,SHIFT_X,SHIFT_Y",
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
    return cli


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
    run = load_run(args.run)
    if run.positions.shape[-1] != 2:
        raise InputError(
            f"{args.run}: a 3D run; give a camera run of strain2d analyze (the surface of a "
            "stereo run is not registered to a microscope yet)"
        )
    frame = run.endpoint if args.frame is None else args.frame
    if not 0 < frame < run.n_frames:
        raise InputError(f"--frame {frame} is outside the run's frames 1..{run.n_frames - 1}")
    triangles = _triangles(Path(args.run), run.n_points)
    before = _named_map("--before", args.before, args.pixel_um)
    after = _named_map("--after", args.after, args.pixel_um)
    residual = None
    if args.landmarks:
        camera, microscope = read_landmarks(args.landmarks)
        transform, residual = Similarity.from_landmarks(camera, microscope, mirrored=args.mirrored)
    else:
        transform = read_transform(args.transform)
        if args.mirrored:
            transform = Similarity(
                transform.scale, transform.angle_deg, transform.shift_um, mirrored=True
            )
    inputs = [Path(args.run) / "summary.json", Path(args.run) / "strain_elements.csv"]
    inputs += [*_map_files(before), *_map_files(after)]
    inputs += [Path(p) for p in (args.landmarks, args.transform) if p and Path(p).is_file()]
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    fit = "" if residual is None else f", landmarks {np.sqrt(np.mean(residual**2)):.3g} um RMS"

    def started(message: str) -> None:  # the inputs hold: what the run is, then the long step
        say(
            f"{args.run}: {run.n_points} nodes, {len(triangles)} triangles; frame {frame} "
            f"against frame 0; camera to microscope: {transform.scale:.4g} um/px, "
            f"{transform.angle_deg:.3g} deg{fit}"
        )
        say(message)

    result = fold_strain_run(
        run, triangles, frame, before, after, transform, path=args.path, progress=started
    )
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        summary = write_fold_run(
            tmp, result, run=run, frame=frame, before=before, after=after,
            transform=transform, residual=residual, path=args.path,
            inputs=[p for p in inputs if p.is_file()],
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
