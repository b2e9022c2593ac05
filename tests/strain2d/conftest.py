import numpy as np
import pytest

from sample_data_synth import make_case, write_video


@pytest.fixture(scope="session")
def small_case(tmp_path_factory):
    """A 200 px, 6-frame equibiaxial video as AVI and TIFF, with its ground truth."""
    folder = tmp_path_factory.mktemp("small")
    video = make_case("equibiaxial", size=200, n_frames=6, rng=1)
    write_video(video.frames, folder / "eq.avi")
    write_video(video.frames, folder / "eq.tif")
    video.truth.save(folder / "eq_truth.json")
    return folder, video


@pytest.fixture(scope="session")
def paper_equibiaxial(tmp_path_factory):
    """The paper's equibiaxial case at full size (800 px, 31 frames) as a lossless AVI."""
    folder = tmp_path_factory.mktemp("paper")
    video = make_case("equibiaxial", size=800, n_frames=31, rng=0)
    write_video(video.frames, folder / "equibiaxial.avi")
    return folder / "equibiaxial.avi", video


@pytest.fixture
def smooth_frames():
    rng = np.random.default_rng(0)
    from scipy import ndimage

    base = ndimage.gaussian_filter(rng.uniform(0, 255, (5, 48, 64)), (0, 2, 2))
    return np.clip(base * 3 - 250, 0, 255).astype(np.uint8)
