"""The analytic deforming surfaces of the stereo scenes and their textures.

``_Sheet`` (the ``stretch`` case) and ``_Dome`` (the ``dome`` case; their maps
are in :mod:`sample_data_synth.stereo`) give the positions, deformation
gradients and Green-Lagrange strains of material points ``X`` ``(N, 2)`` (mm)
at the normalized time ``t``, the material point each camera ray hits (in
closed form), and the truth file's description of themselves.
:func:`_surface_texture` draws a surface's speckle or checker texture in
material coordinates.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from scipy import ndimage

from sample_data_synth._raytrace import _DARK, _LIGHT, _local_rays, _Raster
from sample_data_synth.deformations import Homogeneous
from sample_data_synth.render import render_speckle
from sample_data_synth.speckle import SpecklePattern, speckle_pattern

TextureKind = Literal["speckle", "checker"]

_PLATE_GAIN = 0.75  # the dome's clamp plate is painted a little darker than the membrane


def _sinc(x: np.ndarray) -> np.ndarray:
    """``sin(x) / x`` (1 at 0)."""
    return np.sinc(np.asarray(x) / np.pi)


def _asinc(x: np.ndarray) -> np.ndarray:
    """``asin(x) / x`` (1 at 0)."""
    x = np.asarray(x, dtype=float)
    safe = np.where(x == 0, 1.0, x)
    return np.where(x == 0, 1.0, np.arcsin(np.clip(safe, -1, 1)) / safe)


class _Sheet:
    """Biaxial in-plane stretch of a flat rectangular sheet (the ``stretch`` case)."""

    kind = "stretch"

    def __init__(self, center, axes, half_size, stretch, n_frames) -> None:
        self.center = np.asarray(center, dtype=float)
        self.axes = np.asarray(axes, dtype=float)  # (3, 3): columns e1, e2, normal away
        self.half_size = np.asarray(half_size, dtype=float)
        self.stretch = np.asarray(stretch, dtype=float)
        self.n_frames = int(n_frames)

    def stretches(self, t: float) -> np.ndarray:
        return 1 + t * (self.stretch - 1)

    def positions(self, X: np.ndarray, t: float) -> np.ndarray:
        return self.center + (X * self.stretches(t)) @ self.axes[:, :2].T

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        F = self.axes[:, :2] * self.stretches(t)
        return np.broadcast_to(F, (len(X), 3, 2)).copy()

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        E = np.diag((self.stretches(t) ** 2 - 1) / 2)
        return np.broadcast_to(E, (len(X), 2, 2)).copy()

    @np.errstate(divide="ignore", invalid="ignore", over="ignore")
    def hit(self, origin, M, xn, yn, t: float) -> np.ndarray:
        """Material points ``(n, 2)`` hit by the rays (see ``Shader``); NaN: none."""
        o, (dx, dy, dz) = _local_rays(origin, M, xn, yn, self.center, self.axes)
        depth = -o[2] / dz
        lam = self.stretches(t)
        X = np.column_stack([(o[0] + depth * dx) / lam[0], (o[1] + depth * dy) / lam[1]])
        hx, hy = self.half_size
        X[~((depth > 0) & (np.abs(X[:, 0]) <= hx) & (np.abs(X[:, 1]) <= hy))] = np.nan
        return X

    def texture_extent(self) -> tuple[float, float, float, float]:
        hx, hy = self.half_size
        return (-hx, -hy, hx, hy)

    def texture_gain(self, X: np.ndarray) -> np.ndarray | float:
        return 1.0

    def mapping(self, t: float) -> dict:
        lam = self.stretches(t)
        E = (lam**2 - 1) / 2
        return {"t": t, "lambda1": lam[0], "lambda2": lam[1], "E11": E[0], "E22": E[1], "E12": 0}

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "center_mm": self.center.tolist(),
            "e1": self.axes[:, 0].tolist(),
            "e2": self.axes[:, 1].tolist(),
            "normal_away_from_cameras": self.axes[:, 2].tolist(),
            "half_size_mm": self.half_size.tolist(),
            "final_stretch": self.stretch.tolist(),
            "n_frames": self.n_frames,
            "map": "x = center + lambda1(t) X1 e1 + lambda2(t) X2 e2, |X1|, |X2| <= half_size",
            "strain": "E = diag((lambda1^2 - 1) / 2, (lambda2^2 - 1) / 2) in (e1, e2)",
        }


class _Dome:
    """A clamped circular membrane inflating into a spherical cap (the ``dome`` case)."""

    kind = "dome"

    def __init__(self, center, axes, radius, height, plate_half, n_frames) -> None:
        self.center = np.asarray(center, dtype=float)
        self.axes = np.asarray(axes, dtype=float)  # columns e1, e2, normal away from cameras
        self.up = -self.axes[:, 2]  # towards the cameras: the dome bulges this way
        self.radius = float(radius)
        self.height = float(height)
        self.plate_half = float(plate_half)
        self.n_frames = int(n_frames)

    def shape(self, t: float) -> tuple[float, float, float]:
        """Apex height ``h``, curvature ``kappa`` and meridional stretch ``lam_m`` at ``t``."""
        h = t * self.height
        kappa = 2 * h / (self.radius**2 + h**2)
        return h, kappa, float(_asinc(kappa * self.radius))

    def _polar(self, X: np.ndarray, t: float):
        h, kappa, lam_m = self.shape(t)
        rho = np.hypot(X[:, 0], X[:, 1])
        s = lam_m * rho  # arc length from the apex
        ratio = lam_m * _sinc(kappa * s)  # in-plane radius / rho = circumferential stretch
        on = rho <= self.radius
        return h, kappa, lam_m, rho, s, ratio, on

    def positions(self, X: np.ndarray, t: float) -> np.ndarray:
        h, kappa, _, _, s, ratio, on = self._polar(X, t)
        drop = 0.5 * kappa * s**2 * _sinc(0.5 * kappa * s) ** 2  # (1 - cos(kappa s)) / kappa
        inplane = X * np.where(on, ratio, 1.0)[:, None]
        height = np.where(on, h - drop, 0.0)
        return self.center + inplane @ self.axes[:, :2].T + height[:, None] * self.up

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        _, kappa, lam_m, rho, s, ratio, on = self._polar(X, t)
        safe = np.where(rho > 0, rho, 1.0)
        er = np.where((rho > 0)[:, None], X / safe[:, None], [1.0, 0.0])
        ephi = np.column_stack([-er[:, 1], er[:, 0]])
        er3, ephi3 = er @ self.axes[:, :2].T, ephi @ self.axes[:, :2].T
        tangent = np.cos(kappa * s)[:, None] * er3 - np.sin(kappa * s)[:, None] * self.up
        F = lam_m * np.einsum("ni,nj->nij", tangent, er) + ratio[:, None, None] * np.einsum(
            "ni,nj->nij", ephi3, ephi
        )
        F[~on] = self.axes[:, :2]
        return F

    def stretches(self, X: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Meridional and circumferential stretches ``(N,)``, 1 on the plate."""
        _, _, lam_m, _, _, ratio, on = self._polar(X, t)
        return np.where(on, lam_m, 1.0), np.where(on, ratio, 1.0)

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        lam_m, lam_c = self.stretches(X, t)
        rho = np.hypot(X[:, 0], X[:, 1])
        safe = np.where(rho > 0, rho, 1.0)
        er = np.where((rho > 0)[:, None], X / safe[:, None], [1.0, 0.0])
        Em, Ec = (lam_m**2 - 1) / 2, (lam_c**2 - 1) / 2
        return Ec[:, None, None] * np.eye(2) + (Em - Ec)[:, None, None] * np.einsum(
            "ni,nj->nij", er, er
        )

    @np.errstate(divide="ignore", invalid="ignore", over="ignore")
    def hit(self, origin, M, xn, yn, t: float) -> np.ndarray:
        """Material points ``(n, 2)`` hit by the rays (see ``Shader``); NaN: none."""
        h, kappa, lam_m = self.shape(t)
        # local frame (e1, e2, -up); the sphere through the apex (0, 0, -h), stable for
        # kappa -> 0: kappa |p|^2 - 2 p_z = 0 with p relative to the apex
        o, (dx, dy, dz) = _local_rays(origin, M, xn, yn, self.center, self.axes)
        p0 = o + np.array([0.0, 0.0, h])
        A = kappa * (dx * dx + dy * dy + dz * dz)
        B = 2 * (kappa * (p0[0] * dx + p0[1] * dy + p0[2] * dz) - dz)
        C = kappa * (p0 @ p0) - 2 * p0[2]
        disc = B * B - 4 * A * C
        q = -0.5 * (B + np.copysign(np.sqrt(np.clip(disc, 0, None)), B))
        depth = C / q  # the root nearer the camera
        X = np.column_stack([o[0] + depth * dx, o[1] + depth * dy])
        r = np.hypot(X[:, 0], X[:, 1])
        on_cap = (disc >= 0) & (depth > 0) & (o[2] + depth * dz <= 0) & (r <= self.radius)
        depth = np.where(on_cap, depth, -o[2] / dz)  # else the plate's plane
        X = np.column_stack([o[0] + depth * dx, o[1] + depth * dy])
        r = np.hypot(X[:, 0], X[:, 1])
        X *= np.where(on_cap, _asinc(np.minimum(kappa * r, 1.0)) / lam_m, 1.0)[:, None]
        plate = ~on_cap & (depth > 0) & np.all(np.abs(X) <= self.plate_half, axis=1)
        X[~(on_cap | plate)] = np.nan
        return X

    def texture_extent(self) -> tuple[float, float, float, float]:
        b = self.plate_half
        return (-b, -b, b, b)

    def texture_gain(self, X: np.ndarray) -> np.ndarray:
        return np.where(X[:, 0] ** 2 + X[:, 1] ** 2 <= self.radius**2, 1.0, _PLATE_GAIN)

    def mapping(self, t: float) -> dict:
        h, kappa, lam_m = self.shape(t)
        return {
            "t": t,
            "apex_height_mm": h,
            "curvature_per_mm": kappa,
            "sphere_radius_mm": 1 / kappa if kappa > 0 else None,
            "sphere_center_mm": (
                (self.center + (h - 1 / kappa) * self.up).tolist() if kappa > 0 else None
            ),
            "meridional_stretch": lam_m,
            "rim_polar_angle_deg": math.degrees(math.asin(min(1.0, kappa * self.radius))),
            "E_meridional": (lam_m**2 - 1) / 2,
            "E_circumferential_apex": (lam_m**2 - 1) / 2,
            "E_circumferential_rim": 0.0,
        }

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "center_mm": self.center.tolist(),
            "e1": self.axes[:, 0].tolist(),
            "e2": self.axes[:, 1].tolist(),
            "normal_away_from_cameras": self.axes[:, 2].tolist(),
            "radius_mm": self.radius,
            "final_apex_height_mm": self.height,
            "plate_half_size_mm": self.plate_half,
            "plate_gain": _PLATE_GAIN,
            "n_frames": self.n_frames,
            "map": (
                "rho = |X| <= radius: s = lambda_m rho, x = center + (sin(kappa s) / kappa) "
                "X / rho + (h - (1 - cos(kappa s)) / kappa) up, up = -normal; rho > radius: "
                "x = center + X1 e1 + X2 e2 (fixed plate); h = t final_apex_height, "
                "kappa = 2 h / (radius^2 + h^2), lambda_m = asin(kappa radius) / (kappa radius)"
            ),
            "strain": (
                "E = diag((lambda_m^2 - 1) / 2, (lambda_c^2 - 1) / 2) in (e_rho, e_phi), "
                "lambda_c = sin(kappa s) / (kappa rho); 0 on the plate"
            ),
        }


def _surface_from_dict(d: dict):
    axes = np.column_stack([d["e1"], d["e2"], d["normal_away_from_cameras"]])
    if d["kind"] == "stretch":
        return _Sheet(d["center_mm"], axes, d["half_size_mm"], d["final_stretch"], d["n_frames"])
    if d["kind"] == "dome":
        return _Dome(
            d["center_mm"],
            axes,
            d["radius_mm"],
            d["final_apex_height_mm"],
            d["plate_half_size_mm"],
            d["n_frames"],
        )
    raise ValueError(f"unknown surface kind {d['kind']!r}")


def _surface_texture(
    surface: _Sheet | _Dome,
    texture: TextureKind,
    *,
    speckle_radius: float,
    speckle_density: float,
    speckle_contrast: float,
    rng: np.random.Generator,
) -> tuple[_Raster, SpecklePattern | None]:
    x0, y0, x1, y1 = surface.texture_extent()
    if texture == "speckle":
        texel = speckle_radius / 5
        pad = 4 * texel
        x0, y0, x1, y1 = x0 - pad, y0 - pad, x1 + pad, y1 + pad
        nx, ny = math.ceil((x1 - x0) / texel) + 1, math.ceil((y1 - y0) / texel) + 1
        margin = 6 * speckle_radius
        pattern = speckle_pattern(
            (x0 - margin, y0 - margin, x1 + margin, y1 + margin),
            radius=speckle_radius,
            density=speckle_density,
            contrast=speckle_contrast,
            rng=rng,
        )
        in_texels = SpecklePattern(
            (pattern.centers - (x0, y0)) / texel,
            pattern.sigmas / texel,
            pattern.background,
            pattern.ink,
        )
        identity = Homogeneous("stretch", (0.0, 0.0), lx=1.0, ly=1.0)
        values = render_speckle(in_texels, identity, 0.0, (ny, nx), psf_sigma=0.0)
        return _Raster(values.astype(np.float32), (x0, y0), texel), pattern
    square, per = 2.0, 40  # a 2 mm checker in material coordinates
    texel = square / per
    nx, ny = round((x1 - x0) / texel), round((y1 - y0) / texel)
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    cx = np.floor((x0 + (jj + 0.5) * texel) / square)
    cy = np.floor((y0 + (ii + 0.5) * texel) / square)
    values = np.where((cx + cy) % 2 == 0, _DARK, _LIGHT)
    values = ndimage.gaussian_filter(values, 1.0, mode="nearest")
    origin = (x0 + 0.5 * texel, y0 + 0.5 * texel)
    return _Raster(values.astype(np.float32), origin, texel), None
