"""Studies: many runs (specimens, optionally in groups) combined, with the specimen as the unit.

The source paper compared nodal Exx and Eyy with a paired t-test over the 49
nodes of each specimen.  Those nodes are not independent samples of a
population of specimens: the question a study asks ("does this tissue contract
more along its length than around it?") has the *specimen* as its unit.  This
module therefore reports, for the two components compared (``a`` and ``b``,
by default Exx and Eyy at each specimen's contraction endpoint):

* per specimen, the node-level tests of :func:`strain2d.stats.paired_node_tests`
  (labelled as such);
* across specimens (all, and per group), the paired t-test and the Wilcoxon
  signed-rank test on the specimen means, the mean difference with its
  t interval and Cohen's d_z;
* a linear mixed-effects model of the nodal differences ``d = a - b`` with a
  random intercept per specimen (REML, :class:`statsmodels.regression.mixed_linear_model.MixedLM`):
  ``d ~ 1 + (1 | specimen)``, or ``d ~ 0 + group + (1 | specimen)`` with
  groups.  Its fixed effects are tested with the Wald z that statsmodels
  reports and, because a handful of specimens makes z anticonservative, with a
  t reference on ``n_specimens - n_fixed_effects`` degrees of freedom (the
  specimen-level, or containment, degrees of freedom: the fixed effects vary
  between specimens only, so the specimens are the replicates), which is the
  p-value the summary uses;
* with exactly two groups, Welch's t-test between the groups' specimen mean
  differences, and the group contrast of the mixed model;
* a plain-language summary of what is and is not significant at ``alpha``.

References
----------
* N. M. Laird, J. H. Ware, Random-effects models for longitudinal data,
  Biometrics 38 (1982) 963-974, doi:10.2307/2529876.
* J. C. Pinheiro, D. M. Bates, Mixed-Effects Models in S and S-PLUS, Springer
  2000 (degrees of freedom of fixed effects at the specimen level, sec. 2.4.2).
* S. E. Lazic, The problem of pseudoreplication in neuroscientific studies,
  BMC Neuroscience 11 (2010) 5, doi:10.1186/1471-2202-11-5.
"""

from __future__ import annotations

import csv
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from strain2d.errors import InputError
from strain2d.run import COMPONENTS, Run, load_run
from strain2d.stats import paired_node_tests
from tissue_core.csvtext import restore_cell
from tissue_core.filenames import readable

__all__ = [
    "Specimen",
    "load_specimens",
    "mixed_model",
    "plain_summary",
    "read_manifest",
    "specimen_tests",
    "study_statistics",
]


@dataclass(frozen=True)
class Specimen:
    """One run of a study.

    Attributes
    ----------
    name : str
    group : str
        Empty when the study has no groups.
    run : Run
    endpoint : int
        The frame compared (the run's contraction endpoint unless overridden).
    endpoint_source : str
    """

    name: str
    group: str
    run: Run
    endpoint: int
    endpoint_source: str

    def values(self, component: str) -> np.ndarray:
        """Nodal values of ``component`` on the endpoint frame, ``(N,)``."""
        return self.run.nodal[component][self.endpoint]


#: how the node-level tests are labelled wherever they appear: descriptive, never the headline
_NODE_LEVEL_LABEL = (
    "node-level paired tests, descriptive: nodes within a specimen are not independent"
)


def read_manifest(path: str | os.PathLike) -> list[dict]:
    """Read a study manifest CSV.

    Columns: ``run`` (an ``analyze`` output folder, relative to the manifest's
    folder or absolute; required), ``specimen`` (default: the folder name),
    ``group`` (optional), ``endpoint`` (optional frame index overriding the
    run's contraction endpoint).  Other columns are kept and ignored.  A cell
    the toolkit wrote inert for spreadsheets (``strain2d batch``'s
    ``study_manifest.csv``) is read as it was given
    (:func:`tissue_core.csvtext.restore_cell`).
    """
    from tissue_core.tables import cell_count_error

    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.DictReader(f)
            rows = [(reader.line_num, row) for row in reader]
    except FileNotFoundError:
        raise InputError(f"manifest {path} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"manifest {path} is a folder; give the CSV file") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"manifest {path} cannot be read: {exc}") from None
    for i, row in rows:  # a row with more or fewer cells than the header
        cells = [v for k, v in row.items() if k is not None and v is not None]
        cells += row.get(None, [])
        if len(cells) != len(reader.fieldnames) and any(c.strip() for c in cells):
            raise cell_count_error(
                f"manifest {path}", i, len(cells), len(reader.fieldnames), ",".join(cells)
            )
    # header names are matched without surrounding spaces and case
    rows = [
        (i, {(k or "").strip().lower(): restore_cell(v.strip()) if isinstance(v, str) else v
             for k, v in row.items()})
        for i, row in rows
    ]  # fmt: skip
    if not rows or "run" not in rows[0][1]:
        raise InputError(f"manifest {path} needs a header with a 'run' column and one row per run")
    entries = []
    for i, row in rows:
        run = (row.get("run") or "").strip()
        if not run:
            raise InputError(f"manifest {path}, line {i}: the run column is empty")
        run_path = Path(run) if Path(run).is_absolute() else path.parent / run
        endpoint = (row.get("endpoint") or "").strip()
        if endpoint:
            try:
                endpoint = int(endpoint)
            except ValueError:
                endpoint = -1
            if endpoint < 0:
                raise InputError(
                    f"manifest {path}, line {i}: endpoint must be a frame number from 0 "
                    f"(the reference frame), got {row.get('endpoint')!r}"
                )
        group = (row.get("group") or "").strip()
        if group.lower() == "all":
            raise InputError(f"manifest {path}, line {i}: 'all' is reserved; rename the group")
        entries.append(
            {
                "run": run_path,
                "specimen": (row.get("specimen") or "").strip() or readable(run_path.name),
                "group": group,
                "endpoint": endpoint if endpoint != "" else None,
            }
        )
    return entries


def load_specimens(entries: list[dict]) -> list[Specimen]:
    """Load every run of a manifest (see :func:`read_manifest`) or of plain folders.

    ``entries`` are dicts with ``run`` and optional ``specimen``, ``group``,
    ``endpoint``.  Specimen names must be unique.
    """
    if not entries:
        raise InputError("a study needs at least one run folder")
    specimens = []
    for e in entries:
        run = load_run(e["run"])
        # a folder's name as text: bytes that are not UTF-8 as \xNN (tables, figures, reports)
        name = e.get("specimen") or readable(Path(e["run"]).name)
        endpoint, source = run.endpoint, run.endpoint_source
        if e.get("endpoint") is not None:
            endpoint, source = int(e["endpoint"]), "given in the manifest"
            if not 0 <= endpoint < run.n_frames:
                raise InputError(
                    f"specimen {name}: endpoint {endpoint} is outside frames 0..{run.n_frames - 1}"
                )
        specimens.append(Specimen(name, e.get("group") or "", run, endpoint, source))
    names = [s.name for s in specimens]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(
            f"specimen names must be unique; repeated: {', '.join(dup)} (name them in a "
            "manifest's specimen column)"
        )
    if any(s.group.lower() == "all" for s in specimens):
        raise InputError("'all' is reserved; rename the group")
    return specimens


def specimen_tests(a_means: np.ndarray, b_means: np.ndarray, *, confidence: float = 0.95) -> dict:
    """Paired tests with the specimen as the unit: one mean of ``a`` and ``b`` per specimen.

    Returns ``n``, ``mean_difference`` (a - b) with its t interval
    ``mean_difference_ci``, ``t``, ``t_p`` (paired t-test), ``wilcoxon_p``
    (exact signed-rank test; with fewer than 6 specimens it cannot reach
    p < 0.05 two-sided) and ``cohens_dz``.  Values that need more specimens
    are NaN.
    """
    from scipy import stats

    a = np.asarray(a_means, np.float64)
    b = np.asarray(b_means, np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    d = a[ok] - b[ok]
    n = int(d.size)
    out = {
        "n": n,
        "mean_difference": float(d.mean()) if n else float("nan"),
        "mean_difference_ci": [float("nan"), float("nan")],
        "confidence": confidence,
        "t": float("nan"),
        "t_p": float("nan"),
        "wilcoxon_p": float("nan"),
        "cohens_dz": float("nan"),
        "label": "specimen-level paired tests (one mean per specimen)",
    }
    if n >= 2 and d.std(ddof=1) > 0:
        t = stats.ttest_rel(a[ok], b[ok])
        out.update(
            t=float(t.statistic),
            t_p=float(t.pvalue),
            cohens_dz=float(d.mean() / d.std(ddof=1)),
            mean_difference_ci=[float(v) for v in t.confidence_interval(confidence)],
        )
    elif n >= 2:  # every specimen differs by the same amount: the interval is that value
        out["mean_difference_ci"] = [float(d.mean())] * 2
    if n >= 2 and np.any(d != 0):
        out["wilcoxon_p"] = float(stats.wilcoxon(d[d != 0]).pvalue)
    return out


def mixed_model(
    d: np.ndarray,
    specimen: np.ndarray,
    group: np.ndarray | None = None,
    *,
    confidence: float = 0.95,
) -> dict:
    """Random-intercept model of nodal differences ``d`` with the specimen as a random effect.

    ``d ~ 1 + (1 | specimen)`` without groups; ``d ~ 0 + group + (1 | specimen)``
    (one mean difference per group) with them, plus the contrast between the
    first group and each other group from ``d ~ group + (1 | specimen)``.
    Fitted by REML.

    Returns
    -------
    dict
        ``effects``: a list of {``term``, ``estimate``, ``se``, ``z_p`` (Wald),
        ``df``, ``t_p`` (t reference, specimen-level df), ``ci`` (t interval)};
        ``contrasts`` likewise (groups only); ``specimen_variance``,
        ``residual_variance``, ``icc``, ``n_nodes``, ``n_specimens``,
        ``converged``, ``warnings``, ``formula``.
    """
    import pandas as pd
    import statsmodels.formula.api as smf
    from scipy import stats

    d = np.asarray(d, np.float64)
    specimen = np.asarray(specimen).astype(str)
    ok = np.isfinite(d)
    # statsmodels flags a random-effect variance under 0.01 as "on the boundary" in
    # absolute terms; strains are ~0.01, so fit d in units of its own SD and scale back
    unit = float(np.std(d[ok])) if ok.sum() > 1 else 1.0
    unit = unit if unit > 0 else 1.0
    frame = pd.DataFrame({"d": d[ok] / unit, "specimen": specimen[ok]})
    groups = None
    if group is not None:
        frame["group"] = np.asarray(group).astype(str)[ok]
        groups = list(dict.fromkeys(frame["group"]))
    n_spec = int(frame["specimen"].nunique())
    if n_spec < 2:
        raise InputError(f"a mixed-effects model needs at least 2 specimens, got {n_spec}")

    if frame["specimen"].value_counts().max() < 2:
        raise InputError("a mixed-effects model needs a specimen with at least 2 nodes")

    def fit(formula: str):
        caught: list[str] = []
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            try:
                model = smf.mixedlm(formula, frame, groups=frame["specimen"])
                result = model.fit(reml=True)
                # statsmodels computes these lazily: inside the warning filter
                fe, bse = result.fe_params.copy(), result.bse_fe.copy()
                cov_re, scale = np.asarray(result.cov_re).copy(), float(result.scale)
            except (ValueError, np.linalg.LinAlgError) as exc:
                raise InputError(f"the mixed-effects model cannot be fitted: {exc}") from None
        for w in record:
            message = str(w.message).splitlines()[0].rstrip(".")
            if message not in caught:
                caught.append(message)
        fitted = {"fe": fe, "bse": bse, "cov_re": cov_re, "scale": scale}
        fitted["converged"] = bool(getattr(result, "converged", True))
        return fitted, caught

    def terms(result, names: list[str], df: int) -> list[dict]:
        out = []
        for name, key in names:
            est = unit * float(result["fe"][key])
            se = unit * float(result["bse"][key])
            z = est / se if se > 0 else float("nan")
            out.append(
                {
                    "term": name,
                    "estimate": est,
                    "se": se,
                    "z_p": float(2 * stats.norm.sf(abs(z))) if math.isfinite(z) else float("nan"),
                    "df": df,
                    "t_p": float(2 * stats.t.sf(abs(z), df))
                    if math.isfinite(z) and df > 0
                    else float("nan"),
                    "ci": [float(v) for v in stats.t.interval(confidence, df, loc=est, scale=se)]
                    if df > 0 and se > 0
                    else [float("nan"), float("nan")],
                }
            )
        return out

    if groups is None or len(groups) == 1:
        formula = "d ~ 1"
        result, caught = fit(formula)
        effects = terms(result, [("mean difference", "Intercept")], n_spec - 1)
        contrasts: list[dict] = []
    else:
        formula = "d ~ 0 + C(group)"
        result, caught = fit(formula)
        keys = list(result["fe"].index)
        # keys follow pandas' category order (sorted): name them from the keys
        names = [(f"mean difference, {k[len('C(group)[') : -1]}", k) for k in keys]
        effects = terms(result, names, n_spec - len(groups))
        base = sorted(groups)[0]
        contrast_result, caught2 = fit("d ~ C(group)")
        caught += [c for c in caught2 if c not in caught]
        keys = [k for k in contrast_result["fe"].index if k != "Intercept"]
        names = [(f"{k[len('C(group)[T.') : -1]} - {base}", k) for k in keys]
        contrasts = terms(contrast_result, names, n_spec - len(groups))
    tau2 = unit**2 * float(result["cov_re"][0, 0])
    sigma2 = unit**2 * result["scale"]
    return {
        "formula": formula.replace("C(group)", "group") + " + (1 | specimen)",
        "method": "REML (statsmodels MixedLM)",
        "effects": effects,
        "contrasts": contrasts,
        "specimen_variance": tau2,
        "residual_variance": sigma2,
        "icc": tau2 / (tau2 + sigma2) if tau2 + sigma2 > 0 else float("nan"),
        "n_nodes": len(frame),
        "n_specimens": n_spec,
        "converged": result["converged"],
        "warnings": caught,
        # p-values of a fit that did not converge cleanly are reported, not used
        "usable": result["converged"] and not caught,
        "p_value_used": "t_p: t reference on n_specimens - n_fixed_effects degrees of freedom",
    }


def _finite_mean(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def study_statistics(
    specimens: list[Specimen],
    *,
    a: str = "Exx",
    b: str = "Eyy",
    alpha: float = 0.05,
    confidence: float = 0.95,
    n_boot: int = 2000,
) -> dict:
    """All statistics of a study comparing components ``a`` and ``b`` at each endpoint.

    Returns a dict with ``specimens`` (one row per specimen: name, group,
    endpoint, n_nodes, mean/SD of ``a``, ``b`` and their difference, and the
    node-level tests, labelled descriptive), ``specimen_level`` (``all`` and
    one entry per group, see :func:`specimen_tests`; ``headline`` names it:
    the specimen is the experimental unit), ``mixed_model`` (see
    :func:`mixed_model`; ``None`` with fewer than 2 specimens),
    ``groups_compared`` (two groups only: Welch's t-test on the specimen mean
    differences), the settings (``alpha``, ``confidence``, ``n_boot``) and
    ``software`` (name and version).
    """
    for comp in (a, b):
        if comp not in COMPONENTS:
            raise InputError(f"unknown component {comp!r}; choose from {', '.join(COMPONENTS)}")
    if a == b:
        raise InputError("compare two different components")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must lie between 0 and 1, got {alpha}")
    rows = []
    long_d, long_s, long_g = [], [], []
    for s in specimens:
        va, vb = s.values(a), s.values(b)
        ok = np.isfinite(va) & np.isfinite(vb)
        pos = s.run.positions[s.endpoint]
        row = {
            "specimen": s.name,
            "group": s.group,
            "run": readable(s.run.path),
            "endpoint": s.endpoint,
            "endpoint_source": s.endpoint_source,
            "endpoint_time": float(s.run.times[s.endpoint]),
            "time_unit": s.run.time_unit,
            "n_nodes": int(ok.sum()),
            f"mean_{a}": _finite_mean(va[ok]),
            f"sd_{a}": float(np.std(va[ok], ddof=1)) if ok.sum() > 1 else float("nan"),
            f"mean_{b}": _finite_mean(vb[ok]),
            f"sd_{b}": float(np.std(vb[ok], ddof=1)) if ok.sum() > 1 else float("nan"),
        }
        row["mean_difference"] = row[f"mean_{a}"] - row[f"mean_{b}"]
        try:
            node = paired_node_tests(va, vb, positions=pos, n_boot=n_boot, confidence=confidence)
        except InputError as exc:
            node = {"error": str(exc)}
        node["label"] = _NODE_LEVEL_LABEL
        row["node_level"] = node
        rows.append(row)
        long_d.append(va[ok] - vb[ok])
        long_s += [s.name] * int(ok.sum())
        long_g += [s.group] * int(ok.sum())
    groups = list(dict.fromkeys(s.group for s in specimens))
    has_groups = any(groups)
    if has_groups and not all(groups):
        lacking = [s.name for s in specimens if not s.group]
        raise InputError(f"give every specimen a group, or none; without: {', '.join(lacking)}")
    # a specimen without a single node holding both values has nothing to compare
    excluded = [r["specimen"] for r in rows if r["n_nodes"] == 0]
    used = [r for r in rows if r["n_nodes"] > 0]

    def level(sel: list[dict]) -> dict:
        return specimen_tests(
            np.array([r[f"mean_{a}"] for r in sel]),
            np.array([r[f"mean_{b}"] for r in sel]),
            confidence=confidence,
        )

    specimen_level = {"all": level(used)}
    if has_groups:
        for g in groups:
            specimen_level[g] = level([r for r in used if r["group"] == g])
    model, model_note = None, ""
    if len(used) >= 2:
        try:
            model = mixed_model(
                np.concatenate(long_d),
                np.array(long_s),
                np.array(long_g) if has_groups else None,
                confidence=confidence,
            )
        except InputError as exc:
            model_note = str(exc)
    else:
        model_note = "a mixed-effects model needs at least 2 specimens with values"
    compared = None
    if has_groups and len(groups) == 2:
        from scipy import stats

        g0, g1 = sorted(groups)
        d0 = np.array([r["mean_difference"] for r in used if r["group"] == g0])
        d1 = np.array([r["mean_difference"] for r in used if r["group"] == g1])
        gap = float(d1.mean() - d0.mean()) if d0.size and d1.size else float("nan")
        compared = {"groups": [g0, g1], "difference": gap}
        if d0.size >= 2 and d1.size >= 2:
            w = stats.ttest_ind(d1, d0, equal_var=False)
            compared.update(welch_t=float(w.statistic), welch_p=float(w.pvalue))
        else:
            compared.update(welch_t=float("nan"), welch_p=float("nan"))
        compared["label"] = (
            f"Welch's t-test between the groups' specimen mean differences ({a} - {b})"
        )
    from strain2d import __version__

    return {
        "software": {"name": "strain2d", "version": __version__},
        "components": [a, b],
        "frame": "each specimen's contraction endpoint",
        # the specimen is the experimental unit: these results answer the study's question
        "headline": "specimen_level",
        "alpha": alpha,
        "confidence": confidence,
        "n_boot": n_boot,
        "specimens": rows,
        "excluded": excluded,
        "groups": groups if has_groups else [],
        "specimen_level": specimen_level,
        "mixed_model": model,
        "mixed_model_note": model_note,
        "groups_compared": compared,
    }


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "p not available"
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


def _verdict(p: float, alpha: float) -> str:
    if not math.isfinite(p):
        return "cannot be tested"
    return "significant" if p < alpha else "not significant"


_NORMAL = ("Exx", "Eyy", "E1", "E2")


def plain_summary(stats: dict) -> list[str]:
    """Sentences saying what is and is not significant, for a report or a terminal."""
    a, b = stats["components"]
    alpha = stats["alpha"]
    pct = round(100 * stats["confidence"])
    lines = []
    if stats.get("excluded"):
        lines.append(
            f"Left out (no node with both {a} and {b} at the endpoint): "
            f"{', '.join(stats['excluded'])}."
        )
    levels = stats["specimen_level"]
    model = stats["mixed_model"]
    effects = {}
    if model:
        for e in model["effects"]:
            effects[e["term"].removeprefix("mean difference").removeprefix(", ") or "all"] = e
        if len(stats["groups"]) == 1 and "all" in effects:
            effects[stats["groups"][0]] = effects.pop("all")
    keys = stats["groups"] or ["all"]
    for key in keys:
        t = levels[key]
        who = f"group {key}" if stats["groups"] else "all specimens"
        n = t["n"]
        head = f"In {who} ({n} specimen{'s' if n != 1 else ''})"
        if n < 2:
            lines.append(
                f"{head}, {a} - {b} at the contraction endpoint cannot be tested across "
                "specimens: at least 2 specimens are needed."
            )
            continue
        lo, hi = t["mean_difference_ci"]
        diff = t["mean_difference"]
        verdict = _verdict(t["t_p"], alpha)
        sentence = (
            f"{head}, {a} - {b} at the contraction endpoint averaged {diff:+.4f} "
            f"({pct}% CI {lo:+.4f} to {hi:+.4f}); the paired t-test on specimen means gives "
            f"{_p(t['t_p'])}: {verdict} at alpha = {alpha:g}"
        )
        if verdict == "significant":
            low, high = (a, b) if diff < 0 else (b, a)
            sentence += f" ({low} is lower than {high}"
            rows = [r for r in stats["specimens"] if key == "all" or r["group"] == key]
            means = [r[f"mean_{c}"] for r in rows if r["n_nodes"] for c in (a, b)]
            if a in _NORMAL and b in _NORMAL and means and max(means) < 0:
                sentence += f": {low} shortens more"
            sentence += ")"
        sentence += "."
        e = effects.get(key)
        if e is not None and model["usable"]:
            agree = _verdict(e["t_p"], alpha)
            sentence += (
                f" The mixed-effects model (specimen as random effect) estimates "
                f"{e['estimate']:+.4f}, {_p(e['t_p'])} ({agree})."
            )
            if "cannot" not in agree + verdict and agree != verdict:
                why = (
                    "the model pools the between-specimen variance over all groups"
                    if len(stats["groups"]) > 1
                    else "the model weights specimens by their node counts and spread"
                )
                sentence += (
                    f" The two tests disagree ({why}); with this few specimens treat the "
                    "result as inconclusive."
                )
        elif e is not None:
            sentence += (
                " The mixed-effects model did not fit cleanly ("
                + ("; ".join(model["warnings"]) or "no convergence")
                + "); its p-value is reported but not used."
            )
        if verdict == "not significant":
            sentence += (
                " Not significant does not mean equal: the interval shows the differences "
                "the data still allow."
            )
        if n < 6:
            sentence += f" With {n} specimens the Wilcoxon signed-rank test cannot reach p < 0.05."
        lines.append(sentence)
    if stats.get("mixed_model_note"):
        lines.append(f"No mixed-effects model: {stats['mixed_model_note']}.")
    comp = stats["groups_compared"]
    if comp is not None:
        g0, g1 = comp["groups"]
        lines.append(
            f"Between groups, the mean {a} - {b} of {g1} differs from that of {g0} by "
            f"{comp['difference']:+.4f}; Welch's t-test on specimen means gives "
            f"{_p(comp['welch_p'])}: {_verdict(comp['welch_p'], alpha)}."
        )
    elif model and model["contrasts"] and model["usable"]:
        parts = [f"{c['term']} {c['estimate']:+.4f} ({_p(c['t_p'])})" for c in model["contrasts"]]
        lines.append(
            f"Between groups (mixed-model contrasts of {a} - {b}): " + "; ".join(parts) + "."
        )
    node = [r["node_level"] for r in stats["specimens"] if "t_p" in r["node_level"]]
    if node:
        k = sum(1 for r in node if math.isfinite(r["t_p"]) and r["t_p"] < alpha)
        lines.append(
            f"Node-level paired t-tests (the source paper's test; descriptive) are significant "
            f"in {k} of {len(node)} specimens. They treat the nodes of one specimen as "
            "independent samples, which they are not, and describe that specimen's field, not "
            "the population; use the specimen-level results above for conclusions about the "
            "tissue."
        )
    return lines


def study_cycles(specimens: list[Specimen], a: str = "Exx", b: str = "Eyy") -> dict | None:
    """The repeated contractions of a study's runs: per cycle, per specimen, and tests.

    Each run with cycles (``summary.json``'s ``cycles``, :mod:`strain2d.cycles`)
    gives a row per cycle: its peak's mean ``a`` and ``b`` and their difference,
    its time to peak, 50 % relaxation and relaxation times.  Per specimen the
    cycles are averaged (mean and SD over its cycles, how many).  The tests
    have the specimen as the unit (:func:`specimen_tests`): ``a`` against ``b``
    at each cycle number that two specimens or more reach (``per_cycle``), and
    on the specimens' averages over their cycles (``averaged_over_cycles``).
    None when no run has repeated contractions.

    Returns
    -------
    dict
        ``rows`` (a dict per specimen and cycle), ``specimens`` (a dict per
        specimen with cycles), ``per_cycle`` (per cycle number: ``cycle`` and
        the tests) and ``averaged_over_cycles`` (the tests).
    """
    rows = []
    for s in specimens:
        found = s.run.summary.get("cycles") or {}
        if not found.get("repeated", True):
            continue  # one contraction: the endpoint comparison is the study
        for c in found.get("cycles", []):
            if c.get("peak") is None:
                continue
            means = c.get("peak_mean") or {}
            va, vb = means.get(a, float("nan")), means.get(b, float("nan"))
            rows.append({
                "specimen": s.name, "group": s.group, "cycle": int(c["cycle"]),
                "peak_frame": int(c["peak"]), a: va, b: vb, f"{a}-{b}": va - vb,
                "time_to_peak": c.get("time_to_peak"), "rt50": c.get("rt50"),
                "relaxation_time": c.get("relaxation_time"), "rise": c.get("amplitude"),
            })  # fmt: skip
    if not rows:
        return None

    def value(row, key):
        v = row.get(key)
        return float("nan") if v is None else float(v)

    per_specimen = []
    for s in specimens:
        mine = [r for r in rows if r["specimen"] == s.name]
        if not mine:
            continue
        entry = {"specimen": s.name, "group": s.group, "n_cycles": len(mine)}
        for key in (a, b, f"{a}-{b}", "time_to_peak", "rt50", "relaxation_time"):
            v = np.array([value(r, key) for r in mine])
            ok = np.isfinite(v)
            entry[f"{key}_mean"] = float(v[ok].mean()) if ok.any() else float("nan")
            entry[f"{key}_sd"] = float(v[ok].std(ddof=1)) if ok.sum() > 1 else float("nan")
        per_specimen.append(entry)
    per_cycle = []
    for k in sorted({r["cycle"] for r in rows}):
        at = [r for r in rows if r["cycle"] == k]
        if len(at) < 2:
            continue
        tests = specimen_tests([value(r, a) for r in at], [value(r, b) for r in at])
        per_cycle.append({"cycle": k, **tests})
    averaged = specimen_tests(
        [e[f"{a}_mean"] for e in per_specimen], [e[f"{b}_mean"] for e in per_specimen]
    )
    return {
        "components": [a, b],
        "rows": rows,
        "specimens": per_specimen,
        "per_cycle": per_cycle,
        "averaged_over_cycles": averaged,
    }
