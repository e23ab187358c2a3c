"""Which joints changed: a trend test per (robot, joint, direction, parameter) over the dates.

The rule (stated in the fleet report): for each series of one parameter of one joint in one
direction over at least :data:`MIN_DATES` dates, a weighted least-squares line ``p = a + b t`` with
weights ``1 / se^2`` (``se``: the fit's standard error of each date's value).  The slope's standard
error is the weighted one, widened by the Birge ratio ``sqrt(chi2 / (n - 2))`` when the points
scatter about the line more than their standard errors say (date-to-date variation the fit's
standard error does not see: temperature, lubrication, load); the two-sided p-value of ``b / se_b``
comes from Student's t with ``n - 2`` degrees of freedom when so widened, else from the normal
distribution (the standard errors explain the scatter and are taken as known).  Every test made over the fleet is then
corrected together by Holm's step-down method (family-wise error ``alpha``, default 1 %): a series
is flagged when its Holm-adjusted p-value is below ``alpha``, and a joint when any of its series is.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from ..errors import InputError

__all__ = ["trend_tests", "holm", "tested_parameters", "flagged_joints", "MIN_DATES", "ALPHA"]

#: fewest dates a series needs to be tested (a line through 3 points has one degree of freedom)
MIN_DATES = 3
#: default family-wise error rate of all the tests of a fleet together
ALPHA = 0.01
#: seconds per day: slopes are reported per day
DAY = 86400.0


def holm(p) -> np.ndarray:
    """Holm's step-down adjusted p-values of ``p`` (NaN stays NaN and does not count as a test)."""
    p = np.asarray(p, float)
    out = np.full(p.shape, np.nan)
    ok = np.isfinite(p)
    m = int(ok.sum())
    if m == 0:
        return out
    idx = np.flatnonzero(ok)[np.argsort(p[ok], kind="stable")]
    adj = np.maximum.accumulate((m - np.arange(m)) * p[idx])
    out[idx] = np.minimum(adj, 1.0)
    return out


def tested_parameters(df: pd.DataFrame) -> list[str]:
    """The parameters tested by default: the fitted law's friction parameters (from the term
    registry) and every line's amplitude, those with a ``_se`` column in ``df``."""
    from ..terms import BASE_LAWS

    laws = [x for x in df.get("law", pd.Series(dtype=object)).dropna().unique() if x in BASE_LAWS]
    names = list(dict.fromkeys(p for law in laws for p in BASE_LAWS[law].params))
    names += [c for c in df.columns if c.endswith(" amplitude")]
    return [c for c in names if c in df and c + "_se" in df]


def _weighted_trend(t: np.ndarray, y: np.ndarray, se: np.ndarray) -> dict:
    """Weighted line through ``(t, y)``: slope per day, its standard error (widened by the Birge
    ratio), t statistic, two-sided p; the fitted change over the span relative to the weighted mean."""
    x = (t - t.mean()) / DAY
    w = 1.0 / se**2
    xw, yw = np.sum(w * x) / w.sum(), np.sum(w * y) / w.sum()
    sxx = np.sum(w * (x - xw) ** 2)
    b = np.sum(w * (x - xw) * (y - yw)) / sxx
    dof = len(x) - 2
    chi2 = float(np.sum(w * (y - yw - b * (x - xw)) ** 2))
    birge = max(1.0, chi2 / dof)
    se_b = float(np.sqrt(birge / sxx))
    tstat = b / se_b
    # standard errors that explain the scatter are taken as known (normal); widened ones are
    # estimated from the n - 2 residuals (Student's t)
    p = float(2 * (stats.t.sf(abs(tstat), dof) if chi2 > dof else stats.norm.sf(abs(tstat))))
    change = b * (x.max() - x.min())
    return {"n": len(x), "t_ref": float(t.mean() + xw * DAY), "mean": yw, "slope_per_day": b, "slope_se": se_b,
            "change": change,
            "relative_change": change / yw if yw != 0 else np.nan, "chi2_dof": chi2 / dof, "t": tstat, "p": p}


def trend_tests(df: pd.DataFrame, parameters=None, *, alpha: float = ALPHA,
                correction: str = "holm") -> pd.DataFrame:
    """The trend test of every (robot, joint, direction, parameter) series in a batch table.

    Parameters
    ----------
    df : DataFrame
        :func:`gearspec.fleet.batch`'s table (rows with ``status`` "ok", a ``start_time`` in s since
        1970, the parameter and its ``_se``).
    parameters : list of str, optional
        Columns tested (default :func:`tested_parameters`).
    alpha : float
        Family-wise error rate over all the tests made.
    correction : {"holm", "bonferroni", "none"}
        The multiple-testing correction ("none": each test at ``alpha`` alone, for comparison only).

    Returns
    -------
    DataFrame
        One row per series tested: ``robot, joint, direction, parameter, n``, ``t_ref`` (the weighted
        mean date, s since 1970), ``mean`` (the line's value there), ``slope_per_day`` (parameter unit
        per day), ``slope_se, change`` (fitted change from the first to the last
        date), ``relative_change, chi2_dof, t, p, p_adjusted, flagged``.
    """
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be between 0 and 1, got {alpha}")
    if correction not in ("holm", "bonferroni", "none"):
        raise InputError(f"correction must be holm, bonferroni or none, got {correction!r}")
    ok = df[(df["status"] == "ok") & df["start_time"].notna()] if len(df) else df
    params = tested_parameters(ok) if parameters is None else list(parameters)
    rows = []
    t_all = pd.to_numeric(ok["start_time"], errors="coerce").to_numpy(float)
    values = {p: (pd.to_numeric(ok[p], errors="coerce").to_numpy(float),
                  pd.to_numeric(ok[p + "_se"], errors="coerce").to_numpy(float)) for p in params}
    for (robot, joint, direction), idx in ok.groupby(["robot", "joint", "direction"], dropna=False,
                                                     sort=True).indices.items():
        t = t_all[idx]
        for p in params:
            y, se = values[p][0][idx], values[p][1][idx]
            keep = np.isfinite(t) & np.isfinite(y) & np.isfinite(se) & (se > 0)
            if keep.sum() < MIN_DATES or len(np.unique(t[keep])) < MIN_DATES:
                continue
            res = _weighted_trend(t[keep], y[keep], se[keep])
            rows.append({"robot": robot, "joint": joint, "direction": direction, "parameter": p, **res})
    out = pd.DataFrame(rows, columns=["robot", "joint", "direction", "parameter", "n", "t_ref", "mean", "slope_per_day",
                                      "slope_se", "change", "relative_change", "chi2_dof", "t", "p"])
    m = len(out)
    if correction == "holm":
        out["p_adjusted"] = holm(out["p"]) if m else []
    elif correction == "bonferroni":
        out["p_adjusted"] = np.minimum(out["p"] * m, 1.0)
    else:
        out["p_adjusted"] = out["p"]
    out["flagged"] = out["p_adjusted"] < alpha
    out.attrs.update({"alpha": alpha, "correction": correction, "tests": m})
    return out


def flagged_joints(trends: pd.DataFrame) -> pd.DataFrame:
    """One row per (robot, joint) with a flagged series: the parameters flagged (``direction:
    parameter``, ...) and the largest relative change among them."""
    f = trends[trends["flagged"]]
    rows = []
    for (robot, joint), g in f.groupby(["robot", "joint"], dropna=False, sort=True):
        big = g.loc[g["relative_change"].abs().idxmax()]
        rows.append({"robot": robot, "joint": joint,
                     "flagged": ", ".join(f"{d}: {p}" for d, p in zip(g["direction"], g["parameter"])),
                     "largest_relative_change": float(big["relative_change"]), "of": big["parameter"],
                     "smallest_p_adjusted": float(g["p_adjusted"].min())})
    return pd.DataFrame(rows, columns=["robot", "joint", "flagged", "largest_relative_change", "of",
                                       "smallest_p_adjusted"])
