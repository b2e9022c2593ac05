"""A stand-in for the published CoTracker3 offline predictor, honouring its contract.

``StandInPredictor()(video, queries=q)`` takes ``video`` ``(B, T, 3, H, W)``
holding 0-255 and ``q`` ``(B, N, 3)`` of ``(t, x, y)`` in the video's pixels,
and returns tracks ``(B, T, N, 2)`` in the video's pixels and visibility
``(B, T, N)``.  Like the real model it resizes every frame to 384 x 512
(``align_corners=True``) and works in those coordinates, and it refuses
videos longer than its window, so a wrong crop, scaling or chunking shows.

Motion (in the model's coordinates ``u``): a flow that depends only on the
time since the query,

    u(t) = a + L ** (t - t_q) (u_q - a),      L = diag(exp(model.log_stretch)),

about the anchor ``a``: the centroid of the brightness above 128 on the input's
first frame (a bright marker on a gray background).  As ``L`` is diagonal,
cropping and resizing (a shift and a scaling of each axis) change neither ``L``
nor the material anchor, so in the original frame the true path is
``x(t) = A + L ** t (X - A)`` with ``A`` the marker's centre.

Visibility: the frame's value at the tracked point (model resolution) is at
least 32, so a black occluder hides the points under it (the synthetic speckle
videos stay above 40).  ``mode="bool"`` returns booleans like the published
predictor, ``"prob"`` the probability ``min(value / 64, 1)``, ``"conf"`` that
probability and a confidence of 0.9.

The weights are ``model.log_stretch`` (zero without a checkpoint: no motion)
and a probe layer run on every call, which records the dtype autocast gives it.
This file is also copied into fake hub repositories and packages by the tests.
"""

import torch
import torch.nn.functional as F

INTERP = (384, 512)


class StandInCore(torch.nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.log_stretch = torch.nn.Parameter(torch.zeros(2))
        self.probe = torch.nn.Linear(2, 2)


class StandInPredictor(torch.nn.Module):
    def __init__(self, *, window_len: int = 60, mode: str = "bool") -> None:
        super().__init__()
        self.model = StandInCore()
        self.interp_shape = INTERP
        self.window_len = window_len
        self.mode = mode
        self.calls = []  # one dict per call

    @torch.no_grad()
    def forward(self, video, queries=None):
        B, T, C, H, W = video.shape
        if C != 3 or video.dtype != torch.float32 or queries is None:
            raise ValueError(
                f"stand-in wants float32 (B, T, 3, H, W) and queries, got {video.shape}"
            )
        if T > self.window_len:
            raise ValueError(f"stand-in window is {self.window_len} frames, got {T}")
        if video.min() < 0 or video.max() > 255 or video.max() <= 1:
            raise ValueError("stand-in wants values 0-255")
        if not (
            torch.equal(video[:, :, 0], video[:, :, 1])
            and torch.equal(video[:, :, 0], video[:, :, 2])
        ):
            raise ValueError("stand-in expects gray replicated to 3 channels")
        N = queries.shape[1]
        if queries.shape != (B, N, 3) or queries[..., 0].min() < 0 or queries[..., 0].max() >= T:
            raise ValueError(f"bad queries {tuple(queries.shape)}")
        probe = self.model.probe(video.new_ones(1, 2))
        self.calls.append(
            {
                "T": T,
                "N": N,
                "H": H,
                "W": W,
                "device": video.device.type,
                "param_device": self.model.log_stretch.device.type,
                "probe_dtype": probe.dtype,
                "query_t": queries[0, :, 0].tolist(),
            }
        )
        gray = video[:, :, 0].reshape(B * T, 1, H, W)
        img = F.interpolate(gray, INTERP, mode="bilinear", align_corners=True)
        img = img.reshape(B, T, *INTERP)
        scale = video.new_tensor([(INTERP[1] - 1) / (W - 1), (INTERP[0] - 1) / (H - 1)])
        vv, uu = torch.meshgrid(
            torch.arange(INTERP[0], device=video.device, dtype=torch.float64),
            torch.arange(INTERP[1], device=video.device, dtype=torch.float64),
            indexing="ij",
        )
        tracks, vis = [], []
        for b in range(B):
            weight = (img[b, 0].double() - 128).clamp(min=0)
            if weight.sum() > 0:
                a = torch.stack([(weight * uu).sum(), (weight * vv).sum()]) / weight.sum()
            else:
                a = torch.tensor([(INTERP[1] - 1) / 2, (INTERP[0] - 1) / 2], dtype=torch.float64)
            uq = queries[b, :, 1:].double() * scale.double()  # (N, 2) model coordinates
            k = (
                torch.arange(T, device=video.device, dtype=torch.float64)[:, None]
                - queries[b, :, 0].double()
            )
            stretch = torch.exp(self.model.log_stretch.double()[None, None, :] * k[..., None])
            u = a + stretch * (uq - a)  # (T, N, 2)
            grid = torch.stack(
                [2 * u[..., 0] / (INTERP[1] - 1) - 1, 2 * u[..., 1] / (INTERP[0] - 1) - 1], -1
            )
            value = F.grid_sample(
                img[b][:, None], grid[:, None].float(), mode="bilinear", align_corners=True
            )[:, 0, 0]  # (T, N), zero outside the frame
            tracks.append((u / scale.double()).float())
            vis.append(value)
        tracks, value = torch.stack(tracks), torch.stack(vis)
        if self.mode == "bool":
            return tracks, value >= 32
        prob = (value / 64).clamp(max=1)
        if self.mode == "prob":
            return tracks, prob
        return tracks, prob, torch.full_like(prob, 0.9)
