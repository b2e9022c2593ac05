"""Run folders read back, and study statistics against known specimen-level effects."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from strain2d.errors import InputError
from strain2d.export import write_strain_nodes_csv
from strain2d.grid import make_grid
from strain2d.run import load_run
from strain2d.study import (
    load_specimens,
    mixed_model,
    plain_summary,
    read_manifest,
    specimen_tests,
    study_statistics,
)
from surface_strain import compute_strain, grid_triangles, nodal_scalars
from tests.tolerances import STUDY_FIELD_MEAN_STRAIN
from tissue_core.jsonio import write_json


def _field(lx: float, ly: float, *, rng, n_frames: int = 12, endpoint: int = 8, noise=0.05):
    """A 7x7 grid contracting by (lx, ly) until ``endpoint``, with a smooth bump and noise."""
    ref = make_grid((400, 400), shape=(7, 7), roi=(100, 100, 300, 300))
    c = np.array([200.0, 200.0])
    phase = rng.uniform(0, 2 * np.pi)
    positions = []
    for k in range(n_frames):
        s = min(k / endpoint, 1.0)
        A = np.diag([1 + s * (lx - 1), 1 + s * (ly - 1)])
        x = c + (ref - c) @ A.T
        # a smooth heterogeneity: nodal strains vary over the field as in tissue
        x[:, 0] += s * 3.0 * np.sin((ref[:, 1] - 100) / 60 + phase)
        x = x + (rng.normal(0, noise, x.shape) if k else 0)
        positions.append(x)
    positions = np.array(positions)
    return compute_strain(ref, positions, grid_triangles(7, 7))


def _write_run(folder, field, *, endpoint: int | None = None, fps=None) -> None:
    folder.mkdir(parents=True)
    write_strain_nodes_csv(folder / "strain_nodes.csv", field)
    summary = {
        "software": {"name": "strain2d", "version": "test"},
        "source": {"frames_used": field.n_frames},
        "time_axis": {"fps": fps},
    }
    if endpoint is not None:
        summary["contraction_endpoint"] = {"frame": endpoint, "source": "detected"}
    write_json(folder / "summary.json", summary)


@pytest.fixture(scope="module")
def study_dir(tmp_path_factory):
    """Two groups of 5 specimens: Exx shortens 0.08 more than Eyy in one, equally in the other."""
    root = tmp_path_factory.mktemp("study")
    rng = np.random.default_rng(7)
    rows = ["run,specimen,group"]
    truth = {}
    for group, (mx, my) in {"anisotropic": (0.80, 0.88), "isotropic": (0.84, 0.84)}.items():
        for i in range(5):
            lx, ly = mx + rng.normal(0, 0.012), my + rng.normal(0, 0.012)
            name = f"{group[:3]}{i}"
            _write_run(root / "runs" / name, _field(lx, ly, rng=rng), endpoint=8)
            rows.append(f"runs/{name},{name},{group}")
            truth[name] = (0.5 * (lx**2 - 1), 0.5 * (ly**2 - 1))
    (root / "manifest.csv").write_text("\n".join(rows) + "\n")
    return root, truth


def test_load_run_reads_back_the_nodal_field(tmp_path):
    field = _field(0.8, 0.9, rng=np.random.default_rng(0))
    _write_run(tmp_path / "r", field, endpoint=8, fps=5.0)
    run = load_run(tmp_path / "r")
    assert run.n_frames == field.n_frames and run.n_points == 49
    assert run.endpoint == 8 and run.endpoint_source == "detected"
    np.testing.assert_allclose(run.times, np.arange(field.n_frames) / 5.0)
    assert run.time_unit == "s"
    ref = nodal_scalars(field)
    for key in ("Exx", "Eyy", "E1", "J"):
        np.testing.assert_allclose(run.nodal[key], ref[key], rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(run.positions, field.points, atol=1e-6)


def test_load_run_without_endpoint_uses_the_last_frame(tmp_path):
    _write_run(tmp_path / "r", _field(0.8, 0.9, rng=np.random.default_rng(0)))
    run = load_run(tmp_path / "r")
    assert run.endpoint == run.n_frames - 1 and run.endpoint_source == "last frame"


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d: (d / "summary.json").unlink(), "summary.json is missing"),
        (lambda d: (d / "strain_nodes.csv").unlink(), "strain_nodes.csv is missing"),
        (lambda d: (d / "summary.json").write_text("{not json"), "cannot be read"),
        (lambda d: (d / "summary.json").write_text("[1, 2]"), "not a strain2d summary"),
        (lambda d: (d / "strain_nodes.csv").write_text(""), "is empty"),
        (lambda d: (d / "strain_nodes.csv").write_text("a,b\n1,2\n"), "lacks the columns"),
        (
            lambda d: (d / "strain_nodes.csv").write_text(
                "\n".join((d / "strain_nodes.csv").read_text().splitlines()[:-7]) + "\n"
            ),
            "incomplete",
        ),
        (
            lambda d: (d / "strain_nodes.csv").write_text(
                (d / "strain_nodes.csv").read_text().replace("\n3,", "\n3,x", 1)
            ),
            "not a number",
        ),
        (lambda d: (d / "strain_nodes.csv").write_bytes(b"\xff\xfe\x00garbage"), "not a text"),
        (
            lambda d: (d / "summary.json").write_text(
                json.dumps({"software": {}, "contraction_endpoint": {"frame": 99}})
            ),
            "contraction_endpoint.frame",
        ),
        (
            lambda d: (d / "summary.json").write_text(
                json.dumps({"software": {}, "source": {"frames_used": 3}})
            ),
            "says 3 frames",
        ),
    ],
)
def test_corrupt_run_folders_give_one_clear_error(tmp_path, damage, message):
    _write_run(tmp_path / "r", _field(0.8, 0.9, rng=np.random.default_rng(0)), endpoint=8)
    damage(tmp_path / "r")
    with pytest.raises(InputError, match=message):
        load_run(tmp_path / "r")


def test_missing_run_folder(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_run(tmp_path / "nope")


def test_manifest_paths_groups_and_endpoint_override(study_dir, tmp_path):
    root, _ = study_dir
    entries = read_manifest(root / "manifest.csv")
    assert len(entries) == 10
    assert entries[0]["run"] == root / "runs" / "ani0"
    assert {e["group"] for e in entries} == {"anisotropic", "isotropic"}
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"run,endpoint\n{root / 'runs' / 'ani0'},5\n")
    (spec,) = load_specimens(read_manifest(manifest))
    assert spec.name == "ani0" and spec.endpoint == 5
    assert spec.endpoint_source == "given in the manifest"
    manifest.write_text(f"run,endpoint\n{root / 'runs' / 'ani0'},50\n")
    with pytest.raises(InputError, match="outside frames"):
        load_specimens(read_manifest(manifest))
    for bad in ("five", "-1"):  # frames count from the reference, never from the end
        manifest.write_text(f"run,endpoint\n{root / 'runs' / 'ani0'},{bad}\n")
        with pytest.raises(InputError, match="frame number from 0"):
            read_manifest(manifest)
    manifest.write_text("specimen\nA\n")
    with pytest.raises(InputError, match="'run' column"):
        read_manifest(manifest)
    manifest.write_text(f"run,specimen\n{root / 'runs' / 'ani0'},A\n{root / 'runs' / 'ani1'},A\n")
    with pytest.raises(InputError, match="unique"):
        load_specimens(read_manifest(manifest))


def test_study_finds_the_effect_only_where_it_exists(study_dir):
    root, truth = study_dir
    specimens = load_specimens(read_manifest(root / "manifest.csv"))
    stats = study_statistics(specimens, n_boot=200)
    # the specimen means are the known strains (the bump and the noise average out)
    for row in stats["specimens"]:
        exx, eyy = truth[row["specimen"]]
        assert abs(row["mean_Exx"] - exx) < STUDY_FIELD_MEAN_STRAIN
        assert abs(row["mean_Eyy"] - eyy) < STUDY_FIELD_MEAN_STRAIN
    aniso, iso = stats["specimen_level"]["anisotropic"], stats["specimen_level"]["isotropic"]
    assert aniso["n"] == iso["n"] == 5
    expected = 0.5 * (0.80**2 - 0.88**2)  # -0.0672
    assert aniso["t_p"] < 0.001
    assert aniso["mean_difference_ci"][0] < expected < aniso["mean_difference_ci"][1]
    assert iso["t_p"] > 0.05
    assert iso["mean_difference_ci"][0] < 0 < iso["mean_difference_ci"][1]
    effects = {e["term"]: e for e in stats["mixed_model"]["effects"]}
    assert effects["mean difference, anisotropic"]["t_p"] < 0.001
    assert effects["mean difference, isotropic"]["t_p"] > 0.05
    assert abs(effects["mean difference, anisotropic"]["estimate"] - expected) < 0.01
    (contrast,) = stats["mixed_model"]["contrasts"]
    assert contrast["term"] == "isotropic - anisotropic" and contrast["t_p"] < 0.001
    assert stats["groups_compared"]["welch_p"] < 0.001
    assert stats["mixed_model"]["warnings"] == []
    text = " ".join(plain_summary(stats))
    assert "group anisotropic (5 specimens)" in text
    assert "p < 0.001: significant" in text and "not significant" in text
    assert "Exx is lower than Eyy: Exx shortens more" in text
    assert "node-level" in text.lower()


def test_node_level_tests_overstate_the_evidence(study_dir):
    """Within an isotropic specimen the node-level test can still come out 'significant';
    the specimen-level test is what decides, and the output says so."""
    root, _ = study_dir
    stats = study_statistics(load_specimens(read_manifest(root / "manifest.csv")), n_boot=200)
    for row in stats["specimens"]:
        node = row["node_level"]
        assert node["n"] == 49 and node["label"].startswith("node-level")
        assert "not" in node["note"]  # "...which they are not"
    # each isotropic specimen has its own small lx - ly; over 49 nodes that looks "significant"
    iso_nodes = [r["node_level"]["t_p"] for r in stats["specimens"] if r["group"] == "isotropic"]
    assert sum(p < 0.05 for p in iso_nodes) >= 3
    assert stats["specimen_level"]["isotropic"]["t_p"] > 0.05


def test_specimen_tests_against_scipy():
    from scipy import stats

    a = np.array([-0.20, -0.18, -0.22, -0.19, -0.21, -0.17])
    b = np.array([-0.10, -0.11, -0.09, -0.12, -0.10, -0.08])
    out = specimen_tests(a, b)
    t = stats.ttest_rel(a, b)
    assert out["t_p"] == pytest.approx(t.pvalue) and out["t"] == pytest.approx(t.statistic)
    assert out["wilcoxon_p"] == pytest.approx(2 / 64)  # all 6 differences negative
    lo, hi = out["mean_difference_ci"]
    assert lo < (a - b).mean() < hi
    one = specimen_tests(a[:1], b[:1])
    assert one["n"] == 1 and math.isnan(one["t_p"]) and math.isnan(one["mean_difference_ci"][0])


def test_mixed_model_recovers_known_variances():
    """d = mu + u_specimen + e with known mu, tau and sigma."""
    rng = np.random.default_rng(3)
    n_spec, n_node = 30, 49
    u = rng.normal(0, 0.02, n_spec)
    d = -0.05 + np.repeat(u, n_node) + rng.normal(0, 0.01, n_spec * n_node)
    spec = np.repeat([f"s{i}" for i in range(n_spec)], n_node)
    out = mixed_model(d, spec)
    (e,) = out["effects"]
    assert e["ci"][0] < -0.05 < e["ci"][1] and e["df"] == n_spec - 1
    assert out["specimen_variance"] == pytest.approx(0.02**2, rel=0.5)
    assert out["residual_variance"] == pytest.approx(0.01**2, rel=0.1)
    assert out["converged"] and 0.6 < out["icc"] < 0.95
    # the fixed effect's SE follows the specimen count, not the node count
    means = d.reshape(n_spec, n_node).mean(axis=1)
    assert e["se"] == pytest.approx(means.std(ddof=1) / np.sqrt(n_spec), rel=0.05)
    with pytest.raises(InputError, match="at least 2 specimens"):
        mixed_model(d[:49], spec[:49])


def test_study_arguments_are_checked(study_dir):
    root, _ = study_dir
    specimens = load_specimens(read_manifest(root / "manifest.csv"))
    with pytest.raises(InputError, match="unknown component"):
        study_statistics(specimens, a="Ezz")
    with pytest.raises(InputError, match="different components"):
        study_statistics(specimens, a="Exx", b="Exx")
    with pytest.raises(InputError, match="alpha"):
        study_statistics(specimens, alpha=1.5)
    with pytest.raises(InputError, match="at least one run"):
        load_specimens([])


def test_lost_nodes_without_positions_load(tmp_path):
    """Imported tracks may give a lost point no position at all; such a run is usable."""
    field = _field(0.8, 0.9, rng=np.random.default_rng(0))
    _write_run(tmp_path / "r", field, endpoint=8)
    csv_path = tmp_path / "r" / "strain_nodes.csv"
    lines = csv_path.read_text().splitlines()
    # node 3 lost (no position, no strain) from frame 5 on
    for i, line in enumerate(lines[1:], start=1):
        values = line.split(",")
        if int(values[0]) >= 5 and values[1] == "3":
            values[2:7] = ["nan", "nan", "nan", "nan", "0"]
            values[7:] = ["nan"] * len(values[7:])
            lines[i] = ",".join(values)
    csv_path.write_text("\n".join(lines) + "\n")
    run = load_run(tmp_path / "r")
    assert not run.visible[5, 3] and np.isnan(run.nodal["Exx"][8, 3])
    assert np.isfinite(run.nodal["Exx"][8, :3]).all()


@pytest.mark.parametrize(
    ("summary", "message"),
    [
        ({"software": {}, "source": "video"}, "'source' must be an object"),
        ({"software": {}, "contraction_endpoint": "frame 3"}, "must be an object"),
        ({"software": {}, "contraction_endpoint": {"frame": True}}, "contraction_endpoint"),
        ({"software": {}, "time_axis": {"fps": True}}, "fps must be a positive"),
        ({"software": {}, "source": {"frames_used": "12"}}, "frames_used must be a whole"),
        ({"software": "strain2d"}, "not a strain2d summary"),
    ],
)
def test_ill_typed_summaries_give_one_clear_error(tmp_path, summary, message):
    _write_run(tmp_path / "r", _field(0.8, 0.9, rng=np.random.default_rng(0)))
    (tmp_path / "r" / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(InputError, match=message):
        load_run(tmp_path / "r")


def test_node_table_with_bom_loads_and_header_only_is_refused(tmp_path):
    _write_run(tmp_path / "r", _field(0.8, 0.9, rng=np.random.default_rng(0)))
    nodes = tmp_path / "r" / "strain_nodes.csv"
    nodes.write_bytes(b"\xef\xbb\xbf" + nodes.read_bytes())
    assert load_run(tmp_path / "r").n_points == 49
    nodes.write_text(nodes.read_text(encoding="utf-8-sig").splitlines()[0] + "\n")
    with pytest.raises(InputError, match="has no rows"):  # and no warning (warnings are errors)
        load_run(tmp_path / "r")
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match="is not a folder"):
        load_run(tmp_path / "f")


def test_manifest_headers_are_matched_loosely_and_all_is_reserved(study_dir, tmp_path):
    root, _ = study_dir
    manifest = tmp_path / "m.csv"
    a, b = root / "runs" / "ani0", root / "runs" / "iso0"
    manifest.write_text(f" Run , Specimen , GROUP \n{a}, A , g1\n{b},B,g2\n")
    entries = read_manifest(manifest)
    assert [(e["specimen"], e["group"]) for e in entries] == [("A", "g1"), ("B", "g2")]
    manifest.write_text(f"run,group\n{root / 'runs' / 'ani0'},all\n")
    with pytest.raises(InputError, match="reserved"):
        read_manifest(manifest)


def test_a_specimen_without_values_is_left_out_by_name(study_dir, tmp_path):
    import shutil

    root, _ = study_dir
    empty = tmp_path / "empty"
    shutil.copytree(root / "runs" / "ani0", empty)
    lines = (empty / "strain_nodes.csv").read_text().splitlines()
    for i, line in enumerate(lines[1:], start=1):
        values = line.split(",")
        if values[0] == "8":
            values[7:] = ["nan"] * len(values[7:])
            lines[i] = ",".join(values)
    (empty / "strain_nodes.csv").write_text("\n".join(lines) + "\n")
    entries = [
        {"run": empty, "specimen": "E", "group": "g"},
        {"run": root / "runs" / "ani1", "group": "g"},
        {"run": root / "runs" / "ani2", "group": "g"},
        {"run": root / "runs" / "iso0", "group": "h"},
        {"run": root / "runs" / "iso1", "group": "h"},
    ]
    stats = study_statistics(load_specimens(entries), n_boot=100)
    assert stats["excluded"] == ["E"]
    assert stats["specimen_level"]["g"]["n"] == 2
    assert math.isfinite(stats["groups_compared"]["welch_p"])
    assert stats["mixed_model"]["n_specimens"] == 4
    text = " ".join(plain_summary(stats))
    assert "Left out (no node with both Exx and Eyy at the endpoint): E." in text
    # only one specimen with values: no model, said plainly
    stats = study_statistics(load_specimens(entries[:2]), n_boot=100)
    assert stats["mixed_model"] is None and "at least 2 specimens" in stats["mixed_model_note"]
    assert "No mixed-effects model" in " ".join(plain_summary(stats))


def test_summary_wording_is_neutral_for_other_components(study_dir):
    """J (an area ratio, about 0.7) against Exx: 'lower', never 'shortens'."""
    root, _ = study_dir
    entries = [{"run": root / "runs" / f"ani{i}"} for i in range(5)]
    stats = study_statistics(load_specimens(entries), a="Exx", b="J", n_boot=100)
    text = " ".join(plain_summary(stats))
    assert "Exx is lower than J)" in text and "shortens" not in text
    assert "model pools" not in text  # that explanation is for several groups


def test_single_group_gets_its_model_sentence(study_dir):
    root, _ = study_dir
    entries = [{"run": root / "runs" / f"ani{i}", "group": "only"} for i in range(5)]
    stats = study_statistics(load_specimens(entries), n_boot=100)
    text = " ".join(plain_summary(stats))
    assert "In group only (5 specimens)" in text and "The mixed-effects model" in text


def test_mixed_model_errors_are_input_errors():
    with pytest.raises(InputError, match="at least 2 nodes"):
        mixed_model(np.array([0.1, 0.2, 0.15]), np.array(["a", "b", "c"]))


# ------------------------------------------------------------------ study figures


def test_spread_is_the_least_squares_layout():
    """Labels at least ``gap`` apart: the known optimum, and scipy's on a random case."""
    from scipy.optimize import minimize

    from strain2d.figures._study import _spread

    assert _spread(np.array([0.0, 0.0, 5.0]), 1.0).tolist() == [-0.5, 0.5, 5.0]
    assert _spread(np.array([2.0, 0.0, 0.0]), 1.0).tolist() == [2.0, -0.5, 0.5]  # order kept
    assert _spread(np.array([0.0, 3.0]), 1.0).tolist() == [0.0, 3.0]  # far apart: untouched
    assert _spread(np.zeros(3), 1.0, 0.0, 10.0).tolist() == [0.0, 1.0, 2.0]  # floor at 0
    assert _spread(np.zeros(3), 1.0, 0.0, 1.0).tolist() == [-0.5, 0.5, 1.5]  # cannot fit: centred
    y = np.random.default_rng(3).normal(0, 1, 7)
    got = _spread(y, 0.8, -2.6, 2.6)  # 7 labels need 4.8 of the 5.2
    o = np.argsort(y)
    cons = [{"type": "ineq", "fun": lambda p, j=j: p[o[j + 1]] - p[o[j]] - 0.8} for j in range(6)]
    ref = minimize(lambda p: ((p - y) ** 2).sum(), y, constraints=cons,
                   bounds=[(-2.6, 2.6)] * 7, method="SLSQP", options={"ftol": 1e-12})  # fmt: skip
    assert ref.success
    np.testing.assert_allclose(got, ref.x, atol=1e-6)


@pytest.mark.parametrize("n", [4, 25])
def test_specimen_labels_never_overlap(n):
    """Specimens with nearly equal means: their names, as drawn, do not intersect."""
    from matplotlib.text import Text

    from strain2d.figures import plot_specimen_means

    rng = np.random.default_rng(n)
    table = [
        {"name": f"S{i:02d}", "group": "g" if i % 3 else "h",
         "Exx": -0.15 + rng.normal(0, 0.01), "Eyy": -0.1 + 1e-5 * i}
        for i in range(n)
    ]  # fmt: skip
    table[0]["Eyy"] = -0.05  # one far from the crowd stays by its point
    fig = plot_specimen_means(table, tests={"all": {"t_p": 0.2, "n": n}})
    ax = fig.axes[0]
    for dpi in (72, 150):
        fig.set_dpi(dpi)
        fig.draw_without_rendering()
        names = {t.get_text(): t for t in ax.texts if t.get_text().startswith("S")}
        assert sorted(names) == [r["name"] for r in table]
        # the text's own box (an Annotation's extent also holds its leader line)
        boxes = {k: Text.get_window_extent(t) for k, t in names.items()}
        for i, a in enumerate(sorted(boxes)):
            for b in sorted(boxes)[i + 1 :]:
                assert not boxes[a].overlaps(boxes[b]), (a, b, dpi)
        axes_box = ax.get_window_extent()
        assert all(axes_box.y0 <= b.y0 and b.y1 <= axes_box.y1 for b in boxes.values())
        # the lone specimen's name sits level with its point
        point = ax.transData.transform((1.0, table[0]["Eyy"]))
        centre = 0.5 * (boxes["S00"].y0 + boxes["S00"].y1)
        assert abs(centre - point[1]) < 0.5 * dpi / 72
        # within a group the names keep the order of the means (leaders do not cross)
        for group in ("g", "h"):
            rows = sorted((r for r in table if r["group"] == group and r["name"] != "S00"),
                          key=lambda r: r["Eyy"])  # fmt: skip
            ys = [boxes[r["name"]].y0 for r in rows]
            assert ys == sorted(ys)


def test_study_report_leads_with_the_specimen_and_fits_the_window(study_dir, tmp_path):
    """The report: specimen-level results first, node-level marked descriptive, 1024 px wide."""
    import re

    from strain2d.report import write_study
    from tests.report_browser import problems

    root, _ = study_dir
    entries = read_manifest(root / "manifest.csv")
    entries = entries[:3] + entries[5:8]  # 3 specimens per group keep it quick
    summary = write_study(tmp_path / "study", entries, manifest=root / "manifest.csv")
    report = tmp_path / "study" / "report.html"
    page = report.read_text(encoding="utf-8")
    heads = re.findall(r"<h[23]>(.*?)</h[23]>", page)
    first = heads.index("Specimen-level results (the specimen is the experimental unit)")
    assert first < heads.index("Specimens") < heads.index("Node-level tests (descriptive)")
    assert heads.index("Mixed-effects model") < heads.index("Specimens")
    # the specimen means figure sits with the specimen-level results, before the node level
    means = page.index("with the specimen-level paired tests (the specimen is the")
    assert page.index(heads[first]) < means < page.index("Node-level tests (descriptive)")
    assert "nodes within a specimen are not independent" in page
    # the specimens' metadata and their means are two tables, neither needing small print
    assert 'class="wide"' not in page
    tables = re.findall(r"<table.*?</table>", page, re.S)
    meta = [t for t in tables if "<th>endpoint source</th>" in t]
    means = [t for t in tables if "<th>SD Exx</th>" in t]
    assert len(meta) == len(means) == 1 and meta != means
    assert all(f"<td>{r['specimen']}</td>" in means[0] for r in summary["specimens"])
    stats = json.loads((tmp_path / "study" / "statistics.json").read_text())
    assert stats["headline"] == "specimen_level" and stats["software"]["name"] == "strain2d"
    assert stats["n_boot"] == 2000
    assert all("descriptive" in r["node_level"]["label"] for r in stats["specimens"])
    assert problems(report) == []


@pytest.mark.parametrize(("n", "alpha", "flagged"), [(5, 0.05, True), (6, 0.05, False),
                                                     (7, 0.01, True), (8, 0.01, False),
                                                     (5, 0.1, False)])  # fmt: skip
def test_the_small_group_flag_follows_alpha(n, alpha, flagged):
    """The exact two-sided Wilcoxon p is at least 2 / 2^n: flagged when that is not < alpha."""
    from strain2d.report import _study_flags

    stats = {"components": ["Exx", "Eyy"], "alpha": alpha, "specimen_level": {"all": {"n": n}}}
    stats["specimens"] = []
    flags = _study_flags(stats)
    assert any("cannot reach" in f for f in flags) == flagged
