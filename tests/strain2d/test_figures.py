import numpy as np
from matplotlib.image import imread

from strain2d.figures import plot_strain_maps, plot_tracked_grid
from strain2d.pipeline import strain_from_tracks
from strain2d.tracks import Tracks


def test_figures_render_with_lost_points_and_uniform_fields(tmp_path):
    ref = np.stack(np.meshgrid(np.linspace(20, 80, 4), np.linspace(20, 80, 4)), -1).reshape(-1, 2)
    pos = np.stack([ref, 50 + (ref - 50) * 1.2])  # uniform field: constant contour values
    vis = np.ones((2, 16), bool)
    vis[1, 0] = False
    tracks = Tracks(pos, vis, np.ones((2, 16)))
    field = strain_from_tracks(tracks)
    image = np.random.default_rng(0).uniform(0, 255, (100, 100))
    plot_tracked_grid(tmp_path / "grid.png", image, image, tracks, field.triangles)
    plot_strain_maps(tmp_path / "maps.png", image, field, 1)
    plot_strain_maps(tmp_path / "maps.svg", image, field, 1, components=("E1",))
    for name in ("grid.png", "maps.png"):
        img = imread(tmp_path / name)
        assert img.shape[0] > 300 and img.shape[1] > 600
        assert img[..., :3].std() > 0.05  # not blank
    assert (tmp_path / "maps.svg").read_text().startswith("<?xml")
