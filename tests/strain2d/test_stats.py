import numpy as np
import pytest

from strain2d.errors import InputError
from strain2d.stats import contraction_endpoint, morans_i, paired_node_tests


@pytest.mark.parametrize("end", [5, 17, 29])
def test_endpoint_of_a_ramp_that_holds(end):
    t = np.arange(31.0)
    ramp = np.minimum(t, end) / end
    curve = np.column_stack([-0.3 * ramp, -0.1 * ramp])
    assert contraction_endpoint(curve) == end
    # with noise well under the tolerance, and with real times
    noisy = curve + np.random.default_rng(0).normal(0, 2e-4, curve.shape)
    assert contraction_endpoint(noisy, times=t / 25.0) == end


def test_endpoint_of_a_video_that_ends_while_contracting():
    assert contraction_endpoint(-0.01 * np.arange(12.0)) == 11


def test_endpoint_checks_its_input():
    with pytest.raises(InputError):
        contraction_endpoint(np.zeros(2))
    with pytest.raises(InputError):
        contraction_endpoint(np.zeros(5), times=np.array([0, 1, 1, 2, 3.0]))
    assert contraction_endpoint(np.zeros(5)) == 0


def _grid(n=7):
    y, x = np.mgrid[0:n, 0:n] * 10.0
    return np.column_stack([x.ravel(), y.ravel()])


def test_a_real_anisotropy_is_significant_and_its_effect_size_interval_excludes_zero():
    rng = np.random.default_rng(1)
    eyy = rng.normal(-0.20, 0.03, 49)
    exx = eyy - 0.05 + rng.normal(0, 0.02, 49)  # longitudinal contraction stronger
    r = paired_node_tests(exx, eyy, positions=_grid())
    assert r["n"] == 49
    assert r["t_p"] < 1e-6 and r["wilcoxon_p"] < 1e-6
    assert r["mean_difference"] == pytest.approx(-0.05, abs=0.01)
    lo, hi = r["cohens_dz_ci"]
    assert lo < r["cohens_dz"] < hi < 0
    assert "node-level" in r["note"]


def test_no_anisotropy_is_not_significant():
    rng = np.random.default_rng(2)
    eyy = rng.normal(-0.20, 0.03, 49)
    exx = eyy + rng.normal(0, 0.02, 49)
    r = paired_node_tests(exx, eyy)
    assert r["t_p"] > 0.05 and r["wilcoxon_p"] > 0.05
    lo, hi = r["mean_difference_ci"]
    assert lo < 0 < hi


def test_morans_i_sees_a_smooth_field_and_not_noise():
    pos = _grid(9)
    smooth = np.sin(pos[:, 0] / 30.0) + np.cos(pos[:, 1] / 30.0)
    i, p = morans_i(smooth, pos, permutations=199)
    assert i > 0.5 and p < 0.01
    noise = np.random.default_rng(3).normal(size=len(pos))
    i, p = morans_i(noise, pos, permutations=199)
    assert abs(i) < 0.2 and p > 0.05
    r = paired_node_tests(smooth + 0.1, smooth * 0 + 0.0, positions=pos)
    assert "spatially correlated" in r["note"]


def test_paired_tests_check_their_input():
    with pytest.raises(InputError):
        paired_node_tests(np.zeros(5), np.zeros(4))
    with pytest.raises(InputError):
        paired_node_tests(np.array([1.0, np.nan]), np.array([0.0, 0.0]))


def test_paired_tests_of_identical_components_warn_of_nothing():
    """No deformation: Exx = Eyy to round-off at every node (NumPy's warnings are errors here)."""
    rng = np.random.default_rng(3)
    exx = rng.normal(0, 1e-16, 40)
    for b in (exx, exx + rng.normal(0, 1e-30, 40)):
        result = paired_node_tests(exx, b, positions=rng.uniform(0, 100, (40, 2)))
        assert np.isnan(result["t"]) and np.isnan(result["t_p"])
        assert np.isnan(result["cohens_dz"]) and np.isnan(result["cohens_dz_ci"]).all()
