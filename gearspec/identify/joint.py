"""Identification of friction models: the papers' procedures and better estimators beside them.

Two estimators of the SILO4 model (eq. 11) and its parts:

* :func:`silo4_published` -- the procedure as published (SILO4 section 3-4): Coulomb and viscous
  friction from a straight line through the plateau averages above ``high_speed`` (100 rpm),
  static friction and Stribeck velocity from the log-linear fit of eqs. 4-5 on the plateaus
  below it (viscous term neglected), and per stage and direction the amplitude and decay constant
  from the log-linear fit of eq. 10 to the amplitudes of the spectra (``constant`` stages, the
  paper's F1, keep a constant amplitude, eq. 6), phases from the spectra (circular mean).
* :func:`fit` -- weighted nonlinear least squares of all parameters of a direction jointly, on the
  samples themselves (amplitudes fitted in the position domain, not through logs of noisy
  amplitudes), with standard errors from the covariance (or a bootstrap over segments).

How :func:`fit` works.  Within a constant-speed segment ``s`` the model is *linear* in a few local
coefficients ``beta_s = [level, a_1, c_1, ..., a_K, c_K]`` (the friction level, and
``A_k e^{-b_k |v_s|}`` times ``cos phi_k``, ``sin phi_k`` of every harmonic), so the residual sum of
squares of the segment is exactly ``(beta_s - beta_hat_s)^T G_s (beta_s - beta_hat_s) + const``
with ``G_s = X_s^T X_s`` and ``beta_hat_s`` the segment's own least-squares coefficients (X_s: the
columns 1, sin, cos at the samples' positions).  One pass over the samples gives every ``G_s`` and
``beta_hat_s``; the fit then works on a few numbers per segment -- exact, and independent of the
number of samples.  Each segment is weighted by the inverse of its own residual variance (pure
error: the variance left after its unrestricted local fit).  The law's linear parameters are
solved in closed form for given nonlinear ones (variable projection: Stribeck velocity, decay
constants), the nonlinear ones by ``scipy.optimize.least_squares`` from a grid start, and a last
joint Gauss-Newton pass over all parameters gives the covariance.  This needs the velocity constant
within a segment: the laws are evaluated at each segment's mean velocity (``FitData`` with
``velocity="segment"``), and a load-dependent law at the segment's mean load.

Lola/CROPS: :func:`fit` with ``law="lola8"``/``"lola11"`` fits friction points (from
:meth:`FitData.from_points` or the load-holding segments of a recording); :func:`fit_efficiency`
fits the efficiency (eq. 13) of such points as the paper does (eq. 9) with the constraints of
eq. 10; :func:`fit_catalog` fits law (8) to a catalog table of efficiency.

Held-out errors (:func:`holdout_rmse`, :func:`compare`) leave out whole segments or runs, never
interleaved samples.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd
from scipy import optimize

from .. import laws
from ..errors import InputError, warn
from ..fitdata import FitData
from ..gears import GearTrain, load_gear
from ..model import LAWS, RPM, FrictionModel
from ..spectrum import MEASURABLE_FRACTION, position_nyquist
from ..terms.registry import Basis as _Basis
from ..terms.registry import basis as _basis

__all__ = ["fit", "silo4_published", "holdout_rmse", "holdout", "compare", "refit", "harmonic_specs", "fit_efficiency",
           "fit_catalog", "efficiency_model", "SegmentStats", "segment_stats", "ConvergenceError", "segment_errors", "identify_recording", "FitResult",
           "line_amplitudes", "amplitudes_from_spectrum", "negative_viscous", "MIN_CYCLES"]

_TWO_PI = 2.0 * np.pi
#: a segment counts towards a line where it covers at least this fraction of a cycle (the default
#: of :func:`fit`; the closed loop uses the same rule for the speed range of an amplitude law)
MIN_CYCLES = 0.1


class ConvergenceError(InputError):
    """The fit did not converge (too few data for the law, or data the law cannot describe)."""


# ---------------------------------------------------------------------- harmonics to fit
def harmonic_specs(harmonics=None, gear: GearTrain | str | None = None) -> list[dict]:
    """The position-locked lines a model fits: ``[{"frequency", "label"}]``.

    ``harmonics``: None (every declared line of ``gear``: shafts, wave generator, meshes), a
    list of frequencies (cycles per unit of theta), or a list of dicts with ``frequency`` and
    optionally ``label``, ``law`` (amplitude law: exp, const, rational, power) and ``decay``
    (False to keep the amplitude constant, SILO4 eq. 6).
    """
    if harmonics is None:
        g = load_gear(gear) if gear is not None else None
        if g is None:
            return []
        return [{"frequency": ln.frequency, "label": ln.label} for ln in g.declared_lines()]
    out = []
    for h in harmonics:
        if isinstance(h, Mapping):
            if "frequency" not in h:
                raise InputError("a harmonic to fit needs a 'frequency' (cycles per unit of theta)")
            out.append(dict(h))
        else:
            out.append({"frequency": float(h), "label": f"line {float(h):.6g}"})
    for h in out:
        if not (np.isfinite(h["frequency"]) and h["frequency"] > 0):
            raise InputError(f"harmonic frequency must be positive, got {h['frequency']}")
    return out


# ---------------------------------------------------------------------- sufficient statistics
@dataclass
class SegmentStats:
    """Per-segment sufficient statistics of the samples for one direction.

    ``G[s]``, ``g[s]``, ``yy[s]``: normal equations of the local model ``[1, sin_k, cos_k]`` on the
    friction magnitude; ``sampled[s, k]``: harmonic k lies below ``nyquist_fraction`` of the
    segment's position Nyquist frequency (its columns are in ``G``, whatever the number of cycles:
    the global model predicts what a partial cycle does to the segment's level); ``active[s, k]``:
    it can also be measured in the segment on its own (it completes
    at least ``min_cycles`` cycles and lies below ``nyquist_fraction`` of the position Nyquist);
    ``speed``, ``load`` (mean), ``n``, ``sigma2`` (residual variance of the unrestricted local fit).
    """

    segment: np.ndarray
    speed: np.ndarray
    load: np.ndarray | None
    n: np.ndarray
    G: np.ndarray          # (S, P, P)
    g: np.ndarray          # (S, P)
    yy: np.ndarray         # (S,)
    active: np.ndarray     # (S, K) bool
    sampled: np.ndarray    # (S, K) bool
    cycles: np.ndarray     # (S, K) cycles of each line in each segment
    sigma2: np.ndarray     # (S,)
    beta_hat: np.ndarray   # (S, P)
    rss_hat: np.ndarray    # (S,)
    frequencies: np.ndarray

    def take(self, idx) -> "SegmentStats":
        """The statistics of the segments ``idx`` (rows; repeats allowed, as in a bootstrap)."""
        idx = np.asarray(idx)
        t = lambda a: None if a is None else a[idx]  # noqa: E731
        return SegmentStats(np.arange(len(idx)), t(self.speed), t(self.load), t(self.n), t(self.G), t(self.g),
                            t(self.yy), t(self.active), t(self.sampled), t(self.cycles), t(self.sigma2),
                            t(self.beta_hat), t(self.rss_hat), self.frequencies)


def segment_stats(data: FitData, frequencies: Sequence[float], *, min_cycles: float = 1.0,
                  nyquist_fraction: float = MEASURABLE_FRACTION) -> SegmentStats:
    """One pass over the samples of ``data`` (one direction): see :class:`SegmentStats`.

    Results are cached per segment on ``data`` (and shared with its whole-segment subsets), so
    that cross-validation and refits do not pass over the samples again.
    """
    freqs = np.asarray(list(frequencies), dtype=float)
    key = (tuple(freqs.tolist()), float(min_cycles), float(nyquist_fraction))
    cache = data.cache.setdefault(("segment_stats",) + key, {})
    order = np.argsort(data.segment, kind="stable")
    sids, starts = np.unique(data.segment[order], return_index=True)
    bounds = np.append(starts, len(order))
    rows = []
    for sid, a, b in zip(sids, bounds[:-1], bounds[1:]):
        ii = order[a:b]
        tag = (int(sid), len(ii), float(data.y[ii[0]]), float(data.y[ii[-1]]))
        row = cache.get(tag)
        if row is None:
            row = _one_segment_stats(data, ii, freqs, min_cycles, nyquist_fraction)
            cache[tag] = row
        rows.append(row)
    K = len(freqs)
    P = 1 + 2 * K
    S = len(rows)
    stack = lambda name, shape: (np.array([r[name] for r in rows]) if S else np.zeros(shape))  # noqa: E731
    load = stack("load", (0,)) if data.load is not None else None
    return SegmentStats(sids, stack("speed", (0,)), load, stack("n", (0,)).astype(int), stack("G", (0, P, P)),
                        stack("g", (0, P)), stack("yy", (0,)), stack("active", (0, K)).astype(bool),
                        stack("sampled", (0, K)).astype(bool),
                        stack("cycles", (0, K)), stack("sigma2", (0,)), stack("beta_hat", (0, P)),
                        stack("rss_hat", (0,)), freqs)


def _one_segment_stats(data: FitData, ii: np.ndarray, freqs: np.ndarray, min_cycles: float,
                       nyquist_fraction: float) -> dict:
    from ..core.reduction import harmonic_columns

    K = len(freqs)
    P = 1 + 2 * K
    y = data.direction[ii] * data.y[ii]
    out = {"n": len(ii), "speed": float(np.mean(np.abs(data.v[ii]))),
           "load": float(np.mean(np.abs(data.load[ii]))) if data.load is not None else 0.0,
           "active": np.zeros(K, bool), "sampled": np.zeros(K, bool), "cycles": np.zeros(K)}
    X = np.ones((len(ii), P))
    if K:
        if data.theta is None:
            raise InputError("harmonics need positions (theta) in the fit data")
        th = data.theta[ii]
        span = float(np.ptp(th)) if len(th) > 1 else 0.0
        out["cycles"] = freqs * span
        # THE position-Nyquist rule (gearspec.spectrum.position_nyquist), on the samples in time order
        nyq = position_nyquist(th) if len(th) > 1 else 0.0
        out["sampled"] = freqs < nyquist_fraction * nyq
        out["active"] = (out["cycles"] >= min_cycles) & out["sampled"]
        X[:, 1::2], X[:, 2::2] = harmonic_columns(th, freqs)   # phases about the segment's mean position
        X[:, 1:][:, np.repeat(~out["sampled"], 2)] = 0.0
    G = X.T @ X
    g = X.T @ y
    yy = float(y @ y)
    try:
        beta = np.linalg.pinv(G, rcond=1e-12, hermitian=True) @ g
    except np.linalg.LinAlgError as exc:
        raise ConvergenceError(f"the local fit of a segment did not converge ({exc}) with {K} lines; fit fewer "
                               f"lines (--lines)") from exc
    rss = max(yy - beta @ g, 0.0)
    dof = len(ii) - (1 + 2 * int(out["sampled"].sum()))
    out.update(G=G, g=g, yy=yy, beta_hat=beta, rss_hat=rss, sigma2=rss / dof if dof >= 3 else np.nan)
    return out


# ---------------------------------------------------------------------- the joint fit of one direction
@dataclass
class _Problem:
    stats: SegmentStats
    basis: _Basis
    harmonics: list[dict]
    decay_free: np.ndarray     # (K,) bool: decay fitted (else fixed 0)
    amp_law: list[str]
    weights: np.ndarray        # (S,)
    Lt: np.ndarray             # (S, P, P): sqrt(w) diag(sqrt(lambda)) U^T
    ranges: np.ndarray         # (K, 2): speed range of each amplitude law (:func:`speed_ranges`)

    @property
    def K(self):
        return len(self.harmonics)

    def factors(self, decays):
        """(S, K) amplitude factor of each harmonic at each segment's speed, the speed held within
        the harmonic's ``speed_range`` (as :meth:`FrictionModel.evaluate` does)."""
        out = np.ones((len(self.stats.speed), self.K))
        for k, law in enumerate(self.amp_law):
            s = np.clip(self.stats.speed, *self.ranges[k])[:, None]
            b = decays[k]
            if law == "exp":
                out[:, k] = np.exp(-b * s[:, 0])
            elif law == "rational":
                out[:, k] = 1.0 / (1.0 + (b * s[:, 0]) ** 2)
            elif law == "power":
                out[:, k] = (1.0 + s[:, 0]) ** (-b)
            elif law == "const":
                out[:, k] = 1.0
            else:
                raise InputError(f"unknown amplitude law '{law}'")
        return out

    def design(self, nonlin_base, decays):
        """M (S, P, L): local coefficients = M @ lin, lin = [base lin..., a_1, c_1, ...]."""
        st = self.stats
        S, P = st.g.shape
        nb = len(self.basis.lin)
        L = nb + 2 * self.K
        M = np.zeros((S, P, L))
        if nb:
            M[:, 0, :nb] = self.basis.columns(st.speed, st.load if st.load is not None else np.zeros(S), *nonlin_base)
        fac = self.factors(decays) * st.sampled
        for k in range(self.K):
            M[:, 1 + 2 * k, nb + 2 * k] = fac[:, k]
            M[:, 2 + 2 * k, nb + 2 * k + 1] = fac[:, k]
        return M

    def solve_linear(self, nonlin_base, decays):
        M = self.design(nonlin_base, decays)
        A = np.einsum("spq,sql->spl", self.Lt, M).reshape(-1, M.shape[2])
        rhs = np.einsum("spq,sq->sp", self.Lt, self.stats.beta_hat).ravel()
        nonneg = [j for j, nm in enumerate(self.basis.lin) if nm in self.basis.nonneg]
        if nonneg:
            lo = np.full(A.shape[1], -np.inf)
            lo[nonneg] = 0.0
            sol = optimize.lsq_linear(A, rhs, bounds=(lo, np.inf), method="bvls").x
        else:
            sol = np.linalg.lstsq(A, rhs, rcond=None)[0]
        return sol, A @ sol - rhs

    def residual_full(self, lin, nonlin_base, decays):
        M = self.design(nonlin_base, decays)
        beta = np.einsum("spl,l->sp", M, lin)
        return np.einsum("spq,sq->sp", self.Lt, beta - self.stats.beta_hat).ravel()

    def rss_const(self):
        return float(np.sum(self.weights * self.stats.rss_hat))


def _make_problem(stats: SegmentStats, law: str, harmonics: list[dict], weights: str) -> _Problem:
    basis = _basis(law)
    S, P = stats.g.shape
    if weights == "segment" and np.all(np.isfinite(stats.sigma2)) and np.all(stats.sigma2 > 0):
        w = 1.0 / stats.sigma2
        w = w / np.median(w)
    elif weights in ("segment", "uniform"):
        w = np.ones(S)
    else:
        raise InputError(f"weights must be 'segment' or 'uniform', got '{weights}'")
    Lt = np.zeros((S, P, P))
    for i in range(S):
        lam, U = np.linalg.eigh(stats.G[i])
        lam = np.clip(lam, 0.0, None)
        Lt[i] = math.sqrt(w[i]) * (np.sqrt(lam)[:, None] * U.T)
    decay_free = np.array([h.get("decay", True) is not False and h.get("law", "exp") != "const" for h in harmonics],
                          bool)
    amp_law = [("const" if h.get("decay", True) is False else h.get("law", "exp")) for h in harmonics]
    return _Problem(stats, basis, harmonics, decay_free, amp_law, w, Lt, speed_ranges(stats))


def speed_ranges(stats: SegmentStats) -> np.ndarray:
    """``(K, 2)``: ``[min, max]`` of the speeds of the segments where each line was measurable
    (``active``: below the position-Nyquist limit of the segment,
    :func:`gearspec.spectrum.position_nyquist`, and at least ``min_cycles`` of its cycles in the
    segment).  The amplitude law is fitted there and held at the edges elsewhere
    (``speed_range`` of a harmonic); ``[0, inf]`` for a line measured nowhere."""
    K = len(stats.frequencies)
    out = np.tile([0.0, np.inf], (K, 1))
    for k in range(K):
        m = stats.active[:, k]
        if m.any():
            out[k] = float(np.min(stats.speed[m])), float(np.max(stats.speed[m]))
    return out


def _fit_direction(prob: _Problem, *, init: Mapping | None = None) -> dict:
    """Variable projection from a grid start, then one joint least-squares pass for the covariance."""
    st = prob.stats
    nb_nl = len(prob.basis.nonlin)
    free = np.flatnonzero(prob.decay_free)
    spd = st.speed[st.speed > 0]
    # grids for the start: Stribeck velocity over the plateau speeds, decays from 0
    lo, hi = (spd.min(), spd.max()) if len(spd) else (1e-3, 1.0)
    # the Stribeck velocity is searched within the bounds and from the grid the registry declares
    # (:class:`gearspec.terms.Nonlinear`: outside [lo/10, 2 hi] it is not identifiable); a result
    # on a bound is reported as not identified
    nl_lo, nl_hi = prob.basis.search[0].bounds(lo, hi) if nb_nl else (1.0, 1.0)
    vs_bounds = (math.log(nl_lo), math.log(nl_hi))
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
    costs = []
    for vs in grid_vs:
        nl = [] if vs is None else [vs]
        _, r = prob.solve_linear(nl, dec0)
        costs.append(float(r @ r))
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
        starts = [[] if grid_vs[int(np.argmin(costs))] is None else [float(grid_vs[int(np.argmin(costs))])]]
    # outer problem over log(nonlinear base) and free decays (scaled by the speed range)
    sscale = 1.0 / max(float(np.max(st.speed)), 1e-12) if len(st.speed) else 1.0
    x0 = np.concatenate([np.log(starts[0]) if nb_nl else [], dec0[free] / sscale])

    def unpack(x):
        nl = list(np.exp(x[:nb_nl])) if nb_nl else []
        dec = dec0.copy()
        dec[free] = x[nb_nl:] * sscale
        return nl, dec

    def proj(x):
        nl, dec = unpack(x)
        return prob.solve_linear(nl, dec)[1]

    if len(x0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            lb = np.concatenate([[vs_bounds[0]] * nb_nl, np.full(len(free), -np.inf)])
            ub = np.concatenate([[vs_bounds[1]] * nb_nl, np.full(len(free), np.inf)])
            res = None
            for st_ in starts:
                x0 = np.clip(np.concatenate([np.log(st_) if nb_nl else [], dec0[free] / sscale]), lb + 1e-9, ub - 1e-9)
                r_ = optimize.least_squares(proj, x0, bounds=(lb, ub), method="trf", x_scale="jac", max_nfev=400)
                if res is None or (np.all(np.isfinite(r_.x)) and r_.cost < res.cost):
                    res = r_
        if not np.all(np.isfinite(res.x)):
            raise ConvergenceError("the friction fit did not converge (non-finite parameters)")
        x_opt = res.x
        status = res.status
    else:
        x_opt = x0
        status = 1
    nl, dec = unpack(x_opt)
    lin, _ = prob.solve_linear(nl, dec)
    # joint pass over all parameters: covariance from the Jacobian at the optimum
    nb = len(prob.basis.lin)

    def full(z):
        lin_ = z[:len(lin)]
        x = z[len(lin):]
        nl_, dec_ = unpack(x)
        return prob.residual_full(lin_, nl_, dec_)

    z = np.concatenate([lin, x_opt])
    r = full(z)
    J = _jacobian(full, z)
    rss = float(r @ r) + prob.rss_const()
    N = int(np.sum(st.n))
    p = len(z)
    dof = max(N - p, 1)
    s2 = rss / dof
    JtJ = J.T @ J
    try:
        cov = np.linalg.inv(JtJ) * s2
        ok = np.all(np.isfinite(cov))
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.nan)
        ok = False
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) if ok else np.full(p, np.nan)
    on_bound = bool(nb_nl and (x_opt[0] <= vs_bounds[0] + 1e-3 or x_opt[0] >= vs_bounds[1] - 1e-3))
    out = {"on_bound": on_bound, "lin": lin, "nonlin": nl, "decays": dec, "cov": cov, "se": se, "rss": rss, "s2": s2, "dof": dof,
           "status": status, "n_lin": nb, "sscale": sscale, "nb_nl": nb_nl, "free": free}
    return out


def _jacobian(fun, z):
    f0 = fun(z)
    J = np.empty((len(f0), len(z)))
    for j in range(len(z)):
        h = 1e-6 * max(abs(z[j]), 1e-8)
        zp = z.copy()
        zp[j] += h
        zm = z.copy()
        zm[j] -= h
        J[:, j] = (fun(zp) - fun(zm)) / (2 * h)
    return J


def _direction_params(prob: _Problem, sol: dict) -> dict:
    """Fitted values and standard errors of one direction, in the FrictionModel form."""
    basis = prob.basis
    lin, se, cov = sol["lin"], sol["se"], sol["cov"]
    nb = sol["n_lin"]
    L = len(lin)
    P: dict = {}
    for j, name in enumerate(basis.lin):
        P[name] = float(lin[j])
        P[name + "_se"] = float(se[j])
    # nonlinear base parameters are fitted as logs: delta method
    for j, name in enumerate(basis.nonlin):
        val = float(sol["nonlin"][j])
        P[name] = val
        P[name + "_se"] = float(val * se[L + j])
    harm = []
    free = list(sol["free"])
    for k, h in enumerate(prob.harmonics):
        a, c = lin[nb + 2 * k], lin[nb + 2 * k + 1]
        ia, ic = nb + 2 * k, nb + 2 * k + 1
        A = float(math.hypot(a, c))
        phi = float(math.atan2(c, a))
        if A > 0 and np.all(np.isfinite(cov)):
            ga = np.array([a / A, c / A])
            gp = ga[::-1] * np.array([-1.0, 1.0]) / A     # (-c, a) / A^2 without A^2 (denormal A)
            C2 = cov[np.ix_([ia, ic], [ia, ic])]
            a_se = float(math.sqrt(max(ga @ C2 @ ga, 0)))
            p_se = float(math.sqrt(max(gp @ C2 @ gp, 0)))
        else:
            a_se = p_se = float("nan")
        entry = {"frequency": float(h["frequency"]), "amplitude": A, "amplitude_se": a_se,
                 "decay": float(sol["decays"][k]), "phase": phi, "phase_se": p_se,
                 "law": prob.amp_law[k]}
        if k in free:
            j = L + sol["nb_nl"] + free.index(k)
            entry["decay_se"] = float(se[j] * sol["sscale"])
        else:
            entry["decay_se"] = 0.0 if prob.amp_law[k] == "const" else float("nan")
        if h.get("label"):
            entry["label"] = h["label"]
        entry["segments"] = int(prob.stats.active[:, k].sum())
        if np.all(np.isfinite(prob.ranges[k])):
            entry["speed_range"] = [float(prob.ranges[k][0]), float(prob.ranges[k][1])]
        harm.append(entry)
    P["harmonics"] = harm
    return P


def fit(data: FitData, law: str = "silo4", *, harmonics=None, gear=None, weights: str = "segment",
        se: str = "covariance", bootstrap: int = 200, min_cycles: float = MIN_CYCLES, holdout: str | None = "segment",
        folds: int = 5, init: FrictionModel | None = None, seed: int = 0, name: str | None = None,
        check: bool = True) -> FrictionModel:
    """Fit a friction law to samples, jointly per direction (weighted nonlinear least squares).

    Parameters
    ----------
    data : FitData
        Samples in constant-speed segments (``velocity="segment"``) or quasi-static points.
    law : str
        ``silo4`` (eq. 11: eq. 3 + harmonics), ``stribeck`` (eq. 3 alone), ``coulomb_viscous``,
        ``lola8``, ``lola11`` or ``none`` (harmonics only).  ``silo4`` fits the declared lines of
        ``gear`` unless ``harmonics`` says otherwise; the others fit ``harmonics`` only if given.
    harmonics, gear
        See :func:`harmonic_specs`.
    weights : {"segment", "uniform"}
        Weight each segment by the inverse of its own residual variance, or all samples alike.
    se : {"covariance", "bootstrap"}
        Standard errors from the covariance of the weighted fit, or from ``bootstrap`` refits on
        segments resampled with replacement (per direction).
    min_cycles : float
        A segment counts towards a harmonic where it covers at least this fraction of a cycle;
        the harmonic is identified when those segments cover at least one cycle together (a line
        too slow for any one segment, e.g. one joint turn, is fitted from many).  Every segment's
        level is modelled with the partial cycles of slow lines it contains.
    holdout : {"segment", "run", None}
        Also compute ``rmse_holdout`` by ``folds``-fold cross-validation over whole segments or
        runs (None: skip).
    init : FrictionModel, optional
        Starting values (e.g. from :func:`silo4_published`).
    check : bool
        Warn (:class:`~gearspec.errors.GearspecWarning`) about a negative viscous coefficient
        (:func:`negative_viscous`); it is flagged in the model either way.

    Returns
    -------
    FrictionModel
        With ``rmse`` (in-sample), ``rmse_holdout``, ``not_identified`` and, in ``meta["fit"]``,
        the settings that :func:`refit` uses.
    """
    if law not in LAWS:
        raise InputError(f"unknown friction law '{law}' (known: {', '.join(LAWS)})")
    if se not in ("covariance", "bootstrap"):
        raise InputError(f"se must be 'covariance' or 'bootstrap', got '{se}'")
    if LAWS[law].needs_load and data.load is None:
        raise InputError(f"law {law} needs the output load torque: the data has no 'load' channel")
    if law == "silo4" and harmonics is None:
        specs = harmonic_specs(None, gear)
        if not specs:
            warn("law silo4 without a gear spec or harmonics: fitting eq. 3 only")
    else:
        specs = harmonic_specs(harmonics, gear) if harmonics is not None else []
    settings = {"law": law, "harmonics": specs, "weights": weights, "se": se, "min_cycles": min_cycles,
                "bootstrap": bootstrap}
    directions: dict[str, dict] = {}
    not_identified: dict[str, str] = {}
    notes: list[str] = []
    for d, dname in ((1, "positive"), (-1, "negative")):
        sub = data.direction_subset(d)
        if len(sub) == 0:
            directions[dname] = {k: None for k in LAWS[law].params}
            directions[dname]["harmonics"] = []
            for k in LAWS[law].params:
                not_identified[f"{dname}.{k}"] = f"no segment in the {dname} direction"
            for h in specs:
                not_identified[f"{dname}.{h.get('label') or h['frequency']}"] = f"no segment in the {dname} direction"
            continue
        P, ni, nt = _fit_one_direction(sub, law, specs, dname, weights=weights, min_cycles=min_cycles,
                                       init=None if init is None else init.params(dname), se=se,
                                       bootstrap=bootstrap, seed=seed)
        directions[dname] = P
        not_identified.update(ni)
        notes += nt
    model = FrictionModel(law if law != "none" else "none", directions["positive"], directions["negative"],
                          unit=data.unit, not_identified=not_identified, notes=notes, name=name or law,
                          meta={"fit": settings})
    model.rmse = _safe_rmse(model, data)
    for msg in negative_viscous(model, data):
        if check:
            warn(msg)
    if holdout:
        model.rmse_holdout, model.rmse_holdout_reason = _holdout_of(
            lambda tr: refit(model, tr, holdout=None), data, by=holdout, folds=folds)
    return model


def _holdout_of(fit_fn, data, **kw):
    return holdout(fit_fn, data, **kw)


def negative_viscous(model: FrictionModel, data: FitData | None = None) -> list[str]:
    """Flag a negative viscous coefficient (``viscous``, Lola's ``b``; more than two standard
    errors below 0) of each direction: friction
    that falls with speed over the whole measured range is rarely physical, and more often an
    inertia, a channel lag or aliasing the model does not hold, or plateau speeds too close
    together to tell viscous from Stribeck friction.  Each flag is one sentence, added to
    ``model.notes`` (``warning: ...``) and to ``model.meta["flags"]`` (``"direction.parameter"
    -> sentence``); returns the sentences."""
    out = []
    flags = model.meta.setdefault("flags", {})
    su = "rad/s" if model.unit == "rad" else "m/s"
    for dname, p in model.directions.items():
        for k in ("viscous", "b"):
            val = p.get(k)
            if k not in model.law_spec.params or val is None or not val < 0:
                continue
            se = p.get(k + "_se")
            # a value within two standard errors of 0 is no finding (and none without an error)
            if se is None or not np.isfinite(se) or not val < -2 * se:
                continue
            sig = f" ({abs(val) / se:.1f} standard errors below 0)" if se > 0 else ""
            rng = ""
            if data is not None:
                sp = np.abs(data.v[data.direction == (1 if dname == "positive" else -1)])
                if len(sp):
                    rng = f" over {float(np.min(sp)):.3g}..{float(np.max(sp)):.3g} {su}"
            msg = (f"{model.name}: the {dname} viscous coefficient ({k}) {val:.3g}{sig} is negative{rng}: likely an "
                   f"inertia, a channel lag or aliasing the model does not hold, or a speed range too narrow to "
                   f"tell viscous from Stribeck friction")
            flags[f"{dname}.{k}"] = msg
            note = "warning: " + msg
            if note not in model.notes:
                model.notes.append(note)
            out.append(msg)
    return out


def _safe_rmse(model: FrictionModel, data: FitData) -> float | None:
    ok = np.zeros(len(data), bool)
    for d, dname in ((1, "positive"), (-1, "negative")):
        p = model.params(dname)
        if all(p.get(k) is not None for k in model.law_spec.params if k not in model.law_spec.optional):
            ok |= data.direction == d
    if not ok.any():
        return None
    return model.rmse_on(data.subset(ok))


def _fit_one_direction(sub: FitData, law: str, specs: list[dict], dname: str, **kw):
    """One direction's fit; a linear-algebra failure (an SVD or eigen-solver that does not
    converge: lines far too many or too close for the data) is a :class:`ConvergenceError` with
    one sentence, never a traceback."""
    try:
        return _fit_one_direction_(sub, law, specs, dname, **kw)
    except np.linalg.LinAlgError as exc:
        raise ConvergenceError(f"the {law} fit did not converge in the {dname} direction ({exc}) with "
                               f"{len(specs)} lines; fit fewer lines (--lines) or a simpler law") from exc


def _fit_one_direction_(sub: FitData, law: str, specs: list[dict], dname: str, *, weights, min_cycles, init, se,
                        bootstrap, seed):
    notes: list[str] = []
    ni: dict[str, str] = {}
    freqs = [h["frequency"] for h in specs]
    stats = segment_stats(sub, freqs, min_cycles=min_cycles)
    # harmonics that the segments do not cover by one cycle together cannot be identified: left out
    total = np.where(stats.active, stats.cycles, 0.0).sum(axis=0) if len(specs) else np.zeros(0)
    keep = [k for k in range(len(specs)) if total[k] >= 1.0]
    for k in range(len(specs)):
        if k not in keep:
            lab = specs[k].get("label") or f"{specs[k]['frequency']:.6g}"
            ni[f"{dname}.{lab}"] = (f"the {dname} segments cover {total[k]:.3g} of its cycles together (segments "
                                    f"with at least {min_cycles:g} cycle each); one cycle is "
                                    f"{1 / specs[k]['frequency']:.4g} {sub.unit} of travel")
    if len(keep) < len(specs):
        specs = [specs[k] for k in keep]
        stats = segment_stats(sub, [h["frequency"] for h in specs], min_cycles=min_cycles)
    # a decay needs the line measured on its own (a whole cycle in a segment) at two speeds or
    # more: a line seen only in partial cycles shifts segment levels, which the speed law could
    # trade against a speed-dependent amplitude; it keeps a constant amplitude (SILO4 eq. 6)
    specs = [dict(h) for h in specs]
    if len(sub.segments) and "kind" in sub.segments and bool((sub.segments["kind"] == "quasi_static").all()):
        return _quasi_static_direction(sub, stats, law, specs, dname, ni, notes, weights)
    for k, h in enumerate(specs):
        whole = stats.sampled[:, k] & (stats.cycles[:, k] >= 1.0)
        speeds = np.unique(np.round(stats.speed[whole], 9))
        if len(speeds) < 2 and h.get("decay", True) is not False and h.get("law", "exp") != "const":
            h["decay"] = False
            lab = h.get("label") or f"{h['frequency']:.6g}"
            ni[f"{dname}.{lab}.decay"] = (f"the line completes a cycle within a segment at {len(speeds)} speed(s) "
                                          f"only: its amplitude is held constant")
    basis = _basis(law)
    distinct = len(np.unique(np.round(stats.speed, 9)))
    need = len(basis.lin) + len(basis.nonlin)
    if LAWS[law].needs_load:
        distinct_load = len(np.unique(np.round(stats.load, 9))) if stats.load is not None else 0
        if distinct_load < 2:
            raise ConvergenceError(f"law {law} needs points at two loads or more in the {dname} direction")
    if distinct < need - (1 if LAWS[law].needs_load else 0):
        raise ConvergenceError(f"law {law} has {need} parameters per direction but the {dname} direction has "
                               f"plateaus at only {distinct} speed(s); fit a simpler law "
                               f"(e.g. coulomb_viscous) or record more speeds")
    prob = _make_problem(stats, law, specs, weights)
    try:
        sol = _fit_direction(prob, init=init)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ConvergenceError(f"the {law} fit did not converge in the {dname} direction ({exc}); the lines "
                               f"asked for may be too close to each other or to the Nyquist frequency") from exc
    if sol["status"] <= 0:
        raise ConvergenceError(f"the {law} fit did not converge in the {dname} direction")
    P = _direction_params(prob, sol)
    for h in P["harmonics"]:
        if np.isfinite(h["amplitude_se"]) and h["amplitude"] < 2 * h["amplitude_se"]:
            notes.append(f"{dname}: amplitude of {h.get('label') or h['frequency']} not significant "
                         f"({h['amplitude']:.3g} +- {h['amplitude_se']:.2g})")
    if se == "bootstrap":
        _bootstrap_se(P, stats, law, specs, weights, bootstrap, seed)
    # parameters the data cannot pin down: a Stribeck velocity outside the plateau speeds.  Then
    # the Stribeck part is left out (None) and the rest refitted without it: the law degrades to
    # its Coulomb + viscous part over the measured speeds, and says so
    if basis.nonlin:
        lo, hi = float(np.min(stats.speed)), float(np.max(stats.speed))
        rel = P["v_s_se"] / P["v_s"] if P["v_s"] > 0 else np.inf
        # the height of the Stribeck term must be there too: static minus Coulomb larger than its
        # error (either sign: Lola's Table IV has T_fS < T_f0, friction rising towards T_f0)
        top, base = ("tau_s", "tau_c") if "tau_s" in P else ("t_fs", "t_f0")
        hump = P[top] - P[base]
        weak = not (np.isfinite(P[top + "_se"]) and P[top + "_se"] < abs(hump))
        if sol["on_bound"] or not np.isfinite(rel) or rel > 1.0 or weak:
            why = (f"not identified by plateaus at {lo:.3g}..{hi:.3g} {sub.unit}/s (the fit went to v_s = "
                   f"{P['v_s']:.3g} {sub.unit}/s, relative standard error {rel:.2g}, hump {top} - {base} = "
                   f"{hump:.3g} +- {P[top + '_se']:.2g}); record slower plateaus")
            reduced = LAWS[law].degraded_for("v_s")
            prob2 = _make_problem(stats, reduced.name, specs, weights)
            P2 = _direction_params(prob2, _fit_direction(prob2, init=init))
            drop = reduced.dropped
            P = {**P2, **{k: None for k in drop}, **{k + "_se": None for k in drop}}
            for k in drop:
                ni[f"{dname}.{k}"] = why
            notes.append(f"{dname}: Stribeck part of law {law} not identified; Coulomb + viscous part fitted alone")
    P["n_segments"] = int(len(stats.speed))
    P["n_samples"] = int(np.sum(stats.n))
    return P, ni, notes


def _quasi_static_direction(sub: FitData, stats: SegmentStats, law: str, specs: list[dict], dname: str,
                            ni: dict, notes: list, weights):
    """One direction of a quasi-static map (every segment a sweep taken at rest): the level
    (``tau_c``, the direction offset) and the lines with constant amplitudes.  The speeds of the
    sweeps are nominal (travel over duration, at rest in between), so nothing that depends on
    speed (Stribeck, viscous, decay laws) is identifiable: those are None, with the reason."""
    quasi = LAWS[law].degraded_for("speed")
    if LAWS[law].needs_load or quasi is None:
        raise ConvergenceError(f"law {law} needs plateaus at several speeds and loads; the {dname} direction "
                               f"has quasi-static sweeps only (fit silo4, stribeck or coulomb_viscous)")
    why = (f"the {dname} direction has quasi-static sweeps only (rows taken at rest; their speed is nominal): "
           f"no speed dependence can be identified")
    for h in specs:
        if h.get("decay", True) is not False and h.get("law", "exp") != "const":
            ni[f"{dname}.{h.get('label') or format(h['frequency'], '.6g')}.decay"] = why + "; amplitude held constant"
        h["decay"] = False
    prob = _make_problem(stats, quasi.name, specs, weights)
    P = _direction_params(prob, _fit_direction(prob))
    for k in LAWS[law].params:
        if k not in P:
            P[k], P[k + "_se"] = None, None
            ni[f"{dname}.{k}"] = why
    notes.append(f"{dname}: quasi-static map: level and lines only")
    P["n_segments"] = int(len(stats.speed))
    P["n_samples"] = int(np.sum(stats.n))
    return P, ni, notes


def _bootstrap_se(P, stats: SegmentStats, law, specs, weights, B, seed):
    """Replace the standard errors by the spread of refits on segments resampled with replacement."""
    rng = np.random.default_rng(seed)
    S = len(stats.speed)
    base_names = list(_basis(law).lin) + list(_basis(law).nonlin)
    draws = {k: [] for k in base_names}
    hdraws = [{"amplitude": [], "decay": [], "phase": []} for _ in P["harmonics"]]
    for _ in range(B):
        bs = stats.take(rng.integers(0, S, S))
        if len(np.unique(np.round(bs.speed, 9))) < len(base_names):
            continue
        try:
            prob = _make_problem(bs, law, specs, weights)
            Q = _direction_params(prob, _fit_direction(prob))
        except (InputError, np.linalg.LinAlgError, ValueError):
            continue
        for k in base_names:
            draws[k].append(Q[k])
        for k, h in enumerate(Q["harmonics"]):
            hdraws[k]["amplitude"].append(h["amplitude"])
            hdraws[k]["decay"].append(h["decay"])
            hdraws[k]["phase"].append(h["phase"])
    for k in base_names:
        if len(draws[k]) >= 10:
            P[k + "_se"] = float(np.std(draws[k], ddof=1))
    for h, dr in zip(P["harmonics"], hdraws):
        if len(dr["amplitude"]) >= 10:
            h["amplitude_se"] = float(np.std(dr["amplitude"], ddof=1))
            h["decay_se"] = float(np.std(dr["decay"], ddof=1))
            ph = np.angle(np.exp(1j * (np.asarray(dr["phase"]) - h["phase"])))
            h["phase_se"] = float(np.sqrt(np.mean(ph ** 2)))
    P["se_method"] = f"bootstrap over segments ({B} resamples)"


# ---------------------------------------------------------------------- held-out errors
def _folds(data: FitData, by: str, folds: int) -> np.ndarray:
    """Fold of every sample: its segment's (or run's) fold by THE rule of :mod:`gearspec.core.crossval`."""
    from ..core.crossval import row_folds

    return row_folds(data.groups(by), data.direction, data.v, folds)


def holdout_rmse(fit_fn: Callable[[FitData], FrictionModel], data: FitData, *, by: str = "segment",
                 folds: int = 5, residual: Callable | None = None) -> float | None:
    """Root-mean-square error on held-out data: ``folds``-fold cross-validation over whole
    segments (or runs); each fold is predicted by a model fitted to the others.  Folds where the
    fit fails (too few speeds left) are skipped; None when every fold fails.  ``residual(model,
    test_data)`` gives the error of a fold (default: ``model.residual``, friction torque).
    :func:`holdout` gives the reason too."""
    return holdout(fit_fn, data, by=by, folds=folds, residual=residual)[0]


def holdout(fit_fn: Callable[[FitData], FrictionModel], data: FitData, *, by: str = "segment",
            folds: int = 5, residual: Callable | None = None) -> tuple[float | None, str | None]:
    """:func:`holdout_rmse` and why it is missing or partial: ``(rmse, reason)``.

    ``rmse`` is None when cross-validation cannot run -- fewer than two held-out groups, or no
    fold whose model can be fitted without it and predict it (each direction needs its own
    groups, and enough speeds left for the law) -- and ``reason`` says which, in one sentence;
    never the in-sample error in its place.  When some folds fail, ``rmse`` comes from the others
    and ``reason`` says how many held-out samples it covers.  Folds: :mod:`gearspec.core.crossval`."""
    from ..core.crossval import held_out

    ng = len(np.unique(data.groups(by)))
    if ng < 2:
        return None, (f"cross-validation needs two held-out {by}s or more; the data have {ng}")

    def score(m, test):
        t = data.subset(test)
        r = np.asarray(m.residual(t) if residual is None else residual(m, t), dtype=float)
        return np.where(np.isfinite(r), r * r, np.nan)

    h = held_out(_folds(data, by, folds), lambda train: fit_fn(data.subset(train)), score)
    n, failed = h.covered, h.failed
    if not n:
        why = failed[0] if failed else f"every {by} falls into one fold"
        return None, (f"cross-validation over {ng} {by}s could not run: no fold could be fitted without its "
                      f"{by}s and predict them ({why})")
    if n < len(data):
        return h.rmse, (f"from {n} of {len(data)} samples: {len(failed)} of {h.ran} folds could not be "
                        f"fitted without their {by}s ({failed[0] if failed else 'no test data'})")
    return h.rmse, None


def refit(model: FrictionModel, data: FitData, **overrides) -> FrictionModel:
    """Fit ``model``'s law and harmonics again, with the settings it was fitted with, to other data."""
    s = dict(model.meta.get("fit") or {})
    if not s:
        raise InputError("this model carries no fit settings (it was not made by gearspec.identify.fit)")
    kw = {"harmonics": s.get("harmonics") or None, "weights": s.get("weights", "segment"), "se": "covariance",
          "min_cycles": s.get("min_cycles", 1.0), "name": model.name, "check": False}
    if s["law"] != "silo4" and not s.get("harmonics"):
        kw["harmonics"] = None
    if s["law"] == "silo4" and not s.get("harmonics"):
        kw["harmonics"] = []
    kw.update(overrides)
    if s.get("method") == "efficiency":
        return fit_efficiency(data, s["law"], ratio=s["ratio"], holdout=kw.get("holdout"), name=model.name)
    return fit(data, s["law"], **kw)


def compare(data: FitData, candidates: Mapping[str, FrictionModel | Mapping], *, by: str = "segment",
            folds: int = 5) -> pd.DataFrame:
    """Models side by side on the same data: rmse (in-sample) and held-out rmse.

    ``candidates`` maps a name to a fitted model (refitted per fold with its own settings for the
    held-out error; a model without fit settings cannot be refitted: ``rmse_holdout`` None, never
    its in-sample rmse) or to keyword arguments of :func:`fit` (``{"law": "stribeck"}``).
    ``rmse_holdout_reason`` says why a held-out rmse is missing or partial (:func:`holdout`).
    """
    rows = []
    for name, c in candidates.items():
        if isinstance(c, FrictionModel):
            m = c
            if m.meta.get("fit"):
                ho, why = holdout(lambda tr, m=m: refit(m, tr, holdout=None), data, by=by, folds=folds)
            else:
                ho, why = None, "the model carries no fit settings to refit it without the held-out data"
        else:
            kw = dict(c)
            kw.setdefault("holdout", None)
            m = fit(data, **kw)
            ho, why = holdout(lambda tr, kw=kw: fit(tr, **{**kw, "check": False}), data, by=by, folds=folds)
        n_par = _n_params(m)
        rows.append({"model": name, "law": m.law, "parameters": n_par, "rmse": _safe_rmse(m, data),
                     "rmse_holdout": ho, "rmse_holdout_reason": why})
    return pd.DataFrame(rows)


def _n_params(m: FrictionModel) -> int:
    from ..core.crossval import n_params

    return n_params(m)


# ---------------------------------------------------------------------- the published SILO4 procedure
def line_amplitudes(data: FitData, harmonics, *, min_cycles: float = 1.0) -> pd.DataFrame:
    """Amplitude, phase and standard error of each line in each segment where it completes
    ``min_cycles`` cycles: the joint least-squares fit of the lines and a constant on the segment's
    own samples (what the spectra of :mod:`gearspec.spectrum` measure at declared lines, with white-
    noise errors).  One row per (segment, line)."""
    specs = harmonic_specs(harmonics)
    rows = []
    for d in (1, -1):
        sub = data.direction_subset(d)
        if len(sub) == 0 or not specs:
            continue
        st = segment_stats(sub, [h["frequency"] for h in specs], min_cycles=min_cycles)
        for i, sid in enumerate(st.segment):
            try:
                cov = np.linalg.pinv(st.G[i], rcond=1e-12, hermitian=True) * (st.sigma2[i] if np.isfinite(st.sigma2[i])
                                                                               else np.nan)
            except np.linalg.LinAlgError:
                cov = np.full(st.G[i].shape, np.nan)
            for k, h in enumerate(specs):
                if not st.active[i, k]:
                    continue
                ia, ic = 1 + 2 * k, 2 + 2 * k
                a_, c_ = st.beta_hat[i, ia], st.beta_hat[i, ic]
                A = math.hypot(a_, c_)
                g = np.array([a_, c_]) / A if A > 0 else np.zeros(2)
                se = math.sqrt(max(g @ cov[np.ix_([ia, ic], [ia, ic])] @ g, 0.0)) if A > 0 else float("nan")
                rows.append({"segment": int(sid), "direction": d, "speed": float(st.speed[i]),
                             "label": h.get("label"), "frequency": h["frequency"], "amplitude": A,
                             "amplitude_se": se, "phase": math.atan2(c_, a_)})
    return pd.DataFrame(rows, columns=["segment", "direction", "speed", "label", "frequency", "amplitude",
                                       "amplitude_se", "phase"])


def amplitudes_from_spectrum(spectrum, data: FitData, harmonics=None) -> pd.DataFrame:
    """The declared-line peaks of a :class:`~gearspec.spectrum.SpectrumResult` in the form of
    :func:`line_amplitudes`, matched to ``data``'s segments (same segmentation)."""
    specs = harmonic_specs(harmonics, spectrum.gear) if harmonics is None else harmonic_specs(harmonics)
    rows = []
    for s in spectrum.segments:
        sid = _segment_id(data.segments, s)
        if sid is None:
            continue
        for h in specs:
            p = s.peak(h["label"]) if h.get("label") else None
            if p is not None and p.amplitude > 0:
                rows.append({"segment": sid, "direction": s.direction, "speed": s.speed, "label": h["label"],
                             "frequency": h["frequency"], "amplitude": p.amplitude, "amplitude_se": p.amplitude_se,
                             "phase": p.phase})
    return pd.DataFrame(rows, columns=["segment", "direction", "speed", "label", "frequency", "amplitude",
                                       "amplitude_se", "phase"])


def silo4_published(data: FitData, amplitudes=None, *, harmonics=None, gear=None, high_speed: float = 100 * RPM,
                    constant: Iterable[str] = ("output shaft",), min_cycles: float = 1.0,
                    holdout: str | None = "segment", folds: int = 5) -> FrictionModel:
    """The SILO4 identification procedure as published (section 3-4; see the module docstring).

    Parameters
    ----------
    data : FitData
        Samples in segments (the plateau averages come from it).
    amplitudes : DataFrame or SpectrumResult, optional
        Per-segment amplitudes and phases of the lines (:func:`line_amplitudes`, or the spectra of
        :func:`gearspec.spectrum.analyze` on the same segmentation).  Default: measured from
        ``data`` at the lines of ``harmonics``/``gear``.
    harmonics, gear
        The lines (:func:`harmonic_specs`); none: eq. 3 only.
    high_speed : float
        Plateaus above this speed give Coulomb and viscous friction (the paper: 100 rpm, in rad/s
        here); the others static friction and Stribeck velocity.
    constant : labels
        Lines modelled with a constant amplitude (eq. 6): the paper's F1, one joint turn.
    """
    specs = harmonic_specs(harmonics, gear)
    if amplitudes is None:
        amplitudes = line_amplitudes(data, specs, min_cycles=min_cycles)
    elif not isinstance(amplitudes, pd.DataFrame):
        if not specs and amplitudes.gear is not None:
            specs = harmonic_specs(None, amplitudes.gear)
        amplitudes = amplitudes_from_spectrum(amplitudes, data, specs)
    model = _published(data, amplitudes, specs, high_speed, set(constant))
    if holdout:
        def fit_fold(train):  # the plateaus and line amplitudes of the training segments only
            amp = amplitudes[amplitudes["segment"].isin(np.unique(train.segment))]
            return _published(train, amp, specs, high_speed, set(constant))

        model.rmse_holdout, model.rmse_holdout_reason = _holdout_of(fit_fold, data, by=holdout, folds=folds)
    return model


def _published(data: FitData, amplitudes: pd.DataFrame, specs, high_speed, constant) -> FrictionModel:
    plate = data.plateaus()
    directions, ni, notes = {}, {}, []
    for d, dname in ((1, "positive"), (-1, "negative")):
        pl = plate[plate["direction"] == d]
        P = {"tau_c": None, "tau_s": None, "v_s": None, "viscous": None, "harmonics": []}
        if pl.empty:
            for k in ("tau_c", "tau_s", "v_s", "viscous"):
                ni[f"{dname}.{k}"] = f"no segment in the {dname} direction"
            directions[dname] = P
            continue
        hi = pl[pl["speed"] > high_speed]
        lo = pl[pl["speed"] <= high_speed]
        if len(hi) >= 2:
            X = np.column_stack([np.ones(len(hi)), hi["speed"]])
            coef, se = _ols(X, hi["level"].to_numpy())
            P["tau_c"], P["viscous"] = float(coef[0]), float(coef[1])
            P["tau_c_se"], P["viscous_se"] = float(se[0]), float(se[1])
        else:
            ni[f"{dname}.tau_c"] = ni[f"{dname}.viscous"] = (f"needs two plateaus above {high_speed:.4g} "
                                                               f"{data.unit}/s in the {dname} direction, has {len(hi)}")
        if P["tau_c"] is not None:
            excess = lo["level"].to_numpy() - P["tau_c"]
            ok = excess > 0
            if ok.sum() >= 2:
                X = np.column_stack([np.ones(ok.sum()), lo["speed"].to_numpy()[ok]])
                coef, se = _ols(X, np.log(excess[ok]))
                m_, n_ = coef[1], coef[0]
                if m_ < 0:
                    P["v_s"] = float(-1.0 / m_)
                    P["v_s_se"] = float(se[1] / m_ ** 2)
                    P["tau_s"] = float(P["tau_c"] + math.exp(n_))
                    P["tau_s_se"] = float(math.exp(n_) * se[0])
                    if ok.sum() < len(lo):
                        notes.append(f"{dname}: {len(lo) - ok.sum()} low-speed plateau(s) below the Coulomb level "
                                     f"left out of the log-linear fit (eq. 4 cannot take their log)")
                else:
                    ni[f"{dname}.v_s"] = ni[f"{dname}.tau_s"] = "the low-speed plateaus do not fall with speed"
            else:
                ni[f"{dname}.v_s"] = ni[f"{dname}.tau_s"] = (f"needs two plateaus below {high_speed:.4g} "
                                                             f"{data.unit}/s above the Coulomb level, has {ok.sum()}")
        # amplitudes and decays from the per-segment line fits (eq. 10), phases by circular mean
        for h in specs:
            lab = h.get("label")
            rows = amplitudes[(amplitudes["direction"] == d) & np.isclose(amplitudes["frequency"], h["frequency"])]
            rows = rows[rows["amplitude"] > 0]
            key = f"{dname}.{lab or h['frequency']}"
            if rows.empty:
                ni[key] = "not fitted in any segment (too few cycles)"
                continue
            sp, amp, ph = rows["speed"].to_numpy(), rows["amplitude"].to_numpy(), rows["phase"].to_numpy()
            phase = float(np.angle(np.sum(amp * np.exp(1j * ph))))
            # the amplitude law holds over the speeds of the segments that measured the line
            entry = {"frequency": h["frequency"], "phase": phase,
                     "speed_range": [float(np.min(sp)), float(np.max(sp))]}
            if lab:
                entry["label"] = lab
            if lab in constant or len(np.unique(np.round(sp, 9))) < 2:
                entry.update(amplitude=float(np.mean(amp)), decay=0.0, decay_se=0.0, law="const",
                             amplitude_se=float(np.std(amp, ddof=1) / math.sqrt(len(amp))) if len(amp) > 1
                             else float("nan"))
                if lab not in constant:
                    ni[key + ".decay"] = "the line is measured at one speed only"
            else:
                coef, se = _ols(np.column_stack([np.ones(len(sp)), sp]), np.log(amp))
                entry.update(amplitude=float(math.exp(coef[0])), amplitude_se=float(math.exp(coef[0]) * se[0]),
                             decay=float(-coef[1]), decay_se=float(se[1]))
            P["harmonics"].append(entry)
        directions[dname] = P
    model = FrictionModel("silo4", directions["positive"], directions["negative"], unit=data.unit,
                          not_identified=ni, notes=notes, name="SILO4 published procedure",
                          meta={"procedure": "published", "high_speed": high_speed})
    model.rmse = _safe_rmse(model, data)
    return model


def _segment_id(segments: pd.DataFrame, seg_spectrum) -> int | None:
    s = seg_spectrum.segment
    m = segments[(segments["run"] == s.run) & (segments["direction"] == s.direction)
                 & (np.isclose(segments["speed"], s.speed))]
    return int(m["segment"].iloc[0]) if len(m) else None


def _ols(X, y):
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    dof = max(len(y) - X.shape[1], 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(X.T @ X) * s2
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        se = np.full(X.shape[1], np.nan)
    if len(y) <= X.shape[1]:
        se = np.full(X.shape[1], np.nan)
    return coef, se


# ---------------------------------------------------------------------- Lola/CROPS: efficiency
def efficiency_model(model: FrictionModel, v, load, ratio: float) -> np.ndarray:
    """Efficiency a friction model predicts when the motor drives the load (Lola eq. 13 with
    eq. 12): ``eta = (|T_l|/N) / (|T_l|/N + |tau_f(v, T_l)|)``."""
    tau = model.friction(None, v, load=load)
    return laws.efficiency_from_friction(tau, load, ratio)


_EFF_LAWS = ("lola8", "lola11")


def fit_efficiency(data: FitData, law: str = "lola8", *, ratio: float, init: FrictionModel | None = None,
                   holdout: str | None = None, folds: int = 5, name: str | None = None,
                   gamma_free: bool = True) -> FrictionModel:
    """Fit law (8) or (11) to the *efficiency* of quasi-static points (Lola eq. 9) under the
    constraints of eq. 10 (``T_f0, mu, b >= 0``; law (11) also ``T_fS >= 0``, ``v_S > 0``).

    ``data`` carries the measured efficiency as ``y`` (dimensionless) with ``v`` the motor speed
    and ``load`` the output torque (e.g. ``FitData.from_points(v, eta, load=T_l)``).  The RMS of the
    efficiency residual is ``rmse`` (what the paper's Tables III-V call RMS).  Symmetric model.
    """
    if law not in _EFF_LAWS:
        raise InputError(f"efficiency fits take law lola8 or lola11, got '{law}'")
    if data.load is None:
        raise InputError("an efficiency fit needs the output load torque ('load')")
    if not ratio or ratio <= 0:
        raise InputError("an efficiency fit needs the gear ratio N")
    eta = np.asarray(data.y, dtype=float)
    v = np.abs(data.v)
    tl = np.abs(data.load)
    if np.any(tl <= 0):
        raise InputError("efficiency points need a nonzero load (eta = 0 at no load carries no information)")
    all_names = list(LAWS[law].params)
    fixed = {"gamma": 0.0} if (not gamma_free and "gamma" in all_names) else {}
    names = [k for k in all_names if k not in fixed]
    # start: friction implied by the efficiency, fitted linearly
    tau_implied = (tl / ratio) * (1.0 / np.clip(eta, 1e-3, None) - 1.0)
    pts = FitData.from_points(v, tau_implied, load=tl, unit=data.unit)
    src = init
    if src is None:
        try:
            src = fit(pts, law, holdout=None, weights="uniform", check=False)
        except InputError:
            src = None
    if src is not None:
        x0 = np.array([src.params("positive")[k] for k in names], float)
    else:
        guess = {"t_f0": float(np.median(tau_implied)), "mu": 1e-3, "b": 1e-4, "gamma": 0.0,
                 "t_fs": float(np.median(tau_implied)), "v_s": float(np.median(v))}
        x0 = np.array([guess[k] for k in names])
    lo = np.full(len(names), -np.inf)
    for k in LAWS[law].nonneg:
        if k in names:
            lo[names.index(k)] = 0.0
    if "v_s" in names:
        lo[names.index("v_s")] = 1e-9
    x0 = np.where(np.isfinite(lo), np.maximum(x0, lo + 1e-12), x0)

    def params_of(x):
        p = dict(zip(names, x))
        p.update(fixed)
        return [p[k] for k in all_names]

    def resid(x):
        tau = LAWS[law].magnitude(v, tl, *params_of(x))
        return laws.efficiency_from_friction(tau, tl, ratio) - eta

    scale = np.where(np.abs(x0) > 0, np.abs(x0), 1.0)
    res = optimize.least_squares(resid, x0, bounds=(lo, np.inf), x_scale=scale, method="trf", max_nfev=2000)
    if res.status <= 0:
        raise ConvergenceError(f"the efficiency fit of law {law} did not converge ({res.message})")
    r = res.fun
    dof = max(len(r) - len(names), 1)
    s2 = float(r @ r) / dof
    cov = np.linalg.pinv(res.jac.T @ res.jac) * s2
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    P = {k: float(x) for k, x in zip(names, res.x)}
    P.update({k + "_se": float(e) for k, e in zip(names, se)})
    for k, val in fixed.items():
        P[k], P[k + "_se"] = val, 0.0
    at_bound = [k for k, x, lb in zip(names, res.x, lo) if np.isfinite(lb) and x <= lb + 1e-12 and k != "gamma"]
    notes = [f"fitted to efficiency (eq. 9) of {len(r)} points, ratio N = {ratio:g}; constraints of eq. 10"]
    if at_bound:
        notes.append("at the eq. 10 bound (0): " + ", ".join(at_bound))
    m = FrictionModel(law, P, None, unit=data.unit, notes=notes, name=name or f"{law} (efficiency fit)",
                      meta={"fit": {"law": law, "method": "efficiency", "ratio": ratio}})
    m.rmse = float(math.sqrt(np.mean(r * r)))
    if holdout:
        m.rmse_holdout, m.rmse_holdout_reason = _eff_holdout(data, law, ratio, holdout, folds)
    return m


def _eff_holdout(data, law, ratio, by, folds):
    return _holdout_of(lambda tr: fit_efficiency(tr, law, ratio=ratio), data, by=by, folds=folds,
                       residual=lambda m, t: efficiency_model(m, t.v, t.load, ratio) - t.y)


def fit_catalog(table: pd.DataFrame, *, ratio: float, law: str = "lola8", drop_extrapolated: bool = True
                ) -> tuple[FrictionModel, pd.DataFrame]:
    """Fit law (8) (or (11)) to a catalog efficiency table (Lola Table V), as the paper does.

    ``table`` has columns ``input_speed_rpm``, ``load`` (output torque, Nm) and ``efficiency``
    -- e.g. the product form ``eta_R(speed) * K(load)`` of ``gearspec.datasets.load
    ("harmonic_drive_catalog")``.  Rows at zero speed (an extrapolation in that source) and zero
    load (zero output power, where efficiency carries no information) are left out when
    ``drop_extrapolated``.  Returns the model (``rmse``: RMS of the efficiency residual) and the
    table with the model's efficiency beside the catalog's.
    """
    need = {"input_speed_rpm", "load", "efficiency"}
    if not need <= set(table.columns):
        raise InputError(f"a catalog table needs columns {sorted(need)}, has {list(table.columns)}")
    t = table.copy()
    if drop_extrapolated:
        t = t[(t["input_speed_rpm"] > 0) & (t["load"] > 0)]
    data = FitData.from_points(t["input_speed_rpm"].to_numpy() * RPM, t["efficiency"].to_numpy(),
                               load=t["load"].to_numpy())
    m = fit_efficiency(data, law, ratio=ratio, name=f"law ({law[4:]}) fitted to catalog efficiency")
    out = table.copy()
    ok = (out["load"] > 0)
    out["model"] = np.nan
    out.loc[ok, "model"] = efficiency_model(m, out.loc[ok, "input_speed_rpm"].to_numpy() * RPM,
                                            out.loc[ok, "load"].to_numpy(), ratio)
    out["used"] = out.index.isin(t.index)
    return m, out


# ---------------------------------------------------------------------- validation per segment
def segment_errors(model: FrictionModel, data: FitData) -> pd.DataFrame:
    """Model error per segment, as SILO4 validates its model (eqs. 12-13, Table 3): the mean
    error ``e`` and its standard deviation ``s_e`` of ``model - data`` (friction magnitudes, so that
    a model above the data is positive in both directions), the rmse, the mean friction and ``e``
    in percent of it.  Segments of a direction the model cannot predict are left out."""
    rows = []
    for sid in np.unique(data.segment):
        sub = data.subset(data.segment == sid)
        d = int(sub.direction[0])
        try:
            pred = model.evaluate(**sub.inputs())
        except InputError:
            continue
        err = d * (pred - sub.y)
        level = float(np.mean(d * sub.y))
        rows.append({"segment": int(sid), "run": int(sub.run[0]), "direction": d,
                     "speed": float(np.mean(np.abs(sub.v))), "n": len(sub), "level": level,
                     "e": float(np.mean(err)), "s_e": float(np.std(err, ddof=1)) if len(err) > 1 else float("nan"),
                     "rmse": float(np.sqrt(np.mean(err ** 2))),
                     # in percent of the mean friction; undefined (NaN) where that mean is 0
                     "e_percent": 100 * float(np.mean(err)) / level if level != 0 else float("nan")})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------- a whole recording
@dataclass
class FitResult:
    """What :func:`identify_recording` (``gearspec fit``) produces.

    ``model``: the requested law, fitted jointly; ``models``: it and the models it is compared
    with (the published procedure for ``silo4``, simpler laws), by name; ``comparison``: rmse and
    held-out rmse of each on the same data; ``errors``: per-segment errors of each (SILO4 eqs.
    12-13); ``data``: what they were fitted to; ``amplitudes``: the lines' amplitude, phase and
    standard error in every segment (:func:`line_amplitudes`).
    """

    model: FrictionModel
    models: dict
    comparison: pd.DataFrame
    errors: dict
    data: FitData
    amplitudes: pd.DataFrame | None = None
    notes: list = None

    def to_dict(self) -> dict:
        """The ``gearspec fit --json`` form (CONTRACTS.md section 4) plus the comparison."""
        d = self.model.to_dict()
        d["comparison"] = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()}
                           for r in self.comparison.to_dict("records")]
        d["models"] = {name: m.to_dict() for name, m in self.models.items() if m is not self.model}
        return d


#: laws compared with each law by default, and whether they get the same lines
_COMPARE_WITH = {"silo4": (("stribeck", False), ("coulomb_viscous", True)), "stribeck": (("coulomb_viscous", False),),
                 "lola11": (("lola8", False),), "lola8": (("lola11", False),), "coulomb_viscous": (), "none": ()}


def identify_recording(rec, law: str = "silo4", *, segmentation=None, gear=None, harmonics=None,
                       published: bool | None = None, holdout: str = "segment", folds: int = 5,
                       se: str = "covariance", load_ratio: float | None = None,
                       compare_with=None) -> FitResult:
    """Identify ``law`` from a recording, beside the published procedure and simpler laws.

    Parameters
    ----------
    rec : Recording
    law : str
        A key of :data:`gearspec.model.LAWS`.
    segmentation, gear
        Default: found segments, the recording's gear spec.
    harmonics
        Lines to fit (:func:`harmonic_specs`); default for ``silo4``: every declared line.
    published : bool
        Also run :func:`silo4_published` (default: for ``silo4`` and ``stribeck``).
    holdout, folds, se
        As in :func:`fit`.
    load_ratio : float, optional
        Subtract ``|load| / load_ratio`` (the load seen at the motor, eq. 12) from the torque;
        default for the Lola laws: the gear's total ratio when the recording has a load.
    compare_with : sequence of str, optional
        Other laws fitted to the same data (default: the simpler ones).
    """
    from ..segment import find_segments

    gear = load_gear(gear) if gear is not None else rec.gear
    seg = segmentation if segmentation is not None else find_segments(rec)
    notes = []
    if law in ("lola8", "lola11") and load_ratio is None and "load" in rec.data and gear is not None and gear.stages:
        load_ratio = gear.total_ratio
        notes.append(f"friction = drive torque - |load| / {load_ratio:g} (Lola eq. 12; the load opposes the motion)")
    data = FitData.from_recording(rec, seg, load_ratio=load_ratio)
    if published is None:
        published = law in ("silo4", "stribeck")
    lines = harmonic_specs(harmonics, gear) if law == "silo4" else (harmonic_specs(harmonics) if harmonics else [])
    amplitudes = line_amplitudes(data, lines) if lines else None
    model = fit(data, law, harmonics=harmonics, gear=gear, holdout=holdout, folds=folds, se=se,
                name=f"{law} (joint fit)")
    models = {model.name: model}
    if published:
        pm = silo4_published(data, amplitudes, harmonics=lines, holdout=holdout, folds=folds)
        if law == "stribeck":
            for p in pm.directions.values():
                p["harmonics"] = []
            pm.law = "stribeck"
            pm.rmse = _safe_rmse(pm, data)
        models[pm.name] = pm
    others = _COMPARE_WITH.get(law, ()) if compare_with is None else [(o, True) for o in compare_with]
    for other, with_lines in others:
        h = lines if with_lines else []
        try:
            m = fit(data, other, harmonics=h, gear=gear, holdout=holdout, folds=folds,
                    name=other + (" + lines" if h else ""))
            models[m.name] = m
        except InputError as exc:
            notes.append(f"{other} not fitted: {exc}")
    rows = [{"model": name, "law": m.law, "parameters": _n_params(m), "rmse": m.rmse,
             "rmse_holdout": m.rmse_holdout, "rmse_holdout_reason": m.rmse_holdout_reason}
            for name, m in models.items()]
    errors = {name: segment_errors(m, data) for name, m in models.items()}
    return FitResult(model, models, pd.DataFrame(rows), errors, data, amplitudes, notes)
