"""The lines of a joint fit (:mod:`.joint`): when the shape of a line's amplitude law (its decay, or
the shape parameter of a ``rational`` / ``power`` law) is not identified and the line keeps a
constant amplitude instead (SILO4 eq. 6), the covariance and residual variance both stages of the
fit share, and the sentence of a fit that does not converge.

A decay needs the line measured on its own (a whole cycle in a segment) at two speeds or more
(:func:`few_speeds`), and an amplitude distinguishable from zero (:func:`faint_lines`): the decay of
a line with no amplitude changes nothing the data can see, except that a decay running to minus
infinity puts the whole line into the fastest segment, where it fits that segment's noise, so the
least squares follows it without end.  Either way the line is fitted with a constant amplitude and
``not_identified["<direction>.<label>.decay"]`` says why (:func:`hold_constant`: one statement).

Units: speeds rad/s (m/s), amplitudes Nm (N), decays s/rad (s/m; dimensionless for ``power``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .covariance import clusters_of, fit_covariance
from .stats import SIGNIFICANT, SegmentStats, pair_se

__all__ = ["shape_free", "hold_constant", "few_speeds", "held", "faint_lines", "residual_variance", "covariance",
           "grid_starts", "not_converged"]


def shape_free(h: dict) -> bool:
    """Whether line ``h`` (a harmonic spec) has an amplitude law with a shape to fit (not ``const``,
    not ``decay: False``)."""
    return h.get("decay", True) is not False and h.get("law", "exp") != "const"


def label(h: dict) -> str:
    """The line's label, or its frequency (cycles per unit of position) when it has none."""
    return h.get("label") or f"{h['frequency']:.6g}"


def hold_constant(h: dict, dname: str, ni: dict, why: str) -> None:
    """Fit line ``h`` with a constant amplitude (``decay: False``) and state it in ``ni`` (the fit's
    ``not_identified``) under ``<dname>.<label>.decay`` with the reason ``why``."""
    h["decay"] = False
    ni[f"{dname}.{label(h)}.decay"] = f"{why}: its amplitude is held constant"


def few_speeds(stats: SegmentStats, specs: list[dict], ranges: np.ndarray, dname: str, ni: dict) -> None:
    """Hold constant every line that completes a cycle within a segment at fewer than two speeds: a
    line seen only in partial cycles shifts segment levels, which the speed law could trade against a
    speed-dependent amplitude.  Free motion: a cycle of the line at each end of a range of speeds is
    two speeds (``ranges``: :func:`~.stats.speed_ranges`)."""
    for k, h in enumerate(specs):
        whole = stats.sampled[:, k] & (stats.cycles[:, k] >= 1.0)
        speeds = np.unique(np.round(stats.speed[whole], 9))
        pooled = stats.free is not None and np.isfinite(ranges[k, 1]) and ranges[k, 1] > ranges[k, 0]
        if len(speeds) < 2 and not pooled and shape_free(h):
            hold_constant(h, dname, ni, f"the line completes a cycle within a segment at {len(speeds)} speed(s) only")


def residual_variance(prob, r: np.ndarray, p: int) -> float:
    """Residual variance of a weighted fit of ``p`` parameters with residuals ``r``: its weighted
    residual sum of squares plus the segments' own (pure error), over the samples' degrees of freedom."""
    st = prob.stats
    return (float(r @ r) + float(np.sum(prob.weights * st.rss_hat))) / max(int(np.sum(st.n)) - p, 1)


def covariance(prob, J: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, str]:
    """The covariance of the parameters of Jacobian ``J`` (rows: the problem's weighted residuals
    ``r``) and how it was computed (:func:`~.covariance.fit_covariance` with the problem's method)."""
    st = prob.stats
    p = J.shape[1]
    clusters, what = clusters_of(st.segment, prob.segments, p) if prob.se == "covariance" else (None, "")
    return fit_covariance(J, r, residual_variance(prob, r, p), method=prob.se,
                          segment_of_row=np.repeat(np.arange(len(st.g)), st.g.shape[1]),
                          cluster_of_segment=clusters, fallback=what)


def held(prob, lines):
    """The problem with the amplitude of every line in ``lines`` (indices) held constant."""
    free = prob.decay_free.copy()
    free[list(lines)] = False
    return replace(prob, decay_free=free, amp_law=["const" if k in lines else a for k, a in enumerate(prob.amp_law)])


def _amplitudes(prob, sol: dict, lines) -> dict[int, tuple[float, float]]:
    """``{k: (amplitude, se)}`` of the lines ``lines`` in the solution ``sol`` of ``prob``, Nm (N); the
    standard errors from the solution's covariance (all parameters), or where a decay that the data
    do not pin down left it singular, from the linear stage at the solution's nonlinear values."""
    lin, cov = sol["lin"], sol["cov"]
    if not np.all(np.isfinite(cov)):
        M = prob.design(sol["nonlin"], sol["decays"])
        cov, _ = covariance(prob, np.einsum("spq,sql->spl", prob.Lt, M).reshape(-1, M.shape[2]),
                            prob.solve_linear(sol["nonlin"], sol["decays"])[1])
    nb = len(prob.basis.lin)
    out = {}
    for k in lines:
        ia = nb + 2 * int(k)
        with np.errstate(all="ignore"):   # a denormal amplitude: its se is NaN or inf
            se = pair_se(lin[ia], lin[ia + 1], cov[ia:ia + 2, ia:ia + 2])[0]
        out[int(k)] = (math.hypot(lin[ia], lin[ia + 1]), se)
    return out


def _faint(amp: float, se: float) -> bool:
    """Not distinguishable from zero: below :data:`~.stats.SIGNIFICANT` standard errors (a zero
    amplitude, whose se is NaN, too)."""
    return not amp > SIGNIFICANT * se


def faint_lines(prob, fit_direction, init=None) -> dict[int, tuple[float, float]]:
    """The lines of ``prob`` with a shape to fit whose amplitude, fitted as a constant, is not
    distinguishable from zero (:func:`_faint`): ``{k: (amplitude, se)}``, Nm (N).  First every shape
    is held (no decay can run away); then each line found above is tested again with only its own
    shape held and those of the faint lines found so far: holding the decay of a line that does
    decay can lift an empty line above the threshold.  ``fit_direction``:
    :func:`~.joint._fit_direction` (one more fit per line above the noise but the strongest)."""
    free = [int(k) for k in np.flatnonzero(prob.decay_free)]
    if not free:
        return {}
    hold = held(prob, free)
    first = fit_direction(hold, init=init)
    found = _amplitudes(hold, first, free)
    faint = {k: v for k, v in found.items() if _faint(*v)}
    for k in [k for k in free if k not in faint]:
        lines = set(faint) | {k}
        if lines == set(free):     # the first fit is that fit
            continue
        hold = held(prob, lines)    # started where the first fit ended
        amp = _amplitudes(hold, fit_direction(hold, init=init, at=first["nonlin"]), [k])[k]
        if _faint(*amp):
            faint[k] = amp
    return dict(sorted(faint.items()))


def grid_starts(prob, init=None, at=None) -> tuple[list[list[float]], np.ndarray, tuple[float, float]]:
    """Where the nonlinear least squares starts: ``(starts, decays, log_bounds)``.  ``starts``: the
    nonlinear base parameters (the Stribeck velocity, m/s or rad/s) at the best three local minima of
    the registry's grid (``at``: these values instead, no grid), with every decay at ``decays`` (0,
    or ``init``'s); ``log_bounds``: the bounds of the log of the Stribeck velocity (outside them it
    is not identifiable)."""
    st = prob.stats
    nb_nl = len(prob.basis.nonlin)
    spd = st.speed[st.speed > 0]
    lo, hi = (spd.min(), spd.max()) if len(spd) else (1e-3, 1.0)
    # the Stribeck velocity is searched within the bounds and from the grid the registry declares
    # (:class:`gearspec.terms.Nonlinear`: outside [lo/10, 2 hi] it is not identifiable); a result
    # on a bound is reported as not identified
    nl_lo, nl_hi = prob.basis.search[0].bounds(lo, hi) if nb_nl else (1.0, 1.0)
    if nb_nl:
        grid_vs = prob.basis.search[0].grid(lo, hi)
        if init and init.get("v_s") and nl_lo < float(init["v_s"]) < nl_hi:
            grid_vs = np.append(grid_vs, float(init["v_s"]))
    else:
        grid_vs = [None]
    dec0 = np.zeros(prob.K)
    if init:
        for k, h in enumerate(init.get("harmonics", [])[:prob.K]):
            if h.get("decay") is not None and prob.decay_free[k]:
                dec0[k] = float(h["decay"])
    if at is not None:
        return [list(at)], dec0, (math.log(nl_lo), math.log(nl_hi))
    costs = []
    # the grid's costs are kept on the statistics (``grid_costs``): the fit with every shape held
    # (:func:`faint_lines`) and the fit that follows it start from the same grid with the same columns
    # (a decay of 0 is a constant amplitude), so they are computed once; the key holds everything a
    # cost depends on
    memo = prob.stats.grid_costs
    key0 = (prob.basis.lin, prob.basis.nonlin, prob.basis.columns, prob.basis.nonneg, prob.weights.tobytes(),
            (prob.factors(dec0) * prob.stats.sampled).tobytes())
    for vs in grid_vs:
        key = key0 + (None if vs is None else float(vs),)
        if key not in memo:
            _, r = prob.solve_linear([] if vs is None else [vs], dec0)
            memo[key] = float(r @ r)
        costs.append(memo[key])
    # starts: every local minimum of the grid cost (the best three), not only the lowest grid
    # point -- a sharp minimum (noiseless or precise points) can fall between two grid points and
    # cost more there than a broad local minimum elsewhere does
    costs = np.asarray(costs)
    if nb_nl and len(costs) > 2:
        order = np.argsort(np.asarray(grid_vs, dtype=float), kind="stable")
        c_o = costs[order]
        is_min = np.r_[c_o[0] <= c_o[1], (c_o[1:-1] <= c_o[:-2]) & (c_o[1:-1] <= c_o[2:]), c_o[-1] <= c_o[-2]]
        mins = order[is_min]
        starts = [[float(grid_vs[i])] for i in mins[np.argsort(costs[mins], kind="stable")][:3]]
    else:
        best = grid_vs[int(np.argmin(costs))]
        starts = [[] if best is None else [float(best)]]
    return starts, dec0, (math.log(nl_lo), math.log(nl_hi))


def not_converged(law: str, dname: str, prob, res, nonlin: list, decays: np.ndarray, unit: str = "rad") -> str:
    """The sentence of a least squares that stopped without converging (``res``: its result): where
    it stopped (``nonlin``: the Stribeck velocity, ``unit``/s; ``decays``: s/``unit``, dimensionless
    for a ``power`` law) and why."""
    where = [f"{nm} = {v:.3g} {unit}/s" for nm, v in zip(prob.basis.nonlin, nonlin)]
    where += [f"decay of {label(prob.harmonics[k])} = {decays[k]:.3g}"
              + ("" if prob.amp_law[k] == "power" else f" s/{unit}") for k in np.flatnonzero(prob.decay_free)]
    why = (f"it used its {res.nfev} evaluations" if res.status == 0 else f"status {res.status}: {res.message}")
    return (f"the {law} fit did not converge in the {dname} direction ({why} and stopped at "
            f"{', '.join(where) or 'its start'}): a parameter the data do not pin down may still be moving; "
            f"fit fewer lines (--lines) or a simpler law")
