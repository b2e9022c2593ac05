"""Array aliases and option literals shared by the kinematics modules."""

from __future__ import annotations

from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.floating]
IntArray = npt.NDArray[np.integer]
BoolArray = npt.NDArray[np.bool_]

StrainMeasure = Literal["green_lagrange", "euler_almansi", "logarithmic"]
NodalMethod = Literal["area"]
