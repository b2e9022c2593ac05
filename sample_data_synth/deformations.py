"""Analytic deformations with exact positions, deformation gradients and strains.

A deformation maps reference coordinates ``X`` (pixels, x = column, y = row)
to current coordinates ``x`` at a normalized time ``t`` in [0, 1]; ``t = 0`` is
the identity.  Every class offers ``forward``, ``inverse`` and ``gradient`` and
serializes to a plain dict so ground truth can be stored beside a video and
rebuilt later with :func:`deformation_from_dict`.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "Field",
    "Homogeneous",
    "deformation_from_dict",
    "equibiaxial",
    "green_lagrange",
    "rotation",
    "simple_shear",
]


def green_lagrange(F: np.ndarray) -> np.ndarray:
    """``E = (F^T F - I) / 2`` for ``F`` of shape ``(..., 2, 2)``."""
    F = np.asarray(F, dtype=float)
    return 0.5 * (np.einsum("...ki,...kj->...ij", F, F) - np.eye(2))


class Homogeneous:
    """``x = c + A(t) (X - c)`` with ``A(t)`` ramping from I to ``A1``.

    Parameters
    ----------
    kind : {"stretch", "rotation", "shear"}
        ``stretch``: ``A(t) = diag(1 + t (lx - 1), 1 + t (ly - 1))``;
        ``rotation``: rotation by ``t * angle_deg`` (counter-clockwise on screen
        means towards -y, see note); ``shear``: ``A(t) = [[1, t g], [0, 1]]``.
    center : (cx, cy)
        Fixed point in pixels.
    params : dict
        ``lx, ly`` for stretch, ``angle_deg`` for rotation, ``gamma`` for shear.

    Notes
    -----
    With y pointing down (image rows), the rotation matrix
    ``[[cos, -sin], [sin, cos]]`` turns clockwise on screen for positive angles.
    """

    def __init__(self, kind: str, center: tuple[float, float], **params: float) -> None:
        if kind not in ("stretch", "rotation", "shear"):
            raise ValueError(f"kind must be stretch, rotation or shear, got {kind!r}")
        self.kind = kind
        self.center = np.asarray(center, dtype=float)
        self.params = {k: float(v) for k, v in params.items()}

    def matrix(self, t: float) -> np.ndarray:
        """``A(t)``, shape (2, 2)."""
        p = self.params
        if self.kind == "stretch":
            return np.diag([1 + t * (p["lx"] - 1), 1 + t * (p["ly"] - 1)])
        if self.kind == "rotation":
            a = np.radians(t * p["angle_deg"])
            return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        return np.array([[1.0, t * p["gamma"]], [0.0, 1.0]])

    def forward(self, X: np.ndarray, t: float) -> np.ndarray:
        """Current positions ``(..., 2)`` of reference points ``X`` ``(..., 2)``."""
        X = np.asarray(X, dtype=float)
        return self.center + (X - self.center) @ self.matrix(t).T

    def inverse(self, x: np.ndarray, t: float) -> np.ndarray:
        """Reference positions ``(..., 2)`` of current points ``x`` ``(..., 2)``."""
        x = np.asarray(x, dtype=float)
        return self.center + (x - self.center) @ np.linalg.inv(self.matrix(t)).T

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        """Deformation gradient ``F`` at ``X``, shape ``(..., 2, 2)``."""
        X = np.asarray(X, dtype=float)
        return np.broadcast_to(self.matrix(t), (*X.shape[:-1], 2, 2)).copy()

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        """Green-Lagrange strain at ``X``, shape ``(..., 2, 2)``."""
        return green_lagrange(self.gradient(X, t))

    def to_dict(self) -> dict:
        return {
            "type": "homogeneous",
            "kind": self.kind,
            "center": self.center.tolist(),
            **self.params,
        }

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v:g}" for k, v in self.params.items())
        return f"Homogeneous({self.kind}, center={tuple(self.center)}, {args})"


def equibiaxial(stretch: float, center: tuple[float, float]) -> Homogeneous:
    """``x = c + stretch (X - c)`` at t = 1 (the paper's eqs. 3-4)."""
    return Homogeneous("stretch", center, lx=stretch, ly=stretch)


def rotation(angle_deg: float, center: tuple[float, float]) -> Homogeneous:
    """Rigid rotation by ``angle_deg`` at t = 1 (the paper's eqs. 7-8)."""
    return Homogeneous("rotation", center, angle_deg=angle_deg)


def simple_shear(gamma: float, center: tuple[float, float]) -> Homogeneous:
    """``x = X + gamma (Y - cy)``, ``y = Y`` at t = 1 (the paper's eqs. 10-11)."""
    return Homogeneous("shear", center, gamma=gamma)


class Field:
    """A heterogeneous displacement field ramped in time: ``x = X + t u(X)``.

    Parameters
    ----------
    kind : {"gaussian", "sinusoid", "fold"}
        ``gaussian``: local contraction towards ``center``,
        ``u = -a (X - c) exp(-|X - c|^2 / (2 s^2))``; at the centre
        ``F = (1 - a) I``.
        ``sinusoid``: ``u = (A sin(k (X - cx)), A sin(k (Y - cy)))`` with
        ``k = 2 pi / wavelength``: Exx varies along x and Eyy along y.
        ``fold``: a compression band across x (a fold-like strain
        concentration), ``u_x = -a w tanh((X - cx) / w)``, ``u_y = 0``:
        ``F_xx = 1 - a sech^2((X - cx) / w)``.
    center : (cx, cy)
    params : dict
        ``a, s`` (gaussian); ``amplitude, wavelength`` (sinusoid); ``a, width`` (fold).
    """

    def __init__(self, kind: str, center: tuple[float, float], **params: float) -> None:
        if kind not in ("gaussian", "sinusoid", "fold"):
            raise ValueError(f"kind must be gaussian, sinusoid or fold, got {kind!r}")
        self.kind = kind
        self.center = np.asarray(center, dtype=float)
        self.params = {k: float(v) for k, v in params.items()}

    def displacement(self, X: np.ndarray) -> np.ndarray:
        """``u(X)`` at t = 1, shape ``(..., 2)``."""
        d = np.asarray(X, dtype=float) - self.center
        p = self.params
        if self.kind == "gaussian":
            w = np.exp(-np.sum(d**2, axis=-1) / (2 * p["s"] ** 2))
            return -p["a"] * d * w[..., None]
        if self.kind == "sinusoid":
            k = 2 * np.pi / p["wavelength"]
            return p["amplitude"] * np.sin(k * d)
        ux = -p["a"] * p["width"] * np.tanh(d[..., 0] / p["width"])
        return np.stack([ux, np.zeros_like(ux)], axis=-1)

    def displacement_gradient(self, X: np.ndarray) -> np.ndarray:
        """``grad u`` at t = 1, shape ``(..., 2, 2)`` (``[i, j] = du_i / dX_j``)."""
        d = np.asarray(X, dtype=float) - self.center
        p = self.params
        out = np.zeros((*d.shape[:-1], 2, 2))
        if self.kind == "gaussian":
            w = np.exp(-np.sum(d**2, axis=-1) / (2 * p["s"] ** 2))
            outer = d[..., :, None] * d[..., None, :] / p["s"] ** 2
            return -p["a"] * w[..., None, None] * (np.eye(2) - outer)
        if self.kind == "sinusoid":
            k = 2 * np.pi / p["wavelength"]
            out[..., 0, 0] = p["amplitude"] * k * np.cos(k * d[..., 0])
            out[..., 1, 1] = p["amplitude"] * k * np.cos(k * d[..., 1])
            return out
        out[..., 0, 0] = -p["a"] / np.cosh(d[..., 0] / p["width"]) ** 2
        return out

    def forward(self, X: np.ndarray, t: float) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        return X + t * self.displacement(X)

    def inverse(self, x: np.ndarray, t: float) -> np.ndarray:
        """Reference positions by Newton's method on ``X + t u(X) = x`` (to 1e-10 px)."""
        x = np.asarray(x, dtype=float)
        X = x.copy()
        for _ in range(50):
            residual = self.forward(X, t) - x
            if np.abs(residual).max() < 1e-10:
                break
            F = self.gradient(X, t)
            X = X - np.linalg.solve(F, residual[..., None])[..., 0]
        return X

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        return np.eye(2) + t * self.displacement_gradient(X)

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        return green_lagrange(self.gradient(X, t))

    def to_dict(self) -> dict:
        return {"type": "field", "kind": self.kind, "center": self.center.tolist(), **self.params}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v:g}" for k, v in self.params.items())
        return f"Field({self.kind}, center={tuple(self.center)}, {args})"


def deformation_from_dict(d: dict) -> Homogeneous | Field:
    """Rebuild a deformation from its ``to_dict()`` output."""
    d = dict(d)
    kind_type = d.pop("type", None)
    if kind_type not in ("homogeneous", "field"):
        raise ValueError(f"unknown deformation type {kind_type!r}")
    kind = d.pop("kind")
    center = tuple(d.pop("center"))
    cls = Homogeneous if kind_type == "homogeneous" else Field
    return cls(kind, center, **d)
