"""Synthetic specimens for a multi-specimen study with known anisotropy.

Each specimen is a video of tissue that contracts and then holds still, as in
the source paper's bladder strips: the deformation is a
:class:`~sample_data_synth.deformations.Contraction` (stretch ``lx`` along x,
the longitudinal direction, and ``ly`` along y, the circumferential one, about
the frame centre, plus a smooth heterogeneity so nodal strains vary over the
specimen) driven by a :class:`~sample_data_synth.deformations.RampHold` time
course (a smoothstep ramp from frame 0 to the contraction ``endpoint``, then
constant positions to the last frame).

:func:`make_specimen` renders one specimen with its ground truth;
:func:`make_study` writes a whole study (default :data:`DEFAULT_DESIGN`: an
"anisotropic" group whose longitudinal contraction is stronger than its
circumferential one and an "isotropic" group without a difference, four
specimens each) with a ``manifest.csv`` and a ``study_truth.json`` holding the
exact answers the study statistics must recover.

Heterogeneity of amplitude ``h`` (dimensionless strain):

* a Gaussian local contraction (:class:`~sample_data_synth.deformations.Field`
  ``gaussian``, ``a = h``, ``s = 0.2 L``) centred at a random point of the
  central 60 % of the region of interest (side ``L``): ``F = A - h I`` at its
  centre;
* a sinusoidal field (``sinusoid``, wavelength ``L``, displacement gradient
  amplitude ``h / 2``) with random phases: Exx oscillates along x and Eyy
  along y.

Truth at the grid nodes comes two ways: the continuum strain of the analytic
map at each node, and the value a perfect tracker would give through the
pipeline (constant-strain triangles on the grid with alternating diagonals,
area-weighted nodal averages; :func:`grid_nodal_strain`), which is what
``strain2d analyze`` reports and the number to compare tracked results with.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from sample_data_synth._common import Rng, non_negative, positive, spawn, version
from sample_data_synth.cases import (
    GroundTruth,
    SyntheticVideo,
    _reference_bounds,
    write_video,
)
from sample_data_synth.deformations import Contraction, Field, RampHold, green_lagrange
from sample_data_synth.render import add_sensor_noise, render_image, render_speckle
from sample_data_synth.speckle import speckle_pattern
from tissue_core.csvtext import csv_writer
from tissue_core.jsonio import write_json

__all__ = [
    "DEFAULT_DESIGN",
    "Group",
    "grid_nodal_strain",
    "make_specimen",
    "make_study",
    "specimen_roi",
]

Texture = Literal["tissue", "speckle"]
Ramp = Literal["smoothstep", "linear"]

#: fraction of the frame the grid region spans, centred
ROI_FRACTION = 0.6
#: distance in pixels the grid keeps from the frame edge on every frame (a 31 px
#: DIC subset plus room)
EDGE_MARGIN_PX = 20.0

#: manifest.csv names of the truth columns
_MANIFEST_NAMES = {"lx": "true_lx", "ly": "true_ly", "endpoint": "true_endpoint"}

NO_DIFFERENCE = "no difference"
DIFFERENCE = "Exx differs from Eyy"


@dataclass(frozen=True)
class Group:
    """One group of a study design.

    Attributes
    ----------
    name : str
    n : int
        Number of specimens.
    lx, ly : float
        Population means of the final stretches along x (longitudinal) and y
        (circumferential); ``lx < ly`` means the longitudinal contraction is
        stronger.
    sd : float
        Specimen-to-specimen standard deviation of ``lx`` and of ``ly``
        (drawn independently).
    """

    name: str
    n: int
    lx: float
    ly: float
    sd: float = 0.015

    def __post_init__(self) -> None:
        if not self.name or any(c in self.name for c in ',/\\"\n'):
            raise ValueError(
                f"group name must be non-empty, without , / \\ or quotes: {self.name!r}"
            )
        if isinstance(self.n, bool) or int(self.n) != self.n or self.n < 1:
            raise ValueError(f"group {self.name}: n must be an integer >= 1, got {self.n!r}")
        positive(self.lx, f"group {self.name}: lx")
        positive(self.ly, f"group {self.name}: ly")
        non_negative(self.sd, f"group {self.name}: sd")

    @property
    def expected(self) -> str:
        """The verdict a specimen-level test should reach on this group."""
        return NO_DIFFERENCE if self.lx == self.ly else DIFFERENCE


#: two groups of four: longitudinal contraction stronger than circumferential
#: (Exx about -0.18 against Eyy about -0.077), and equal on average (about -0.13)
DEFAULT_DESIGN: tuple[Group, ...] = (
    Group("anisotropic", 4, lx=0.80, ly=0.92, sd=0.015),
    Group("isotropic", 4, lx=0.86, ly=0.86, sd=0.015),
)


def specimen_roi(size: int) -> tuple[float, float, float, float]:
    """The grid region ``(x0, y0, x1, y1)`` of a ``size x size`` specimen: the central
    :data:`ROI_FRACTION` of the frame, on whole pixels."""
    half = ROI_FRACTION / 2 * (size - 1)
    c = (size - 1) / 2
    lo, hi = float(math.ceil(c - half)), float(math.floor(c + half))
    return (lo, lo, hi, hi)


def _heterogeneity_fields(
    center: np.ndarray, roi: tuple[float, ...], amplitude: float, rng: np.random.Generator
) -> tuple[Field, ...]:
    if amplitude == 0:
        return ()
    x0, y0, x1, y1 = roi
    span = min(x1 - x0, y1 - y0)
    bump = center + rng.uniform(-0.3, 0.3, 2) * span
    phase = center + rng.uniform(0.0, span, 2)  # shifting the centre shifts the phase
    return (
        Field("gaussian", tuple(bump), a=amplitude, s=0.2 * span),
        Field(
            "sinusoid",
            tuple(phase),
            amplitude=amplitude / 2 * span / (2 * np.pi),
            wavelength=span,
        ),
    )


class _Offset:
    """A deformation whose reference coordinates are shifted by ``offset`` (photo pixels)."""

    def __init__(self, deformation, offset: np.ndarray) -> None:
        self.deformation, self.offset = deformation, offset

    def inverse(self, x: np.ndarray, t: float) -> np.ndarray:
        return self.deformation.inverse(x, t) + self.offset


def _grid_triangles(n_rows: int, n_cols: int) -> np.ndarray:
    """Alternating diagonals, as ``surface_strain.grid_triangles`` (strain2d's grid mesh)."""
    r, c = np.meshgrid(np.arange(n_rows - 1), np.arange(n_cols - 1), indexing="ij")
    r, c = r.ravel(), c.ravel()
    a = r * n_cols + c
    b, d, e = a + 1, a + n_cols, a + n_cols + 1
    alt = (r + c) % 2 == 1
    t1 = np.where(alt[:, None], np.stack([a, b, d], 1), np.stack([a, b, e], 1))
    t2 = np.where(alt[:, None], np.stack([b, e, d], 1), np.stack([a, e, d], 1))
    return np.concatenate([t1, t2])


def grid_nodal_strain(
    truth: GroundTruth, frame: int | None = None, *, shape: tuple[int, int] = (7, 7)
) -> np.ndarray:
    """Nodal Green-Lagrange strain a perfect tracker gives on the truth's grid.

    The grid (``truth.grid(shape)``, row-major) is meshed with alternating
    diagonals; each triangle's ``F = [d1 d2] [D1 D2]^-1`` comes from the exact
    positions and ``E = (F^T F - I) / 2``; a node's value is the
    area-weighted mean of its triangles (as ``strain2d analyze`` computes it).

    Parameters
    ----------
    truth : GroundTruth
    frame : int, optional
        One frame; all frames when None.
    shape : (n_cols, n_rows), keyword-only

    Returns
    -------
    E : (N, 2, 2) float, or (T, N, 2, 2) when ``frame`` is None
    """
    n_cols, n_rows = shape
    if n_cols < 2 or n_rows < 2:
        raise ValueError(f"shape needs at least 2 points per side, got {shape}")
    ref = truth.grid(shape)
    cur = truth.positions(ref, frame)
    tri = _grid_triangles(n_rows, n_cols)
    G = np.swapaxes(ref[tri[:, 1:]] - ref[tri[:, :1]], -1, -2)  # (M, 2, 2), edges as columns
    g = np.swapaxes(cur[..., tri[:, 1:], :] - cur[..., tri[:, :1], :], -1, -2)
    E = green_lagrange(g @ np.linalg.inv(G))  # (..., M, 2, 2)
    area = 0.5 * np.abs(np.linalg.det(G))
    incidence = np.zeros((len(ref), len(tri)))  # area of triangle m at its corner n
    for k in range(3):
        incidence[tri[:, k], np.arange(len(tri))] = area
    incidence /= incidence.sum(axis=1, keepdims=True)
    return np.einsum("nm,...mij->...nij", incidence, E)


def make_specimen(
    lx: float,
    ly: float,
    *,
    heterogeneity: float = 0.04,
    endpoint: int | None = None,
    n_frames: int = 25,
    size: int = 352,
    texture: Texture = "tissue",
    ramp: Ramp = "smoothstep",
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    name: str = "specimen",
    rng: Rng = None,
    progress: Callable[[int, int], None] | None = None,
) -> SyntheticVideo:
    """Render one contracting specimen with its ground truth.

    Parameters
    ----------
    lx, ly : float
        Final homogeneous stretches along x (longitudinal) and y
        (circumferential) about the frame centre; 0.8 is 20 % shortening.
    heterogeneity : float, keyword-only
        Amplitude ``h`` of the superposed smooth field (see the module
        docstring), in [0, 0.2]; 0 gives a homogeneous specimen.
    endpoint : int, keyword-only
        Frame where the contraction stops (1 to ``n_frames - 1``); default
        65 % of the way.
    n_frames : int, keyword-only
        Frames including the reference (>= 3).
    size : int, keyword-only
        Frame width and height in pixels (>= 64).
    texture : {"tissue", "speckle"}, keyword-only
        A tissue photograph (scikit-image's ``ihc.png``, each specimen a
        randomly placed, flipped and rotated crop) or an analytic speckle
        pattern.
    ramp : {"smoothstep", "linear"}, keyword-only
        Time course up to the endpoint (:class:`RampHold`).
    read_noise, shot_gain : float, keyword-only
        Sensor noise (:func:`sample_data_synth.render.add_sensor_noise`).
    name : str, keyword-only
        The truth's ``case`` name.
    rng : int or Generator, keyword-only
        Seed of the heterogeneity's phases, the pattern and the noise.
    progress : callable(done, total), keyword-only
        Called after each frame.

    Returns
    -------
    SyntheticVideo
        Frames ``(n_frames, size, size)`` uint8; the truth's ``roi`` is the
        grid region (:func:`specimen_roi`), its ``time_profile`` the ramp.

    Raises
    ------
    ValueError
        On a bad argument, or when the grid would come closer than
        :data:`EDGE_MARGIN_PX` (or, on small frames, than it starts) to the
        frame edge on some frame.
    """
    lx, ly = positive(lx, "lx"), positive(ly, "ly")
    heterogeneity = non_negative(heterogeneity, "heterogeneity")
    if heterogeneity > 0.2:
        raise ValueError(f"heterogeneity must be <= 0.2, got {heterogeneity}")
    if isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 3:
        raise ValueError(f"n_frames must be an integer >= 3, got {n_frames!r}")
    if isinstance(size, bool) or int(size) != size or size < 64:
        raise ValueError(f"size must be an integer >= 64 px, got {size!r}")
    n_frames, size = int(n_frames), int(size)
    if endpoint is None:
        endpoint = max(1, round(0.65 * (n_frames - 1)))
    if isinstance(endpoint, bool) or int(endpoint) != endpoint or not 1 <= endpoint < n_frames:
        raise ValueError(f"endpoint must be a frame from 1 to {n_frames - 1}, got {endpoint!r}")
    if texture not in ("tissue", "speckle"):
        raise ValueError(f"texture must be tissue or speckle, got {texture!r}")
    read_noise = non_negative(read_noise, "read_noise")
    shot_gain = non_negative(shot_gain, "shot_gain")
    profile = RampHold(int(endpoint), ramp=ramp)

    shape = (size, size)
    center = np.full(2, (size - 1) / 2)
    roi = specimen_roi(size)
    het_rng, pattern_rng, noise_rng = spawn(rng, 3)
    fields = _heterogeneity_fields(center, roi, heterogeneity, het_rng)
    deformation = Contraction(tuple(center), lx=lx, ly=ly, fields=fields)
    params: dict = {
        "description": f"contraction lx = {lx:g}, ly = {ly:g} with heterogeneity "
        f"{heterogeneity:g}, stopping at frame {profile.endpoint}",
        "texture": texture,
        "seed": rng if isinstance(rng, int) else None,
        "lx": lx,
        "ly": ly,
        "heterogeneity": heterogeneity,
        "endpoint": profile.endpoint,
        "ramp": ramp,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
    }
    truth = GroundTruth(name, deformation, n_frames, shape, roi, params, time_profile=profile)

    grid = truth.grid((7, 7))
    margin = min(EDGE_MARGIN_PX, roi[0])  # small test frames start closer
    times = sorted({truth.time(k) for k in range(n_frames)})
    for t in times:
        if np.linalg.det(deformation.gradient(grid, t)).min() <= 0:
            raise ValueError("the heterogeneity folds the tissue over itself; lower it")
        x = deformation.forward(grid, t)
        if x.min() < margin or x.max() > size - 1 - margin:
            raise ValueError(
                f"the grid comes closer than {margin:g} px to the frame edge; "
                "use stretches nearer 1 or a larger size"
            )

    if texture == "speckle":
        bounds = _reference_bounds(deformation, shape, times, margin=12.0)
        pattern = speckle_pattern(bounds, radius=2.0, density=1.0, contrast=0.8, rng=pattern_rng)
        params.update(speckle_radius=2.0, speckle_density=1.0, speckle_contrast=0.8, psf_sigma=0.5)

        def render(t: float) -> np.ndarray:
            return render_speckle(pattern, deformation, t, shape)
    else:
        from scipy import ndimage

        from sample_data_synth.texture import tissue_photograph

        x0, y0, x1, y1 = _reference_bounds(deformation, shape, times, margin=4.0)
        extent = max(x1 - x0, y1 - y0)
        side = math.ceil(extent) + 1 + round(0.25 * size)
        photo = tissue_photograph(side)
        turns, flip = int(pattern_rng.integers(4)), bool(pattern_rng.integers(2))
        photo = np.rot90(photo[:, ::-1] if flip else photo, turns)
        offset = np.array(
            [pattern_rng.uniform(-lo, side - 1 - hi) for lo, hi in ((x0, x1), (y0, y1))]
        )
        coefficients = ndimage.spline_filter(np.ascontiguousarray(photo), order=3, mode="mirror")
        shifted = _Offset(deformation, offset)
        params.update(
            photograph="scikit-image ihc.png, gray, resized",
            photograph_side_px=side,
            photograph_flip=flip,
            photograph_quarter_turns=turns,
            photograph_offset_px=offset.tolist(),
            interpolation="cubic B-spline",
        )

        def render(t: float) -> np.ndarray:
            return render_image(coefficients, shifted, t, shape)

    frames = np.empty((n_frames, size, size), dtype=np.uint8)
    clean: dict[float, np.ndarray] = {}
    for k in range(n_frames):
        t = truth.time(k)
        if t not in clean:  # the held frames share one noise-free image
            clean = {t: render(t)}
        frames[k] = add_sensor_noise(
            clean[t], read_noise=read_noise, shot_gain=shot_gain, rng=noise_rng
        )
        if progress:
            progress(k + 1, n_frames)
    return SyntheticVideo(frames, truth)


def _endpoint_summary(truth: GroundTruth, shape: tuple[int, int]) -> dict:
    endpoint = truth.time_profile.endpoint
    nodal = grid_nodal_strain(truth, shape=shape)  # (T, N, 2, 2)
    continuum = truth.strain(truth.grid(shape), endpoint)
    at_end = nodal[endpoint]
    return {
        "Exx": float(at_end[:, 0, 0].mean()),
        "Eyy": float(at_end[:, 1, 1].mean()),
        "Exy": float(at_end[:, 0, 1].mean()),
        "Exx_sd": float(at_end[:, 0, 0].std()),
        "Eyy_sd": float(at_end[:, 1, 1].std()),
        "Exx_continuum": float(continuum[:, 0, 0].mean()),
        "Eyy_continuum": float(continuum[:, 1, 1].mean()),
        "Exy_continuum": float(continuum[:, 0, 1].mean()),
        "curve": {
            "Exx": nodal[:, :, 0, 0].mean(axis=1).tolist(),
            "Eyy": nodal[:, :, 1, 1].mean(axis=1).tolist(),
        },
    }


def _group_summary(group: Group, specimens: list[dict]) -> dict:
    from scipy import stats

    exx = np.array([s["Exx"] for s in specimens])
    eyy = np.array([s["Eyy"] for s in specimens])
    diff = exx - eyy
    out = {
        "n": group.n,
        "design": {"lx": group.lx, "ly": group.ly, "sd": group.sd},
        "expected": group.expected,
        "expected_direction": (
            None if group.lx == group.ly else ("Exx < Eyy" if group.lx < group.ly else "Exx > Eyy")
        ),
        "specimens": [s["specimen"] for s in specimens],
        "Exx_mean": float(exx.mean()),
        "Eyy_mean": float(eyy.mean()),
        "difference_mean": float(diff.mean()),
        "difference_sd": float(diff.std(ddof=1)) if len(diff) > 1 else None,
        "exact_paired_t": None,
    }
    if len(diff) > 1 and diff.std() > 0:
        res = stats.ttest_rel(exx, eyy)
        out["exact_paired_t"] = {"t": float(res.statistic), "p": float(res.pvalue)}
    return out


def make_study(
    out_dir: str | os.PathLike,
    *,
    design: Sequence[Group] = DEFAULT_DESIGN,
    size: int = 352,
    n_frames: int = 25,
    heterogeneity: float = 0.04,
    texture: Texture = "tissue",
    endpoint_range: tuple[float, float] = (0.55, 0.75),
    rng: int | None = 0,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Write a multi-specimen study with known anisotropy into ``out_dir``.

    Specimens are named ``S01``, ``S02``, ... through the groups in order.
    Each draws ``lx ~ N(group.lx, group.sd)`` and ``ly ~ N(group.ly,
    group.sd)`` independently (rounded to 4 decimals), an endpoint uniformly
    among the frames between ``endpoint_range`` fractions of the video, and
    its own seed (pattern, noise, heterogeneity phases).

    Files written (paths in the tables are relative to ``out_dir``):

    * ``SNN.avi`` (lossless FFV1), ``SNN_truth.json``
      (:func:`sample_data_synth.load_ground_truth`) and ``SNN_truth.npz``
      (the 7 x 7 grid: ``grid`` (N, 2), ``positions`` (T, N, 2), ``F`` and
      ``E`` (T, N, 2, 2) continuum values, ``E_nodal`` (T, N, 2, 2) as
      :func:`grid_nodal_strain`);
    * ``manifest.csv``: ``run,specimen,group,video,truth,true_lx,true_ly,true_endpoint,roi``
      with ``run`` = ``runs/SNN`` (the folder to give ``strain2d analyze
      --out``; ``runs/`` is created empty) and ``roi`` = ``"x0,y0,x1,y1"``
      (for ``--roi``);
    * ``study_truth.json``: per specimen the exact mean nodal Exx, Eyy, Exy
      at the endpoint over the 7 x 7 grid (``Exx`` ... from
      :func:`grid_nodal_strain`, ``Exx_continuum`` ... from the analytic
      field at the nodes), their spatial SD over the nodes (ddof 0) and the
      mean curves over all frames; per group the means, the expected verdict
      (``"Exx differs from Eyy"`` or ``"no difference"``) and the paired
      t-test on the exact specimen means.

    Parameters
    ----------
    out_dir : path
        Created if missing; files in it are replaced.
    design : sequence of Group, keyword-only
    size, n_frames, heterogeneity, texture : keyword-only
        As :func:`make_specimen` (small values make tiny studies for tests).
    endpoint_range : (lo, hi), keyword-only
        Fractions of ``n_frames - 1`` between which the endpoints fall.
    rng : int, keyword-only
        Seed of the whole study.
    progress : callable(done, total), keyword-only
        Called after each frame of each specimen (total = specimens x frames).

    Returns
    -------
    dict
        The content of ``study_truth.json``.
    """
    design = tuple(design)
    if not design or not all(isinstance(g, Group) for g in design):
        raise ValueError("design must be a non-empty sequence of Group")
    names = [g.name for g in design]
    if len(set(names)) != len(names):
        raise ValueError(f"group names must be unique, got {names}")
    lo, hi = (float(v) for v in endpoint_range)
    if not 0 < lo <= hi < 1:
        raise ValueError(f"endpoint_range must satisfy 0 < lo <= hi < 1, got {endpoint_range}")
    if isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 3:
        raise ValueError(f"n_frames must be an integer >= 3, got {n_frames!r}")
    first, last = max(1, round(lo * (n_frames - 1))), min(n_frames - 2, round(hi * (n_frames - 1)))
    if first > last:
        raise ValueError(f"n_frames = {n_frames} leaves no endpoint in {endpoint_range}")
    if isinstance(size, bool) or int(size) != size or size < 64:
        raise ValueError(f"size must be an integer >= 64 px, got {size!r}")
    out = Path(out_dir)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    roi = specimen_roi(size)
    roi_text = ",".join(f"{v:g}" for v in roi)
    shape = (7, 7)

    seq = np.random.SeedSequence(rng)
    draw = np.random.default_rng(seq.spawn(1)[0])
    n_total = sum(g.n for g in design)
    plan = []
    for g in design:
        for _ in range(g.n):
            plan.append(
                {
                    "group": g,
                    "lx": round(float(draw.normal(g.lx, g.sd)), 4),
                    "ly": round(float(draw.normal(g.ly, g.sd)), 4),
                    "endpoint": int(draw.integers(first, last + 1)),
                    "seed": int(draw.integers(2**31)),
                }
            )
    width = max(2, len(str(n_total)))
    rows, specimens = [], []
    for i, p in enumerate(plan):
        name = f"S{i + 1:0{width}d}"

        def step(done: int, total: int, i: int = i) -> None:
            if progress:
                progress(i * n_frames + done, n_total * n_frames)

        video = make_specimen(
            p["lx"],
            p["ly"],
            heterogeneity=heterogeneity,
            endpoint=p["endpoint"],
            n_frames=n_frames,
            size=size,
            texture=texture,
            name=name,
            rng=p["seed"],
            progress=step,
        )
        truth = video.truth
        write_video(video.frames, out / f"{name}.avi")
        truth.save(out / f"{name}_truth.json")
        grid = truth.grid(shape)
        np.savez_compressed(
            out / f"{name}_truth.npz",
            grid=grid,
            positions=truth.positions(grid),
            F=np.stack([truth.gradient(grid, k) for k in range(n_frames)]),
            E=np.stack([truth.strain(grid, k) for k in range(n_frames)]),
            E_nodal=grid_nodal_strain(truth, shape=shape),
        )
        row = {
            "run": f"runs/{name}",
            "specimen": name,
            "group": p["group"].name,
            "video": f"{name}.avi",
            "truth": f"{name}_truth.json",
            "lx": p["lx"],
            "ly": p["ly"],
            "endpoint": p["endpoint"],
            "roi": roi_text,
        }
        rows.append(row)
        specimens.append({**row, "seed": p["seed"], **_endpoint_summary(truth, shape)})

    # the truth columns carry a true_ prefix: a study manifest's "endpoint" column
    # overrides the run's detected endpoint (strain2d study), which would hide detection
    manifest = [{_MANIFEST_NAMES.get(k, k): v for k, v in r.items()} for r in rows]
    with open(out / "manifest.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv_writer(f)  # group names may be anything: written inert for spreadsheets
        writer.writerow(list(manifest[0]))
        writer.writerows(list(r.values()) for r in manifest)

    result = {
        "description": "synthetic contraction study with known anisotropy: exact mean nodal "
        "strains at each specimen's contraction endpoint and the expected verdict per group",
        "software": {"sample_data_synth": version()},
        "seed": rng,
        "manifest": "manifest.csv",
        "analyze": "in this folder, for each row of manifest.csv: "
        "python -m strain2d analyze VIDEO --grid 7x7 --roi ROI --out RUN",
        "grid": "7x7",
        "roi": list(roi),
        "strain": "Green-Lagrange; Exx longitudinal (x, columns), Eyy circumferential (y, rows)",
        "nodal": "Exx, Eyy, Exy: constant-strain triangles on the grid (alternating diagonals) "
        "from the exact positions, area-weighted at the nodes, as strain2d analyze computes "
        "them; *_continuum: the analytic field at the nodes; *_sd: spatial SD over the nodes "
        "(ddof 0); curve: mean nodal Exx and Eyy on every frame",
        "design": {
            "groups": [
                {"name": g.name, "n": g.n, "lx": g.lx, "ly": g.ly, "sd": g.sd} for g in design
            ],
            "heterogeneity": heterogeneity,
            "texture": texture,
            "size_px": size,
            "n_frames": n_frames,
            "endpoint_range": [lo, hi],
            "ramp": "smoothstep",
        },
        "specimens": specimens,
        "groups": {
            g.name: _group_summary(g, [s for s in specimens if s["group"] == g.name])
            for g in design
        },
    }
    write_json(out / "study_truth.json", result)
    return result
