import numpy as np
import pytest

from sample_data_synth import make_case
from strain2d import track
from strain2d.errors import InputError
from strain2d.pipeline import strain_from_tracks
from strain2d.trackers.dic import track_dic
from tests.strain2d import icgn_oracle
from tests.tolerances import DIC_QUICK_STRAIN_RMSE, DIC_QUICK_TRACK_RMSE_PX


def _rmse(tracks, video, points):
    last = video.truth.n_frames - 1
    err = tracks.positions[-1] - video.truth.positions(points, last)
    return np.sqrt(np.mean(np.sum(err**2, axis=1)))


@pytest.mark.parametrize("case", ["equibiaxial", "rotation", "shear", "tissue"])
def test_dic_tracks_the_paper_cases(case):
    video = make_case(case, size=400, n_frames=11, rng=7)
    points = video.truth.grid((7, 7))
    tracks = track(video.frames, points, tracker="dic")
    assert tracks.visible.all()
    assert _rmse(tracks, video, points) < DIC_QUICK_TRACK_RMSE_PX
    field = strain_from_tracks(tracks, grid_shape=(7, 7))
    error = field.nodal_E[-1] - video.truth.strain(points, 10)
    assert np.sqrt(np.mean(error**2, axis=0)).max() < DIC_QUICK_STRAIN_RMSE
    assert tracks.quality[-1].min() > 0.9


def test_dic_ignores_brightness_and_contrast_changes():
    video = make_case("rotation", size=300, n_frames=6, rng=8)
    points = video.truth.grid((5, 5))
    gain = np.linspace(1.0, 0.6, 6)[:, None, None]
    dimmed = video.frames * gain + np.linspace(0, 40, 6)[:, None, None]
    plain = track(video.frames, points, tracker="dic")
    changed = track(dimmed, points, tracker="dic")
    assert changed.visible.all()
    assert _rmse(changed, video, points) < DIC_QUICK_TRACK_RMSE_PX
    np.testing.assert_allclose(changed.positions, plain.positions, atol=0.01)


@pytest.mark.parametrize("tracker", ["dic", "gdic"])
def test_flags_occluded_and_blank_points_and_recovers_after_occlusion(tracker):
    """Both correlation trackers: what cannot be seen is flagged, never invented."""
    video = make_case("shear", size=300, n_frames=10, rng=9)
    frames = video.frames.astype(float).copy()
    points = video.truth.grid((3, 3))  # spaced so each patch hides one subset only
    true = video.truth.positions(points)
    # a blank patch appears under point 0 from frame 3 on (texture lost for good)
    x, y = np.rint(true[3:, 0]).astype(int).T
    for k, (xi, yi) in enumerate(zip(x, y, strict=True), start=3):
        frames[k, yi - 25 : yi + 26, xi - 25 : xi + 26] = 128.0
    # an occluder hides point 4 on frames 4-5 only
    for k in (4, 5):
        xi, yi = np.rint(true[k, 4]).astype(int)
        frames[k, yi - 20 : yi + 21, xi - 20 : xi + 21] = 255.0
    tracks = track(frames, points, tracker=tracker)
    assert not tracks.visible[3:, 0].any()
    assert (tracks.quality[3:, 0] == 0).all()
    if tracks.uncertainty is not None:  # no uncertainty for a position it did not measure
        assert np.isnan(tracks.uncertainty[3:, 0]).all()
    assert not tracks.visible[4:6, 4].any()
    assert tracks.visible[6:, 4].all()  # found again once the occluder has gone
    err = np.linalg.norm(tracks.positions[-1, 4] - true[-1, 4])
    assert err < DIC_QUICK_TRACK_RMSE_PX
    others = np.setdiff1d(np.arange(9), [0, 4])
    assert tracks.visible[:, others].all()


def test_dic_integer_search_catches_a_sudden_jump():
    from scipy import ndimage

    rng = np.random.default_rng(10)
    big = ndimage.gaussian_filter(rng.uniform(0, 255, (360, 360)), 2.0)
    shifts = [0, 1, 2, 3, 21, 22]  # the 18 px jump defeats the velocity prediction
    frames = np.stack([ndimage.shift(big, (0, s), order=3)[30:330, 30:330] for s in shifts])
    points = np.array([[100.0, 100], [150, 120], [120, 180], [180, 170]])
    tracks = track(frames, points, tracker="dic", options={"subset": 41})
    assert tracks.visible.all()
    np.testing.assert_allclose(tracks.positions[-1, :, 0] - points[:, 0], 22, atol=0.05)


def test_dic_incremental_reference_updates():
    video = make_case("equibiaxial", size=300, n_frames=8, rng=11)
    points = video.truth.grid((4, 4))
    tracks = track(video.frames, points, tracker="dic", options={"zncc_min": 0.5})
    forced = track(
        video.frames, points, tracker="dic", options={"zncc_min": 0.5, "update_below": 0.9999}
    )
    assert sum(tracks.meta["reference_updates"]) == 0
    assert sum(forced.meta["reference_updates"]) >= 16
    assert forced.visible.all()
    # updating the reference every frame accumulates error, but only a little
    assert _rmse(forced, video, points) < 3 * DIC_QUICK_TRACK_RMSE_PX


def test_dic_bad_options():
    frames = np.zeros((3, 60, 60))
    pts = np.array([[20.0, 20], [40, 20], [20, 40]])
    for options, match in (
        ({"subset": 30}, "odd"),
        ({"subset": 61}, "smaller"),
        ({"zncc_min": 2.0}, "between"),
    ):
        with pytest.raises(InputError, match=match):
            track(frames, pts, tracker="dic", options=options)


def test_compiled_kernel_equals_the_numpy_oracle():
    from strain2d.trackers import dic

    video = make_case("shear", size=300, n_frames=3, rng=12)
    points = video.truth.grid((5, 5))
    corr = dic._Correlator(31, 30, 1e-3, 0.75)
    ref = corr.reference(dic._coefficients(video.frames[0]), points, 0)
    coeff = dic._coefficients(video.frames[2])
    guess = np.zeros((25, 6))
    guess[:, :2] = video.truth.positions(points, 2) - points + 0.4  # a start 0.4 px off
    for idx in (np.arange(25), np.array([3, 7, 20])):
        fast = corr.match(coeff, ref, idx, guess[idx])
        slow = icgn_oracle.match_numpy(corr, coeff, ref, idx, guess[idx])
        np.testing.assert_allclose(fast[0], slow[0], atol=1e-10)
        np.testing.assert_allclose(fast[1], slow[1], atol=1e-12)
        np.testing.assert_array_equal(fast[2], slow[2])
        assert fast[2].all()


def test_compiled_kernel_takes_the_warp_order_from_the_parameters():
    from strain2d.trackers._icgn_kernel import icgn

    # one 3 x 3 subset at (10, 10) of a 20 x 20 frame
    frame_and_subset = (np.zeros((20, 20)), np.full((1, 2), 10.0), np.zeros((1, 9)), np.ones(1))
    offsets_and_options = (np.zeros(9), np.zeros(9), 1, np.full(1, 1e-3), 30, 0.75)
    with pytest.raises(ValueError, match=r"6 \(affine\) or 12 \(quadratic\)"):
        icgn(*frame_and_subset, np.zeros((1, 8, 9)), np.zeros((1, 8)), *offsets_and_options)
    with pytest.raises(ValueError, match="one row per warp parameter"):
        icgn(*frame_and_subset, np.zeros((1, 6, 9)), np.zeros((1, 12)), *offsets_and_options)


@pytest.mark.parametrize("shape", [(97, 131), (300, 65), (1, 50), (50, 1), (2, 3), (1, 1)])
def test_coefficients_equal_scipys_spline_filter(shape):
    """The compiled prefilter against SciPy's, column blocks of 64 and a partial one, and
    lines of one and two values."""
    from scipy import ndimage

    from strain2d.trackers import dic

    image = np.random.default_rng(13).uniform(0, 255, shape)
    np.testing.assert_allclose(
        dic._coefficients(image),
        ndimage.spline_filter(image, order=3, mode="mirror"),
        atol=1e-9,
    )


def test_coefficients_do_not_depend_on_the_thread_count():
    import numba

    from strain2d.trackers import dic
    from strain2d.trackers._threads import using_threads

    image = np.random.default_rng(5).uniform(0, 255, (130, 200))
    results = []
    for n in sorted({1, numba.config.NUMBA_NUM_THREADS}):
        with using_threads(n):
            results.append(dic._coefficients(image))
    for other in results[1:]:
        np.testing.assert_array_equal(other, results[0])


@pytest.mark.parametrize("k", [3, 4, 8, 9])
def test_nanmedian_equals_numpys(k):
    """The median test's one-sort median: NumPy's nanmedian to the bit, odd and even
    counts of valid neighbours, NaNs anywhere in the row."""
    from strain2d.trackers.dic import _nanmedian

    rng = np.random.default_rng(k)
    values = rng.normal(size=(2000, k, 2))
    gone = rng.random((2000, k)) < 0.4
    gone[np.arange(2000), rng.integers(0, k, 2000)] = False  # one valid value at least
    values[gone] = np.nan
    np.testing.assert_array_equal(_nanmedian(values), np.nanmedian(values, axis=1))


def test_false_matches_are_caught_by_the_median_test():
    """Small subsets and 7 px first steps invite false matches (once locked in by a
    reference update): the normalized median test sends them back to their neighbours."""
    video = make_case("equibiaxial", size=400, n_frames=11, rng=0)
    points = video.truth.grid((15, 15))
    tracks = track(video.frames, points, tracker="dic", options={"subset": 15})
    err = np.linalg.norm(tracks.positions[-1] - video.truth.positions(points, 10), axis=1)
    assert err.max() < 0.5
    assert np.sqrt(np.mean(err**2)) < 0.1


def test_median_outlier_test():
    from strain2d.trackers.dic import _median_outliers

    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2) * 20
    step = 0.05 * g  # a smooth (stretching) motion field
    step[12] += [3.0, 0.0]  # one false match in the middle
    from scipy.spatial import cKDTree

    near = cKDTree(g).query(g, 9)[1][:, 1:]
    out = _median_outliers(step, np.ones(25, bool), near)
    assert out[12] and out.sum() == 1


def test_quadratic_kernel_equals_the_numpy_oracle_on_a_curved_field():
    from strain2d.trackers import dic

    video = make_case("fold", size=300, n_frames=3, rng=14)
    points = video.truth.grid((5, 5))
    corr = dic._Correlator(31, 30, 1e-3, 0.75, order=2)
    ref = corr.reference(dic._coefficients(video.frames[0]), points, 0)
    coeff = dic._coefficients(video.frames[2])
    guess = np.zeros((25, 12))
    guess[:, :2] = video.truth.positions(points, 2) - points + 0.3
    fast = corr.match(coeff, ref, np.arange(25), guess)
    slow = icgn_oracle.match_numpy(corr, coeff, ref, np.arange(25), guess)
    np.testing.assert_allclose(fast[0], slow[0], atol=1e-10)
    np.testing.assert_array_equal(fast[2], slow[2])
    assert fast[2].all()


def test_second_order_warp_matrix():
    """The 6 x 6 form maps (dx^2, dx dy, dy^2, dx, dy, 1) to the warped offsets, and
    composes like the affine warp where the second-order terms vanish."""
    from strain2d.trackers.dic import _warp

    rng = np.random.default_rng(0)
    p = rng.normal(scale=0.05, size=(4, 12))
    dx, dy = rng.uniform(-15, 15, (2, 9))
    monomials = np.stack([dx * dx, dx * dy, dy * dy, dx, dy, np.ones_like(dx)])
    mapped = icgn_oracle.matrix2(p) @ monomials  # (4, 6, 9)
    x, y = _warp(np.zeros((4, 2)), p, dx, dy)
    np.testing.assert_allclose(mapped[:, 3], x, atol=1e-12)
    np.testing.assert_allclose(mapped[:, 4], y, atol=1e-12)
    np.testing.assert_allclose(icgn_oracle.params2(icgn_oracle.matrix2(p)), p, atol=1e-15)
    p[:, 6:] = 0
    q = rng.normal(scale=0.05, size=(4, 12))
    q[:, 6:] = 0
    affine = icgn_oracle.compose_inverse(p[:, :6], q[:, :6])
    quad = icgn_oracle.compose_inverse(p, q)
    np.testing.assert_allclose(quad[:, :6], affine, atol=1e-12)
    np.testing.assert_allclose(quad[:, 6:], 0, atol=1e-12)


@pytest.mark.parametrize("case", ["gaussian", "fold"])
def test_quadratic_shape_function_beats_affine_on_curved_fields(case):
    video = make_case(case, size=400, n_frames=11, rng=15)
    points = video.truth.grid((15, 15))
    rmse = {}
    for shape_function in ("affine", "quadratic"):
        tracks = track(
            video.frames, points, tracker="dic", options={"shape_function": shape_function}
        )
        assert tracks.visible.all()
        rmse[shape_function] = _rmse(tracks, video, points)
    assert rmse["quadratic"] < 0.06
    assert rmse["quadratic"] < 0.4 * rmse["affine"]


def test_quadratic_shape_function_on_the_paper_cases():
    video = make_case("equibiaxial", size=400, n_frames=11, rng=16)
    points = video.truth.grid((15, 15))
    tracks = track(video.frames, points, tracker="dic", options={"shape_function": "quadratic"})
    assert tracks.visible.all()
    assert _rmse(tracks, video, points) < 2 * DIC_QUICK_TRACK_RMSE_PX
    with pytest.raises(InputError, match="shape-function"):
        track(video.frames, points, tracker="dic", options={"shape_function": "cubic"})


@pytest.mark.parametrize(
    ("points", "options"),
    [([[100.0, 100.0]], {}), ([[100.0, 100.0], [60.0, 60.0], [140.0, 140.0]], {"neighbours": 0})],
)
def test_a_point_without_neighbours_whose_texture_vanishes_is_lost(points, options):
    """A single point, or no neighbours asked for: a failed match is lost, not a crash."""
    video = make_case("equibiaxial", size=200, n_frames=4, rng=0)
    frames = np.array(video.frames, dtype=float)
    frames[1:, 80:130, 80:130] = frames[0, 80:130, 80:130].mean()
    tracks = track_dic(frames, np.array(points), **options)
    assert not tracks.visible[1:, 0].any()
    assert tracks.visible[:, 1:].all()
