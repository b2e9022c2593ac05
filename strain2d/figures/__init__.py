"""Figures of 2D runs and studies: grids, strain maps, crosses, curves, violins, animations.

Per run (the source paper's Figs. 10-15 for one specimen): the tracked grid
(:func:`plot_tracked_grid`), contour maps of strain components on the
deformed configuration (:func:`plot_strain_maps`, :func:`plot_strain_maps_at`),
principal strain directions as crosses (:func:`plot_principal_crosses`), the
mean +/- spatial SD of each component over time (:func:`plot_strain_curves`),
violins of the nodal values at one frame (:func:`plot_strain_violins`) and an
MP4 or GIF of the strain field on the video (:func:`write_strain_animation`).
Per study (several specimens side by side): :func:`plot_study_curves`,
:func:`plot_study_violins` and the specimen-level paired plot
:func:`plot_specimen_means`.

Conventions
-----------
* Built on :class:`matplotlib.figure.Figure` directly, never pyplot, so
  importing or calling this module does not change the global matplotlib
  state or backend.  Functions named ``plot_*`` that take a path save and
  return the written paths; the others return the ``Figure`` and
  :func:`save_figure` writes it in any number of formats (PNG, SVG, PDF).
* Image axes are in pixels with y pointing down, as in the images (x =
  column, y = row, the centre of the top-left pixel at (0, 0)).
* Strain is Green-Lagrange, dimensionless.  Strain colour maps are diverging
  (``RdBu_r``: red = stretch, blue = shortening) with zero white: the colour
  of a value depends only on its sign and magnitude relative to the larger
  end of the range, so a range that does not reach zero uses one half of the
  map only, and a range such as (-0.3, 0.01) gives a barely pink top instead
  of a white middle at -0.15.
* :func:`strain_limits` gives colour limits shared by every frame, so maps at
  different frames and the animation can be compared by eye.

Where they live: the figures live in private modules by concern and are imported from here:
``_maps`` (maps, tracked grid and error maps over a frame), ``_crosses``,
``_curves``, ``_cycles`` (repeated contractions),
``_violins``, ``_study`` (the study figures), ``_animation``
(the video writer), ``_save`` (:func:`save_figure`), ``_style`` (labels,
colours, colour scales, :func:`strain_limits`), ``_checks`` and ``_pool``
(the worker processes that draw a run's figures while it writes the rest).
"""

from strain2d.figures._animation import write_strain_animation
from strain2d.figures._crosses import plot_principal_crosses, principal_noise_floor
from strain2d.figures._curves import mean_strain_curves, plot_strain_curves
from strain2d.figures._cycles import plot_cycles
from strain2d.figures._maps import (
    plot_strain_errors,
    plot_strain_maps,
    plot_strain_maps_at,
    plot_tracked_grid,
    strain_maps_figure,
)
from strain2d.figures._quality import plot_run_quality, run_quality
from strain2d.figures._save import save_figure
from strain2d.figures._signals import plot_strain_and_signals
from strain2d.figures._study import plot_specimen_means, plot_study_curves, plot_study_violins
from strain2d.figures._style import strain_limits
from strain2d.figures._violins import format_p, plot_strain_violins

__all__ = [
    "format_p",
    "mean_strain_curves",
    "plot_cycles",
    "plot_principal_crosses",
    "plot_run_quality",
    "plot_specimen_means",
    "plot_strain_and_signals",
    "plot_strain_curves",
    "plot_strain_errors",
    "plot_strain_maps",
    "plot_strain_maps_at",
    "plot_strain_violins",
    "plot_study_curves",
    "plot_study_violins",
    "plot_tracked_grid",
    "principal_noise_floor",
    "run_quality",
    "save_figure",
    "strain_limits",
    "strain_maps_figure",
    "write_strain_animation",
]
