"""Make the pictures the README shows (run after ``make demo``).

    python docs/make_figures.py

Writes docs/images/: the demo's tracked grid and strain maps (from
demo_output/), the same video analyzed in a tissue mask (docs/masks.md),
the four synthetic benchmark cases, a 3D membrane-strain example computed
by surface_strain, and dic's strain-error maps on two heterogeneous fields
with a coarse and a fine grid; and the mpm3d demo's height map, 3D surface,
fold profiles and before/after comparison; and a screenshot of the top of
every package's report.html, taken in headless Chromium
(``tests/report_browser.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from sample_data_synth import CASES, make_case
from surface_strain import compute_strain, delaunay_triangles, nodal_scalars

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"


def demo_figures() -> None:
    """The demo run's figures again, at a resolution fit for the README."""
    from strain2d import open_frames, read_tracks, strain_from_tracks
    from strain2d.figures import plot_strain_maps, plot_tracked_grid

    run = ROOT / "demo_output" / "equibiaxial"
    if not run.is_dir():
        raise SystemExit("run `make demo` first")
    source = open_frames(ROOT / "demo_output" / "data" / "equibiaxial.avi")
    tracks = read_tracks(run / "tracks.csv")
    field = strain_from_tracks(tracks, grid_shape=(7, 7))
    last = tracks.n_frames - 1
    first_img, last_img = source.first(), source.frame(last)
    plot_tracked_grid(
        OUT / "demo_tracked_grid.png", first_img, last_img, tracks, field.triangles, dpi=60
    )
    plot_strain_maps(OUT / "demo_strain_maps.png", last_img, field, last, dpi=60)


def synthetic_cases() -> None:
    fig = Figure(figsize=(3 * len(CASES), 6.2), layout="constrained")
    axes = fig.subplots(2, len(CASES))
    for col, case in enumerate(CASES):
        video = make_case(case, size=400, n_frames=11, rng=0)
        grid = video.truth.grid((7, 7))
        for row, k in enumerate((0, 10)):
            ax = axes[row, col]
            ax.imshow(video.frames[k], cmap="gray", vmin=0, vmax=255)
            pos = video.truth.positions(grid, k)
            ax.plot(pos[:, 0], pos[:, 1], "o", ms=3, mfc="#ffd000", mec="k", mew=0.4)
            ax.set_title(f"{case}, frame {k}", fontsize=10)
            ax.set_xlabel("x (px)")
            ax.set_ylabel("y (px)")
    fig.savefig(OUT / "synthetic_cases.png", dpi=80)


def membrane_3d() -> None:
    """A flat sheet rolled onto a cylinder (no stretch) while stretched 1.2 along its axis."""
    u, v = np.meshgrid(np.linspace(0, 1, 15), np.linspace(0, 1, 15))
    ref = np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)]) * [3.0, 2.0, 0.0]
    tri = delaunay_triangles(ref)
    radius = 1.5
    angle = ref[:, 0] / radius
    cur = np.column_stack([radius * np.sin(angle), 1.2 * ref[:, 1], radius * (1 - np.cos(angle))])
    field = compute_strain(ref, np.stack([ref, cur]), tri)
    eyy = nodal_scalars(field)["Eyy"][1]
    exx = nodal_scalars(field)["Exx"][1]
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    for i, (values, name) in enumerate(
        ((exx, "E_xx (around the roll)"), (eyy, "E_yy (along the axis)"))
    ):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        surf = ax.plot_trisurf(
            cur[:, 0],
            cur[:, 1],
            cur[:, 2],
            triangles=tri,
            cmap="viridis",
            vmin=-0.01,
            vmax=0.23,
            linewidth=0.2,
            edgecolor="k",
        )
        surf.set_array(values[tri].mean(axis=1))
        ax.set_title(f"{name}: {values.mean():.4f}", fontsize=10)
        ax.set_xlabel("X (mm)")
        ax.set_ylabel("Y (mm)")
        ax.set_zlabel("Z (mm)")
        fig.colorbar(surf, ax=ax, shrink=0.6, label="Green-Lagrange strain (-)")
    fig.savefig(OUT / "surface_strain_3d.png", dpi=80)


def error_figures() -> None:
    """dic's nodal strain error on two heterogeneous fields, 7x7 and 21x21 grids."""
    from strain2d import strain_from_tracks, track
    from strain2d.figures import plot_strain_errors

    for case in ("gaussian", "fold"):
        video = make_case(case, size=800, n_frames=31, rng=0)
        for n in (7, 21):
            points = video.truth.grid((n, n))
            tracks = track(video.frames, points, tracker="dic")
            field = strain_from_tracks(tracks, grid_shape=(n, n))
            err = field.nodal_E[-1] - video.truth.strain(points, 30)
            plot_strain_errors(
                OUT / f"errors_{case}_{n}x{n}.png",
                video.frames[-1],
                field,
                30,
                err,
                title=f"{case}, dic, {n}x{n} grid: nodal strain error on the last frame",
                dpi=55,
            )


def mpm3d_figures() -> None:
    """The mpm3d and stereo demos' figures (``make demo`` writes them), shrunk for the README."""
    from PIL import Image

    runs = {
        "mpm3d_heightmap.png": ROOT / "demo_output" / "mpm3d_after" / "figures" / "heightmap.png",
        "mpm3d_surface3d.png": ROOT / "demo_output" / "mpm3d_after" / "figures" / "surface3d.png",
        "mpm3d_profiles.png": ROOT / "demo_output" / "mpm3d_after" / "figures" / "profiles.png",
        "stereo_views.png": ROOT / "demo_output" / "stereo_dome" / "figures" / "views.png",
        "strain3d_dome.png": ROOT
        / "demo_output"
        / "stereo_dome"
        / "strain"
        / "figures"
        / "E2_frame0010.png",
        "stereo_points3d.png": ROOT / "demo_output" / "stereo_dome" / "figures" / "points3d.png",
        "mpm3d_compare.png": ROOT
        / "demo_output"
        / "mpm3d_compare"
        / "figures"
        / "compare_heightmaps.png",
    }
    for name, path in runs.items():
        if not path.is_file():
            raise SystemExit("run `make demo` first")
        image = Image.open(path).convert("RGB")
        image.thumbnail((760, 760))
        image.save(OUT / name, optimize=True)


def report_figures() -> None:
    """The demo study's figures: one specimen's run figures and the study's, shrunk."""
    from PIL import Image

    run = ROOT / "demo_output" / "study_batch" / "runs" / "S01" / "figures"
    study = ROOT / "demo_output" / "study_batch" / "study" / "figures"
    files = {
        "run_maps_endpoint.png": next(iter(sorted(run.glob("strain_frame*.png"))), None),
        "run_crosses.png": next(iter(sorted(run.glob("principal_directions_frame*.png"))), None),
        "run_curves.png": run / "strain_curves.png",
        "run_violins.png": next(iter(sorted(run.glob("violins_frame*.png"))), None),
        "study_curves.png": study / "study_curves.png",
        "study_violins.png": study / "study_violins.png",
        "study_means.png": study / "specimen_means.png",
    }
    for name, path in files.items():
        if path is None or not path.is_file():
            raise SystemExit("run `make demo` first")
        image = Image.open(path).convert("RGB")
        image.thumbnail((1000, 1000) if name.startswith("study_") else (760, 760))
        image.save(OUT / name, optimize=True)
    # one frame of the animation, halfway through the contraction
    import cv2

    video = cv2.VideoCapture(str(run / "strain_animation.mp4"))
    try:
        n = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
        video.set(cv2.CAP_PROP_POS_FRAMES, n // 3)
        ok, frame = video.read()
    finally:
        video.release()
    if not ok:
        raise SystemExit("cannot read the demo's strain_animation.mp4")
    image = Image.fromarray(frame[..., ::-1])
    image.thumbnail((760, 760))
    image.save(OUT / "run_animation_frame.png", optimize=True)


def report_screenshots() -> None:
    """The top of each demo report.html as the browser shows it (1100 px wide), shrunk."""
    import sys

    from PIL import Image

    sys.path.insert(0, str(ROOT))
    from tests.report_browser import screenshot

    demo = ROOT / "demo_output"
    reports = {
        "report_strain2d.png": demo / "equibiaxial" / "report.html",
        "report_study.png": demo / "study_batch" / "study" / "report.html",
        "report_mpm3d.png": demo / "mpm3d_after" / "report.html",
        "report_mpm3d_compare.png": demo / "mpm3d_compare" / "report.html",
        "report_stereo.png": demo / "stereo_dome" / "report.html",
        "report_surface_strain.png": demo / "stereo_dome" / "strain" / "report.html",
    }
    for name, path in reports.items():
        if not path.is_file():
            raise SystemExit(f"run `make demo` first ({path} is missing)")
        shot = screenshot(path, OUT / name, size=(1100, 1500))
        image = Image.open(shot).convert("RGB")
        image.thumbnail((640, 900))
        image.save(shot, optimize=True)


#: the tissue outline of docs/masks.md (x,y px on the demo's video)
MASK_OUTLINE = (
    "x,y\n230,260\n400,205\n575,250\n600,420\n560,585\n420,560\n330,600\n215,520\n260,400\n"
)


def mask_figure() -> None:
    """docs/masks.md's worked example: the demo's video analyzed in a polygon mask; its
    tracked-grid figure, with the mask's outline."""
    import shutil
    import tempfile

    from strain2d.cli import main

    video = ROOT / "demo_output" / "data" / "equibiaxial.avi"
    if not video.is_file():
        raise SystemExit("run `make demo` first")
    with tempfile.TemporaryDirectory() as tmp:
        outline = Path(tmp) / "outline.csv"
        outline.write_text(MASK_OUTLINE)
        argv = ["-q", "analyze", str(video), "--mask", str(outline), "--grid", "11x11",
                "--fps", "10", "--scale", "0.012mm/px", "--animation", "none",
                "--out", str(Path(tmp) / "masked")]  # fmt: skip
        if main(argv) != 0:
            raise SystemExit("the masked run failed")
        shutil.copy(Path(tmp) / "masked" / "figures" / "tracked_grid.png",
                    OUT / "mask_tracked_grid.png")  # fmt: skip


def register3d_figures() -> None:
    """docs/multimodal.md's 3D registration: a microscope patch of the demo's dome onto its
    stereo run; the height map above the camera's surface, and both surfaces in one scene."""
    import shutil
    import tempfile

    import pyvista as pv

    from multimodal.cli import main as multimodal
    from sample_data_synth.cli import main as synth

    scene, run = (
        ROOT / "demo_output" / "stereo_scene" / "dome",
        ROOT / "demo_output" / "stereo_dome",
    )
    if not (scene.is_dir() and run.is_dir()):
        raise SystemExit("run `make demo` first")
    with tempfile.TemporaryDirectory() as tmp:
        patch, out = Path(tmp) / "patch", Path(tmp) / "reg"
        if synth(["-q", "patch", str(scene), "--out", str(patch)]) != 0:
            raise SystemExit("sample_data_synth patch failed")
        argv = ["-q", "register3d", str(run), str(patch / "heightmap.tif"), "--landmarks",
                str(patch / "landmarks3d.csv"), "--out", str(out)]  # fmt: skip
        if multimodal(argv) != 0:
            raise SystemExit("multimodal register3d failed")
        shutil.copy(out / "figures" / "registration3d.png", OUT / "register3d_heights.png")
        camera = pv.read(out / "camera_surface.vtp")
        micro = pv.read(out / "microscope_surface.vtp")
        plotter = pv.Plotter(off_screen=True, window_size=[900, 600])
        plotter.set_background("white")
        plotter.add_mesh(camera, style="wireframe", color="dimgray", line_width=1.5)
        plotter.add_points(camera.points, color="black", point_size=8)
        micro.point_data["above_um"] = 1000 * micro.point_data["above_camera_surface"]
        top = float(np.nanmax(np.abs(micro.point_data["above_um"])))
        plotter.add_mesh(
            micro, scalars="above_um", cmap="RdBu_r", clim=(-top, top),
            scalar_bar_args={"title": "height above the stereo surface (um)", "color": "black"},
        )  # fmt: skip
        centre = np.asarray(micro.center)
        plotter.camera.focal_point = centre
        plotter.camera.position = centre * (1 - 12.0 / np.linalg.norm(centre))  # the cameras'
        plotter.camera.azimuth = 20
        plotter.camera.up = (0.0, -1.0, 0.0)
        plotter.screenshot(OUT / "register3d_scene.png", transparent_background=False)
        plotter.close()


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    register3d_figures()
    demo_figures()
    mask_figure()
    synthetic_cases()
    membrane_3d()
    error_figures()
    mpm3d_figures()
    report_figures()
    report_screenshots()
    print(f"figures written to {OUT}")
