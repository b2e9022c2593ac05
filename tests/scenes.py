"""Stand-in stereo scenes for tests: what ``sample_data_synth.patch`` needs of a scene."""

import numpy as np


class SphereCap:
    """A sphere of radius 60 mm whose apex faces the cameras at 450 mm: material points
    ``(X, Y)`` mm lie at ``(X, Y, z)``, the same at every frame."""

    radius = 60.0

    def positions(self, X, frame):
        X = np.asarray(X, float).reshape(-1, 2)
        return np.column_stack([X, 390.0 + np.sqrt(self.radius**2 - np.sum(X**2, axis=1))])

    def gradient(self, X, frame):
        X = np.asarray(X, float).reshape(-1, 2)
        s = np.sqrt(self.radius**2 - np.sum(X**2, axis=1))
        F = np.zeros((len(X), 3, 2))
        F[:, 0, 0] = F[:, 1, 1] = 1.0
        F[:, 2, 0], F[:, 2, 1] = -X[:, 0] / s, -X[:, 1] / s
        return F
