"""Repeated contractions in 2D runs: :mod:`surface_strain.cycles`, which 2D and 3D runs share.

``strain2d analyze`` finds a run's cycles with these functions (see
``docs/cycles.md``); they are here under strain2d's name too.
"""

from surface_strain import (
    CYCLE_COMPONENTS,
    Cycle,
    cycle_statistics,
    detect_cycles,
    find_run_cycles,
    mean_strain_noise,
    write_cycles_csv,
)

__all__ = [
    "CYCLE_COMPONENTS",
    "Cycle",
    "cycle_statistics",
    "detect_cycles",
    "find_run_cycles",
    "mean_strain_noise",
    "write_cycles_csv",
]
