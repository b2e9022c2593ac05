"""Analytic deformations with exact positions, deformation gradients and strains.

A deformation maps reference coordinates ``X`` (pixels, x = column, y = row)
to current coordinates ``x`` at a normalized time ``t`` in [0, 1]; ``t = 0`` is
the identity.  Every class offers ``forward``, ``inverse`` and ``gradient`` and
serializes to a plain dict so ground truth can be stored beside a video and
rebuilt later with :func:`deformation_from_dict`.

How frames map to ``t`` is a separate, optional time profile: by default frame
``k`` of ``T`` has ``t = k / (T - 1)``; :class:`RampHold` instead ramps ``t``
from 0 to 1 up to a chosen frame and holds it there (a contraction that
stops), and :class:`Twitch` rises from 0 to 1 and relaxes back (a muscle's
twitch), see :func:`time_profile_from_dict`.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "Contraction",
    "Field",
    "Homogeneous",
    "RampHold",
    "Twitch",
    "Twitches",
    "deformation_from_dict",
    "equibiaxial",
    "green_lagrange",
    "rotation",
    "simple_shear",
    "time_profile_from_dict",
]


def _solve2(F: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``F^-1 r`` for stacks of 2 x 2 matrices ``(..., 2, 2)`` and vectors ``(..., 2)``
    (Cramer's rule: many times faster than ``numpy.linalg.solve`` on small systems)."""
    a, b, c, d = F[..., 0, 0], F[..., 0, 1], F[..., 1, 0], F[..., 1, 1]
    det = a * d - b * c
    return (
        np.stack([d * r[..., 0] - b * r[..., 1], a * r[..., 1] - c * r[..., 0]], -1)
        / det[..., None]
    )


def green_lagrange(F: np.ndarray) -> np.ndarray:
    """``E = (F^T F - I) / 2`` for ``F`` of shape ``(..., 2, 2)``."""
    F = np.asarray(F, dtype=float)
    return 0.5 * (np.einsum("...ki,...kj->...ij", F, F) - np.eye(2))


class Homogeneous:
    """``x = c + A(t) (X - c)`` with ``A(t)`` ramping from I to ``A1``.

    Parameters
    ----------
    kind : {"stretch", "rotation", "shear", "turn"}
        ``stretch``: ``A(t) = diag(1 + t (lx - 1), 1 + t (ly - 1))``;
        ``turn``: ``A(t) = (1 + t (stretch - 1)) R(t angle_deg)``, a uniform
        contraction or dilation while turning;
        ``rotation``: rotation by ``t * angle_deg`` (counter-clockwise on screen
        means towards -y, see note); ``shear``: ``A(t) = [[1, t g], [0, 1]]``.
    center : (cx, cy)
        Fixed point in pixels.
    params : dict
        ``lx, ly`` for stretch, ``angle_deg`` for rotation, ``gamma`` for shear,
        ``stretch, angle_deg`` for turn.

    Notes
    -----
    With y pointing down (image rows), the rotation matrix
    ``[[cos, -sin], [sin, cos]]`` turns clockwise on screen for positive angles.
    """

    def __init__(self, kind: str, center: tuple[float, float], **params: float) -> None:
        if kind not in ("stretch", "rotation", "shear", "turn"):
            raise ValueError(f"kind must be stretch, rotation, shear or turn, got {kind!r}")
        self.kind = kind
        self.center = np.asarray(center, dtype=float)
        self.params = {k: float(v) for k, v in params.items()}

    def matrix(self, t: float) -> np.ndarray:
        """``A(t)``, shape (2, 2)."""
        p = self.params
        if self.kind == "stretch":
            return np.diag([1 + t * (p["lx"] - 1), 1 + t * (p["ly"] - 1)])
        if self.kind in ("rotation", "turn"):
            a = np.radians(t * p["angle_deg"])
            s = 1 + t * (p["stretch"] - 1) if self.kind == "turn" else 1.0
            return s * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
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
    kind : {"gaussian", "sinusoid", "fold", "bump"}
        ``gaussian``: local contraction towards ``center``,
        ``u = -a (X - c) exp(-|X - c|^2 / (2 s^2))``; at the centre
        ``F = (1 - a) I``.
        ``sinusoid``: ``u = (A sin(k (X - cx)), A sin(k (Y - cy)))`` with
        ``k = 2 pi / wavelength``: Exx varies along x and Eyy along y.
        ``fold``: a compression band across x (a fold-like strain
        concentration), ``u_x = -a w tanh((X - cx) / w)``, ``u_y = 0``:
        ``F_xx = 1 - a sech^2((X - cx) / w)``.
        ``bump``: a local shift of the tissue around ``center``,
        ``u = (ax, ay) exp(-|X - c|^2 / (2 s^2))``; one-to-one while
        ``|a| < s sqrt(e)``.
    center : (cx, cy)
    params : dict
        ``a, s`` (gaussian); ``amplitude, wavelength`` (sinusoid); ``a, width`` (fold);
        ``ax, ay, s`` (bump).
    """

    def __init__(self, kind: str, center: tuple[float, float], **params: float) -> None:
        if kind not in ("gaussian", "sinusoid", "fold", "bump"):
            raise ValueError(f"kind must be gaussian, sinusoid, fold or bump, got {kind!r}")
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
        if self.kind == "bump":
            w = np.exp(-np.sum(d**2, axis=-1) / (2 * p["s"] ** 2))
            return np.array([p["ax"], p["ay"]]) * w[..., None]
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
        if self.kind == "bump":
            w = np.exp(-np.sum(d**2, axis=-1) / (2 * p["s"] ** 2))
            a = np.array([p["ax"], p["ay"]])
            return -(w / p["s"] ** 2)[..., None, None] * a[:, None] * d[..., None, :]
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
            X = X - _solve2(self.gradient(X, t), residual)
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


class Contraction:
    """Anisotropic contraction about a centre with a superposed smooth heterogeneity.

    ``x = c + A(t) (X - c) + t sum_k u_k(X)`` with
    ``A(t) = diag(1 + t (lx - 1), 1 + t (ly - 1))`` and ``u_k`` the
    displacement fields of :class:`Field` objects at t = 1.  ``lx`` and
    ``ly`` are the homogeneous stretches along x (longitudinal) and y
    (circumferential): ``lx = 0.8`` is 20 % shortening along x.  The
    deformation gradient is ``F = A(t) + t sum_k grad u_k(X)``, so the
    Green-Lagrange strain of the homogeneous part alone is
    ``Exx = (lx^2 - 1) / 2``, ``Eyy = (ly^2 - 1) / 2``, ``Exy = 0``.

    Parameters
    ----------
    center : (cx, cy)
        Fixed point of the homogeneous part, in pixels.
    lx, ly : float, keyword-only
        Final stretches (> 0).
    fields : sequence of Field, keyword-only
        Heterogeneity superposed on the homogeneous part (default none).

    Examples
    --------
    >>> d = Contraction((50.0, 50.0), lx=0.8, ly=0.9)
    >>> d.forward(np.array([60.0, 60.0]), 1.0).tolist()
    [58.0, 59.0]
    >>> round(float(d.strain(np.array([10.0, 20.0]), 1.0)[0, 0]), 6)
    -0.18
    """

    def __init__(
        self,
        center: tuple[float, float],
        *,
        lx: float,
        ly: float,
        fields: tuple[Field, ...] | list[Field] = (),
    ) -> None:
        lx, ly = float(lx), float(ly)
        for name, value in (("lx", lx), ("ly", ly)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite stretch > 0, got {value}")
        fields = tuple(fields)
        if not all(isinstance(f, Field) for f in fields):
            raise ValueError("fields must be Field objects")
        self.center = np.asarray(center, dtype=float)
        if self.center.shape != (2,):
            raise ValueError(f"center must be (cx, cy), got {center!r}")
        self.lx, self.ly = lx, ly
        self.fields = fields

    def matrix(self, t: float) -> np.ndarray:
        """Homogeneous part ``A(t)``, shape (2, 2)."""
        return np.diag([1 + t * (self.lx - 1), 1 + t * (self.ly - 1)])

    def displacement(self, X: np.ndarray) -> np.ndarray:
        """Heterogeneous displacement ``sum_k u_k(X)`` at t = 1, shape ``(..., 2)``."""
        X = np.asarray(X, dtype=float)
        u = np.zeros(X.shape)
        for f in self.fields:
            u += f.displacement(X)
        return u

    def forward(self, X: np.ndarray, t: float) -> np.ndarray:
        """Current positions ``(..., 2)`` of reference points ``X`` ``(..., 2)``."""
        X = np.asarray(X, dtype=float)
        return self.center + (X - self.center) @ self.matrix(t).T + t * self.displacement(X)

    def inverse(self, x: np.ndarray, t: float) -> np.ndarray:
        """Reference positions by Newton's method from the homogeneous inverse (to 1e-10 px).

        Raises
        ------
        ValueError
            If Newton's method does not converge (the map folds over itself:
            too strong a heterogeneity).
        """
        x = np.asarray(x, dtype=float)
        X = self.center + (x - self.center) @ np.linalg.inv(self.matrix(t)).T
        if not self.fields:
            return X
        for _ in range(50):
            residual = self.forward(X, t) - x
            if np.abs(residual).max(initial=0.0) < 1e-10:
                return X
            X = X - _solve2(self.gradient(X, t), residual)
        raise ValueError("Contraction.inverse did not converge; is det F > 0 everywhere?")

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        """Deformation gradient ``F`` at ``X``, shape ``(..., 2, 2)``."""
        X = np.asarray(X, dtype=float)
        F = np.broadcast_to(self.matrix(t), (*X.shape[:-1], 2, 2)).copy()
        for f in self.fields:
            F += t * f.displacement_gradient(X)
        return F

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        """Green-Lagrange strain at ``X``, shape ``(..., 2, 2)``."""
        return green_lagrange(self.gradient(X, t))

    def to_dict(self) -> dict:
        return {
            "type": "contraction",
            "center": self.center.tolist(),
            "lx": self.lx,
            "ly": self.ly,
            "fields": [f.to_dict() for f in self.fields],
        }

    def __repr__(self) -> str:
        return (
            f"Contraction(center={tuple(self.center.tolist())}, lx={self.lx:g}, ly={self.ly:g}, "
            f"fields={list(self.fields)})"
        )


def deformation_from_dict(d: dict) -> Homogeneous | Field | Contraction:
    """Rebuild a deformation from its ``to_dict()`` output."""
    d = dict(d)
    kind_type = d.pop("type", None)
    if kind_type == "contraction":
        fields = [deformation_from_dict(f) for f in d.get("fields", [])]
        return Contraction(tuple(d["center"]), lx=d["lx"], ly=d["ly"], fields=fields)
    if kind_type not in ("homogeneous", "field"):
        raise ValueError(f"unknown deformation type {kind_type!r}")
    kind = d.pop("kind")
    center = tuple(d.pop("center"))
    cls = Homogeneous if kind_type == "homogeneous" else Field
    return cls(kind, center, **d)


class RampHold:
    """Time profile: ``t`` ramps from 0 at frame 0 to 1 at frame ``endpoint``, then holds.

    With ``u = min(frame / endpoint, 1)``: ``ramp="smoothstep"`` gives
    ``t = 3 u^2 - 2 u^3`` (starts and stops smoothly, like a muscle contraction
    reaching its plateau), ``ramp="linear"`` gives ``t = u`` (constant rate,
    abrupt stop).  From ``endpoint`` on, every frame has ``t = 1``: positions
    are constant and the strain rate is exactly zero.

    A strain-rate endpoint detector with a relative tolerance ``r`` (rate below
    ``r`` times the peak rate) finds ``endpoint`` on the smoothstep ramp while
    the last ramp step, about ``2 / endpoint`` of the peak step, exceeds
    ``r``: for ``r = 0.05``, up to ``endpoint`` of about 35 frames; use the
    linear ramp for longer ramps.

    Parameters
    ----------
    endpoint : int
        Frame where the motion stops (>= 1).
    ramp : {"smoothstep", "linear"}, keyword-only

    Examples
    --------
    >>> profile = RampHold(4)
    >>> [profile(k) for k in range(6)]
    [0.0, 0.15625, 0.5, 0.84375, 1.0, 1.0]
    """

    def __init__(self, endpoint: int, *, ramp: str = "smoothstep") -> None:
        if isinstance(endpoint, bool) or int(endpoint) != endpoint or endpoint < 1:
            raise ValueError(f"endpoint must be a frame index >= 1, got {endpoint!r}")
        if ramp not in ("smoothstep", "linear"):
            raise ValueError(f"ramp must be smoothstep or linear, got {ramp!r}")
        self.endpoint = int(endpoint)
        self.ramp = ramp

    def __call__(self, frame: float) -> float:
        """Normalized time ``t`` in [0, 1] of a frame (fractional frames allowed)."""
        u = min(max(float(frame) / self.endpoint, 0.0), 1.0)
        return 3 * u**2 - 2 * u**3 if self.ramp == "smoothstep" else u

    def describe(self) -> str:
        formula = "3 u^2 - 2 u^3" if self.ramp == "smoothstep" else "u"
        return (
            f"ramp then hold: frame k has t = {formula} with u = min(k / {self.endpoint}, 1); "
            f"motion stops at frame {self.endpoint}"
        )

    def to_dict(self) -> dict:
        return {"type": "ramp_hold", "endpoint": self.endpoint, "ramp": self.ramp}

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RampHold) and other.to_dict() == self.to_dict()

    def __hash__(self) -> int:
        return hash((self.endpoint, self.ramp))

    def __repr__(self) -> str:
        return f"RampHold({self.endpoint}, ramp={self.ramp!r})"


class Twitch:
    """Time profile of a twitch: ``t`` rises from 0 to 1 and relaxes back to 0.

    ``t = 0`` up to frame ``onset``, a smoothstep ``3 u^2 - 2 u^3`` up to 1 at
    frame ``peak``, a smoothstep back down to 0 at frame ``endpoint``, and 0
    from there on (the tissue is back at rest: positions equal the reference).

    Parameters
    ----------
    onset, peak, endpoint : int
        Frames with ``0 <= onset < peak < endpoint``.

    Examples
    --------
    >>> profile = Twitch(1, 3, 7)
    >>> [profile(k) for k in range(9)]
    [0.0, 0.0, 0.5, 1.0, 0.84375, 0.5, 0.15625, 0.0, 0.0]
    """

    def __init__(self, onset: int, peak: int, endpoint: int) -> None:
        values = (onset, peak, endpoint)
        if any(isinstance(v, bool) or int(v) != v for v in values) or not (
            0 <= onset < peak < endpoint
        ):
            raise ValueError(
                "onset, peak and endpoint must be frame indices with 0 <= onset < peak < "
                f"endpoint, got {onset!r}, {peak!r}, {endpoint!r}"
            )
        self.onset, self.peak, self.endpoint = int(onset), int(peak), int(endpoint)

    def __call__(self, frame: float) -> float:
        """Normalized time ``t`` in [0, 1] of a frame (fractional frames allowed)."""
        frame = float(frame)
        if frame <= self.peak:
            u = min(max((frame - self.onset) / (self.peak - self.onset), 0.0), 1.0)
        else:
            u = 1.0 - min((frame - self.peak) / (self.endpoint - self.peak), 1.0)
        return 3 * u**2 - 2 * u**3

    def describe(self) -> str:
        return (
            f"twitch: t = 0 up to frame {self.onset}, a smoothstep (3 u^2 - 2 u^3) up to 1 at "
            f"frame {self.peak} and back to 0 at frame {self.endpoint}, 0 after"
        )

    def to_dict(self) -> dict:
        return {
            "type": "twitch",
            "onset": self.onset,
            "peak": self.peak,
            "endpoint": self.endpoint,
        }

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Twitch) and other.to_dict() == self.to_dict()

    def __hash__(self) -> int:
        return hash((self.onset, self.peak, self.endpoint))

    def __repr__(self) -> str:
        return f"Twitch({self.onset}, {self.peak}, {self.endpoint})"


class Twitches:
    """Time profile of repeated twitches of different sizes: a cycle after another.

    Twitch ``i`` is a :class:`Twitch` ``(onset, peak, end)`` scaled by its
    ``amplitude`` (0 to 1]: ``t`` rises from 0 at ``onset`` to ``amplitude`` at
    ``peak`` and relaxes to 0 at ``end``; between twitches the tissue rests at
    ``t = 0`` (its reference).  A deformation whose strain grows with ``t`` makes
    each twitch's peak strain that of ``t = amplitude``.

    Parameters
    ----------
    twitches : sequence of (onset, peak, end, amplitude)
        Frames with ``onset < peak < end <= next onset``.

    Examples
    --------
    >>> profile = Twitches([(1, 3, 5, 1.0), (6, 7, 9, 0.5)])
    >>> [round(profile(k), 3) for k in range(11)]
    [0.0, 0.0, 0.5, 1.0, 0.5, 0.0, 0.0, 0.5, 0.25, 0.0, 0.0]
    """

    def __init__(self, twitches) -> None:
        twitches = [tuple(t) for t in twitches]
        if not twitches:
            raise ValueError("give at least one twitch")
        self.twitches = []
        end_before = -1
        for onset, peak, end, amplitude in twitches:
            if not 0 < float(amplitude) <= 1:
                raise ValueError(f"a twitch's amplitude must be in (0, 1], got {amplitude!r}")
            if onset < end_before:
                raise ValueError(f"twitch at frame {onset} starts before the one before ends")
            self.twitches.append((Twitch(onset, peak, end), float(amplitude)))
            end_before = end
        self.endpoint = self.twitches[-1][0].endpoint

    @property
    def cycles(self) -> list[dict]:
        """Each twitch's ``onset``, ``peak``, ``end`` frames and ``amplitude``."""
        return [
            {"onset": t.onset, "peak": t.peak, "end": t.endpoint, "amplitude": a}
            for t, a in self.twitches
        ]

    def __call__(self, frame: float) -> float:
        """Normalized time ``t`` of a frame (fractional frames allowed)."""
        frame = float(frame)
        for twitch, amplitude in self.twitches:
            if twitch.onset <= frame <= twitch.endpoint:
                return amplitude * twitch(frame)
        return 0.0

    def describe(self) -> str:
        parts = [f"{a:g} x twitch({t.onset}, {t.peak}, {t.endpoint})" for t, a in self.twitches]
        return f"{len(parts)} twitches, t = 0 between them: " + ", ".join(parts)

    def to_dict(self) -> dict:
        return {
            "type": "twitches",
            "twitches": [[t.onset, t.peak, t.endpoint, a] for t, a in self.twitches],
        }

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Twitches) and other.to_dict() == self.to_dict()

    def __hash__(self) -> int:
        return hash(str(self.to_dict()))

    def __repr__(self) -> str:
        return f"Twitches({self.to_dict()['twitches']})"


def time_profile_from_dict(d: dict) -> RampHold | Twitch | Twitches:
    """Rebuild a time profile from its ``to_dict()`` output."""
    if d.get("type") == "twitches":
        return Twitches(d["twitches"])
    if d.get("type") == "twitch":
        return Twitch(d["onset"], d["peak"], d["endpoint"])
    if d.get("type") != "ramp_hold":
        raise ValueError(f"unknown time profile type {d.get('type')!r}")
    return RampHold(d["endpoint"], ramp=d.get("ramp", "smoothstep"))
