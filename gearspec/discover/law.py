"""Candidate laws: a structure (a tuple of :class:`Part`), fitted on the pseudo rows of
:mod:`.moments` with its nonlinear parameters refined by variable projection (:func:`fit_law`: a
refit costs microseconds, whatever the number of samples), scored on held-out segments, printed as
an equation, exported as a :class:`~gearspec.model.FrictionModel`.

Standard errors: cluster-robust (sandwich) covariance with the segments as clusters (residuals are
correlated within a segment: unmodelled ripple, coloured noise); with fewer segments than
parameters + 2 the ordinary covariance, and the law says so.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from ..core.crossval import deal_folds, group_summary, held_out
from ..model import FrictionModel
from . import lsq
from .library import FAMILIES, _g
from .lsq import NormalSolver
from .moments import Moments

__all__ = ["Part", "LawFit", "fit_law", "fold_ids", "canonical", "complexity"]

_ORDER = list(FAMILIES)


@dataclass(frozen=True)
class Part:
    """One term of a candidate law: a library family, its ripple frequency (index), whether it is
    direction-dependent (``split``: its own coefficients and nonlinear parameter per direction) and
    the start value of its nonlinear parameter (the grid value the sparse regression picked)."""

    family: str
    freq: int | None = None
    split: bool = False
    param0: float | None = None

    @property
    def fam(self):
        return FAMILIES[self.family]

    def slots(self) -> tuple[int, ...]:
        """0: both directions alike; (+1, -1): one set of values per direction."""
        return (1, -1) if self.split and self.fam.basis != "acc" else (0,)

    def n_linear(self) -> int:
        return 2 if self.fam.basis == "ripple" else 1

    @property
    def free(self) -> bool:
        """Has a nonlinear parameter that is refined."""
        return bool(self.fam.param) and self.fam.refine

    def n_params(self) -> int:
        return (self.n_linear() + (1 if self.free else 0)) * len(self.slots())

    def label(self, frequencies=None) -> str:
        s = self.family
        if self.freq is not None:
            f = frequencies[self.freq] if frequencies is not None else self.freq
            s += f"@{_g(float(f), 6)}"
        return s + ("[dir]" if self.split else "")


def canonical(parts) -> tuple:
    """Structures compare equal whatever order their parts came in."""
    return tuple(sorted(parts, key=lambda p: (_ORDER.index(p.family), -1 if p.freq is None else p.freq,
                                              p.param0 or 0.0, p.split)))


def complexity(parts) -> int:
    """Number of free parameters (linear coefficients and nonlinear parameters)."""
    return int(sum(p.n_params() for p in parts))


def fold_ids(m: Moments, by: str = "segment", folds: int = 5) -> np.ndarray:
    """Fold of every segment of ``m``: its group's (segment's or run's) fold by THE rule of
    :mod:`gearspec.core.crossval`, from the same group summaries as :func:`gearspec.identify.fit`
    and the closed loop (direction, mean ``|v|`` over the group's samples, ties by group id)."""
    g = m.groups(by)
    vabs = m.speed if m.vabs is None else m.vabs
    ids, sign, speed = group_summary(g, m.direction, vabs, weight=m.n)
    return deal_folds(sign, speed, ids, folds)[np.searchsorted(ids, g)]


# ---------------------------------------------------------------------- design
@dataclass
class _Layout:
    cols: list            # (part index, slot, basis name)
    nl: list              # (part index, slot): the nonlinear parameters, in z order
    lo: np.ndarray
    hi: np.ndarray


def _layout(parts, m: Moments) -> _Layout:
    cols, nl, lo, hi = [], [], [], []
    speeds = m.speed[m.speed > 0]
    vlo, vhi = (float(np.min(speeds)), float(np.max(speeds))) if len(speeds) else (1.0, 1.0)
    for i, p in enumerate(parts):
        fam = p.fam
        names = [f"sin{p.freq}", f"cos{p.freq}"] if fam.basis == "ripple" else [fam.basis]
        for sl in p.slots():
            for b in names:
                cols.append((i, sl, b))
            if p.free:
                a, b_ = fam.bounds(vlo, vhi)
                nl.append((i, sl))
                lo.append(math.log(a))
                hi.append(math.log(b_))
    return _Layout(cols, nl, np.array(lo), np.array(hi))


def _slots(parts, lay: _Layout, m: Moments) -> list:
    """Per (part, slot) of a law: its columns, magnitude function, per-segment sign, index of its
    nonlinear parameter in ``z`` (None: fixed) and fixed value; what :func:`_multipliers` needs,
    computed once per fit rather than at every evaluation of the optimiser."""
    zpos = {key: k for k, key in enumerate(lay.nl)}
    d = m.direction.astype(float)
    out = []
    for key in dict.fromkeys((i, sl) for i, sl, _ in lay.cols):
        i, sl = key
        p = parts[i]
        sgn = np.ones(m.S) if p.fam.basis == "acc" else (d if sl == 0 else sl * (m.direction == sl))
        cols = [j for j, (ii, ss, _) in enumerate(lay.cols) if (ii, ss) == key]
        out.append((cols, p.fam.magnitude, sgn, zpos.get(key), p.param0))
    return out


def _multipliers(parts, lay: _Layout, m: Moments, z: np.ndarray, deriv: bool = False, slots=None):
    """(S, p) per-segment multipliers of the law's columns for nonlinear parameters exp(z); with
    ``deriv`` also their derivatives with respect to each z (:func:`_derivatives`).
    ``slots``: :func:`_slots` of these parts, layout and moments (computed when not given)."""
    slots = slots if slots is not None else _slots(parts, lay, m)
    A = np.empty((m.S, len(lay.cols)))
    for cols, mag, sgn, k, p0 in slots:
        pv = p0 if k is None else math.exp(z[k])
        A[:, cols] = (sgn * mag(m.speed, pv))[:, None]
    return (A, _derivatives(m, z, slots)) if deriv else A


def _derivatives(m: Moments, z: np.ndarray, slots) -> list:
    """Derivatives of the multipliers with respect to each z (central differences in z): a list,
    per nonlinear parameter, of (column, (S,) derivative) pairs."""
    dA = [[] for _ in z]
    for cols, mag, sgn, k, p0 in slots:
        if k is None:
            continue
        pv, h = math.exp(z[k]), 1e-6
        dcol = sgn * (mag(m.speed, pv * math.exp(h)) - mag(m.speed, pv * math.exp(-h))) / (2 * h)
        dA[k] = [(j, dcol) for j in cols]
    return dA


def _basis_index(lay: _Layout, m: Moments) -> np.ndarray:
    return np.array([m.index(b) for _, _, b in lay.cols], dtype=int)


def _design(parts, lay, m: Moments, z) -> np.ndarray:
    A = _multipliers(parts, lay, m, z)
    # (P[:, :, kidx] is laid out basis-major: made C-ordered, the product reshapes without a copy)
    Pk = np.ascontiguousarray(m.P[:, :, _basis_index(lay, m)])
    return (A[:, None, :] * Pk).reshape(m.S * m.K, len(lay.cols))


def _solve(X, y):
    """Least squares by SVD of the column-scaled design: coefficients, and the orthonormal basis
    of the column space (for the variable-projection Jacobian).  Directions the data do not
    determine (a column absent from the data, exact collinearity) get the minimum-norm answer."""
    nrm = np.sqrt(np.sum(X * X, axis=0))
    nrm[nrm == 0] = 1.0
    Xn = X / nrm
    if X.shape[0] >= X.shape[1]:
        Q, R = np.linalg.qr(Xn)
        d = np.abs(np.diag(R))
        if len(d) and d.min() > 1e-8 * d.max():
            return np.linalg.solve(R, Q.T @ y) / nrm, Q
    U, sv, Vt = np.linalg.svd(Xn, full_matrices=False)
    keep = sv > (sv[0] if len(sv) else 0.0) * 1e-10
    U, sv, Vt = U[:, keep], sv[keep], Vt[keep]
    w = (Vt.T @ ((U.T @ y) / sv)) / nrm
    return w, U


def _solve_fast(X, y, basis: bool = True):
    """:func:`_solve`'s coefficients through the normal equations (:class:`.lsq.NormalSolver`)
    where the design allows, else by :func:`_solve`.  Returns the coefficients and what
    :func:`_project_out` needs: the solver, or (with ``basis``) the QR path's orthonormal basis."""
    ns = NormalSolver.of(X)
    w = ns.solve(y) if ns is not None else None
    if w is not None:
        return w, ns
    w, U = _solve(X, y)
    return w, (U if basis else None)


def _project_out(ns, X, v):
    """``v`` (n,) or the columns of ``v`` (n, m) minus their projections on the column space of
    ``X``; ``ns`` from :func:`_solve_fast`."""
    if isinstance(ns, NormalSolver):
        r = ns.residual(v)
        if r is not None:
            return r
        ns = _solve(X, v if v.ndim == 1 else v[:, 0])[1]      # the basis does not depend on the target
    return v - ns @ (ns.T @ v)


def _solve_law(A, Pk, q, D=None):
    """A law's least squares at the multipliers ``A`` (S, p) on its pseudo rows ``Pk`` (S, K, p)
    and targets ``q`` (S*K,): ``(design, coefficients, solver or QR basis, residual)``.  With ``D``
    (S, p), the pseudo rows' squared column sums (a large design: :data:`.lsq.MIN_SIZE`), the design
    is built column-scaled in one pass (``|X_j|^2 = sum_s a_sj^2 D_sj``) for the normal equations,
    and the design returned is that scaled one; else (or where they refuse) :func:`_solve_fast`."""
    S, K, ncol = Pk.shape
    if D is not None:
        amax = np.max(np.abs(A), axis=0)
        amax[amax == 0] = 1.0
        As = A / amax                   # tiny multipliers are not squared to zero
        nrm = np.sqrt(np.sum(As * As * D, axis=0)) * amax
        if np.all(nrm > 0):
            Xn = ((A / nrm)[:, None, :] * Pk).reshape(-1, ncol)
            ns = NormalSolver.of((Xn, nrm))
            c = ns.coef_scaled(q) if ns is not None else None
            if c is not None:
                return Xn, c / nrm, ns, q - Xn @ c
    X = (A[:, None, :] * Pk).reshape(-1, ncol)
    w, ns = _solve_fast(X, q)
    return X, w, ns, q - X @ w


def _scan(z, lay: _Layout, m: Moments, slots, sse_at):
    """The start of a refinement: each nonlinear parameter scanned over 5 inner points of its
    range (7-point grid), the others held at the best so far (``sse_at``: residual sum of squares
    at the multipliers); only the scanned parameter's columns are recomputed at its grid points.
    Variable projection has local optima (a Stribeck velocity beyond the plateaus trading against
    Coulomb and viscous friction): the refinement starts from the best point of the scan."""
    A0 = _multipliers(None, lay, m, z, slots=slots)
    best = sse_at(A0)
    for k in range(len(z)):
        own = [(cols, mag, sgn) for cols, mag, sgn, kk, _ in slots if kk == k]
        for g in np.linspace(lay.lo[k], lay.hi[k], 7)[1:-1]:
            A = A0.copy()
            for cols, mag, sgn in own:
                A[:, cols] = (sgn * mag(m.speed, math.exp(g)))[:, None]
            r2 = sse_at(A)
            if r2 < best:
                best, A0 = r2, A
                z = z.copy()
                z[k] = g
    return z


# ---------------------------------------------------------------------- fit
@dataclass
class LawFit:
    """A structure fitted to (part of) the data.

    ``z``: log of the nonlinear parameters (layout order); ``w``: linear coefficients; ``sse``:
    residual sum of squares per segment of the data it was fitted to (exact, in torque units^2).
    """

    parts: tuple
    z: np.ndarray
    w: np.ndarray
    sse: np.ndarray
    n: int
    converged: bool = True
    cov: np.ndarray | None = None
    se_method: str = ""
    layout: _Layout | None = field(default=None, repr=False)

    @property
    def rmse(self) -> float:
        return math.sqrt(float(np.sum(self.sse)) / max(self.n, 1))

    @property
    def complexity(self) -> int:
        return complexity(self.parts)

    def predict_sse(self, m: Moments) -> np.ndarray:
        """Per-segment residual sum of squares on other data (e.g. held-out segments)."""
        m = m.restrict({b for _, _, b in self.layout.cols})
        return m.sse(_design(self.parts, self.layout, m, self.z), self.w)

    def basis_coefficients(self, m: Moments) -> np.ndarray:
        """(S, K): the law's prediction in every segment of ``m`` as coefficients of ``m``'s
        sample bases (prediction = Phi_s @ beta_s)."""
        A = _multipliers(self.parts, self.layout, m, self.z)
        beta = np.zeros((m.S, m.K))
        for j, (_, _, b) in enumerate(self.layout.cols):
            beta[:, m.index(b)] += A[:, j] * self.w[j]
        return beta

    def values(self) -> list[dict]:
        """Every parameter with its standard error: ``part, slot, name, value, se``."""
        lay = self.layout
        nlin = len(lay.cols)
        se = np.sqrt(np.clip(np.diag(self.cov), 0, None)) if self.cov is not None else np.full(nlin + len(self.z),
                                                                                                 np.nan)
        out = []
        for j, (i, sl, b) in enumerate(lay.cols):
            out.append({"part": i, "slot": sl, "kind": "linear", "name": b, "value": float(self.w[j]),
                        "se": float(se[j]), "at_bound": False})
        for k, (i, sl) in enumerate(lay.nl):
            v = math.exp(self.z[k])
            at_bound = bool(min(self.z[k] - lay.lo[k], lay.hi[k] - self.z[k]) < 1e-3)
            out.append({"part": i, "slot": sl, "kind": "nonlinear", "name": self.parts[i].fam.param, "value": v,
                        "se": float(v * se[nlin + k]), "at_bound": at_bound})
        return out


def fit_law(m: Moments, parts, *, z0=None, refine: bool = True, se: bool = False, max_nfev: int = 200,
            scan: bool = True) -> LawFit:
    """Least-squares fit of the structure ``parts`` to the segments of ``m``.

    Linear coefficients in closed form, nonlinear parameters (Stribeck velocities, decay
    constants, exponents) by bounded ``scipy.optimize.least_squares`` on their logarithms from
    ``z0`` (default: the parts' grid values), when ``refine``; with ``scan``, each nonlinear
    parameter is first scanned over its range (others held) and the refinement starts from the best.
    """
    parts = tuple(parts)
    lay = _layout(parts, m)
    m = m.restrict({b for _, _, b in lay.cols})
    if z0 is None:
        z0 = np.array([math.log(parts[i].param0) for i, _ in lay.nl])
    z = np.clip(np.asarray(z0, dtype=float), lay.lo + 1e-9, lay.hi - 1e-9) if len(lay.nl) else np.zeros(0)
    q = m.q.reshape(-1)
    converged = True
    kidx = _basis_index(lay, m)
    Pk = np.ascontiguousarray(m.P[:, :, kidx])       # (S, K, p), C-ordered: designs reshape without a copy
    ncol = len(lay.cols)
    slots = _slots(parts, lay, m)
    # the normal equations serve designs of MIN_SIZE entries or more (NormalSolver.of); smaller
    # ones go to QR, with the arithmetic they always had
    large = m.S * m.K * ncol >= lsq.MIN_SIZE and m.S * m.K >= ncol
    # a large design is built column-scaled in one pass (_solve_law)
    D = np.einsum("skj,skj->sj", Pk, Pk) if large else None
    cache = {}

    def solve(A):
        return _solve_law(A, Pk, q, D)

    def state(zz):
        key = zz.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = solve(_multipliers(parts, lay, m, zz, slots=slots))
        return cache[key]

    def resid(zz):
        return state(zz)[3].copy()

    def sse_at(A):
        r = solve(A)[3]
        return float(r @ r)

    def jac(zz):
        # variable projection, Kaufman's approximation: J_k = -(I - U U^T) dX/dz_k w, all k at once
        X, w, ns, _ = state(zz)
        dA = _derivatives(m, zz, slots)                 # only where the optimiser asks
        if large:
            # dX/dz_k w for all k as one product: (S*K, p) design of the derivatives times the
            # columns' assignment to the parameters (p, nz)
            C, own = np.zeros((m.S, ncol)), np.zeros((ncol, len(zz)))
            for k, cols in enumerate(dA):
                for j, d in cols:
                    C[:, j] = d * w[j]
                    own[j, k] = 1.0
            return -_project_out(ns, X, (Pk * C[:, None, :]).reshape(-1, ncol) @ own)
        V = np.zeros((m.S, m.K, len(zz)))
        for k, cols in enumerate(dA):
            for j, d in cols:
                V[:, :, k] += (d * w[j])[:, None] * Pk[:, :, j]
        V = V.reshape(-1, len(zz))
        # small designs (QR): one column at a time, the arithmetic of short recordings unchanged
        return np.column_stack([-_project_out(ns, X, V[:, k].copy()) for k in range(len(zz))])

    if refine and len(z) and scan:
        z = _scan(z, lay, m, slots, sse_at)
    if refine and len(z):
        # least_squares' gradient tolerance is absolute: on torques of mNm (sse ~1e-7) it stopped
        # every refinement after 2-4 evaluations, wherever it started; the residual is scaled to
        # unit norm at the start, so the tolerance is relative to the fit's own error
        r0 = resid(z)
        sc = 1.0 / max(math.sqrt(float(r0 @ r0)), 1e-300)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            sol = optimize.least_squares(lambda zz: resid(zz) * sc, z, jac=lambda zz: jac(zz) * sc,
                                         bounds=(lay.lo, lay.hi), method="trf", max_nfev=max_nfev, x_scale=1.0)
        z = sol.x
        converged = sol.status > 0
    if large:
        # the refined normal equations (QR where they refuse), the residual kept from the solve
        X, w, _, r = cache.get(z.tobytes()) or solve(_multipliers(parts, lay, m, z, slots=slots))
        sse = np.sum(r.reshape(m.S, m.K) ** 2, axis=1) + m.rest
    else:
        X = _design(parts, lay, m, z)
        w = _solve(X, q)[0]
        sse = m.sse(X, w)
    fit = LawFit(parts, z, w, sse, m.N, converged, layout=lay)
    if se:
        _covariance(fit, m, _design(parts, lay, m, z) if large else X)
    return fit


def _covariance(fit: LawFit, m: Moments, X: np.ndarray) -> None:
    """Cluster-robust (segments) covariance of all parameters, in ``fit.cov`` (linear, then log
    nonlinear: :meth:`LawFit.values` converts)."""
    parts, lay = fit.parts, fit.layout
    q = m.q.reshape(-1)
    r = q - X @ fit.w
    cols = [-X]
    for k in range(len(fit.z)):
        h = 1e-5
        zp, zm = fit.z.copy(), fit.z.copy()
        zp[k] += h
        zm[k] -= h
        dX = (_design(parts, lay, m, zp) - _design(parts, lay, m, zm)) / (2 * h)
        cols.append(-(dX @ fit.w)[:, None])
    J = np.hstack(cols)
    p = J.shape[1]
    # columns differ in scale by many decades (|v| at 600 rad/s against a log-parameter): invert
    # the scaled normal matrix, or the pseudo-inverse's cut-off drops the weakly scaled directions
    cn = np.sqrt(np.sum(J * J, axis=0))
    cn[cn == 0] = 1.0
    bread = np.linalg.pinv((J / cn).T @ (J / cn), rcond=1e-12, hermitian=True) / np.outer(cn, cn)
    S = m.S
    if S >= p + 2:
        g = np.einsum("skp,sk->sp", J.reshape(S, m.K, p), r.reshape(S, m.K))
        meat = g.T @ g
        fit.cov = bread @ meat @ bread * (S / (S - p))
        fit.se_method = f"cluster-robust over {S} segments"
    else:
        dof = max(m.N - p, 1)
        fit.cov = bread * float(np.sum(fit.sse)) / dof
        fit.se_method = (f"ordinary covariance (only {S} segments for {p} parameters: assumes independent samples, "
                         "so likely too small)")


def cross_validate(m: Moments, parts, fold: np.ndarray, *, z0=None, refine: bool = True):
    """Held-out residual sum of squares of every segment, each fold predicted by the structure
    refitted (all parameters) on the other folds; and the held-out predictions (S, K) on the
    segments' pseudo rows (for comparing two laws' predictions).  The loop:
    :func:`gearspec.core.crossval.held_out`.  Every fold's refinement starts at the all-data
    optimum ``z0`` (None: :func:`fit_law` on all of ``m`` finds it) and runs to the all-data fit's
    tolerance and evaluation budget: a law has one held-out error, not one per start."""
    full = m
    parts = tuple(parts)
    lay = _layout(parts, m)
    m = m.restrict({b for _, _, b in lay.cols})      # once, not per fold
    if z0 is None and refine and lay.nl:
        z0 = fit_law(m, parts).z
    kfull = np.array([full.index(b) for b in m.basis], dtype=int)
    beta = np.zeros((m.S, full.K))

    def score(fit, test):
        mt = m.take(np.flatnonzero(test))
        beta[np.ix_(test, kfull)] = fit.basis_coefficients(mt)
        return fit.predict_sse(mt)

    def refit(train):
        return fit_law(m.take(np.flatnonzero(train)), parts, z0=z0, refine=refine, scan=False)

    return held_out(fold, refit, score, catch=()).sse, beta


def cross_validate_linear(m: Moments, fit: LawFit, fold: np.ndarray) -> np.ndarray:
    """Held-out residual sum of squares of every segment with the nonlinear parameters held at
    ``fit``'s values and only the linear coefficients refitted per fold: a fast screen (slightly
    optimistic for laws with nonlinear parameters) used while searching; the laws reported are
    scored with :func:`cross_validate`."""
    full = m
    m = m.restrict({b for _, _, b in fit.layout.cols})
    A = _multipliers(fit.parts, fit.layout, m, fit.z)
    kidx = _basis_index(fit.layout, m)
    Xs = A[:, None, :] * m.P[:, :, kidx]                      # (S, K, p)
    kfull = np.array([full.index(b) for _, _, b in fit.layout.cols], dtype=int)
    beta = np.zeros((m.S, full.K))

    def score(w, test):
        r = m.q[test] - np.einsum("skp,p->sk", Xs[test], w)
        bt = np.zeros((int(test.sum()), full.K))
        np.add.at(bt.T, kfull, (A[test] * w).T)
        beta[test] = bt
        return np.sum(r * r, axis=1) + m.rest[test]

    def refit(train):
        # the refined normal equations where the fold's design allows (QR's coefficients to
        # rounding, without forming Q: 10 ms for 8000 x 25), else QR (_solve_fast)
        return _solve_fast(Xs[train].reshape(-1, Xs.shape[2]), m.q[train].reshape(-1), basis=False)[0]

    return held_out(fold, refit, score, catch=()).sse, beta


# ---------------------------------------------------------------------- reading a fitted law
def _slot_values(fit: LawFit, i: int):
    """{slot: {"lin": [(value, se)...], "param": (value, se) or None}} of part i."""
    out = {}
    for v in fit.values():
        if v["part"] != i:
            continue
        d = out.setdefault(v["slot"], {"lin": [], "param": None})
        if v["kind"] == "nonlinear":
            d["param"] = (v["value"], v["se"])
        else:
            d["lin"].append((v["value"], v["se"]))
    p = fit.parts[i]
    if p.fam.param and not p.free:          # a fixed grid value (power-law exponent)
        for d in out.values():
            d["param"] = (p.param0, 0.0)
    return out


def _pair(vals: dict, fmt) -> str:
    """'x' for a symmetric value, '(x+ | x-)' for a direction-dependent one."""
    if 0 in vals:
        return fmt(vals[0])
    return f"({fmt(vals[1])} | {fmt(vals[-1])})"


def _times(c: str, fac: str) -> str:
    """The coefficient ``c`` times the factor ``fac`` as printed (``c/(...)`` for ``1/(...)``)."""
    if fac in ("", "1"):
        return c
    return c + fac[1:] if fac.startswith("1/") else f"{c}*{fac}"


def equation(fit: LawFit, frequencies, t_ref=None, unit: str = "rad") -> str:
    """The fitted law as one readable line (SI units; ``(a | b)``: positive | negative direction)."""
    friction, signed = [], []
    for i, p in enumerate(fit.parts):
        sv = _slot_values(fit, i)
        fam = p.fam
        par = {s: d["param"][0] for s, d in sv.items() if d["param"] is not None}
        fac = fam.factor.format(p=_pair(par, _g) if par else None)
        if t_ref is not None:
            fac = fac.replace("T_ref", _g(t_ref))
        if fam.basis == "ripple":
            amp = {s: math.hypot(d["lin"][0][0], d["lin"][1][0]) for s, d in sv.items()}
            ph = {s: math.atan2(d["lin"][1][0], d["lin"][0][0]) for s, d in sv.items()}
            f = _g(float(frequencies[p.freq]), 6)
            friction.append(f"{_times(_pair(amp, _g), fac)}*sin(2pi*{f}*theta + {_pair(ph, lambda x: _g(x, 3))})")
            continue
        term = _times(_pair({s: d["lin"][0][0] for s, d in sv.items()}, _g), fac)
        (signed if fam.basis == "acc" else friction).append(term)
    body = " + ".join(friction) if friction else "0"
    s = f"tau = sign(v)*[{body}]"
    if signed:
        s += " + " + " + ".join(signed)
    return s.replace("+ -", "- ")


def to_model(fit: LawFit, frequencies, labels=None, t_ref=None, unit: str = "rad", name: str = "discovered",
             rmse=None, rmse_holdout=None) -> FrictionModel:
    """The fitted law as a :class:`FrictionModel` (base law coulomb_viscous per direction, ripple as
    harmonics per direction, other parts as :mod:`gearspec.terms`: what each family becomes is
    :attr:`.library.Family.term`), which evaluates identically."""
    dirs = {1: {"tau_c": 0.0, "viscous": 0.0, "harmonics": []}, -1: {"tau_c": 0.0, "viscous": 0.0, "harmonics": []}}
    terms = []
    for i, p in enumerate(fit.parts):
        sv = _slot_values(fit, i)
        fam = p.fam
        for sl, d in sv.items():
            targets = (1, -1) if sl == 0 else (sl,)
            lin = d["lin"]
            par, par_se = d["param"] if d["param"] is not None else (None, None)
            if fam.term == "harmonic":
                (cs, cs_se), (cc, cc_se) = lin
                A = math.hypot(cs, cc)
                ph = math.atan2(cc, cs)
                A_se = math.sqrt((cs * cs_se) ** 2 + (cc * cc_se) ** 2) / A if A > 0 else float("nan")
                ph_se = math.sqrt((cc * cs_se) ** 2 + (cs * cc_se) ** 2) / (A * A) if A > 0 else float("nan")
                h = {"frequency": float(frequencies[p.freq]), "amplitude": A, "amplitude_se": A_se, "phase": ph,
                     "phase_se": ph_se, "decay": par if par is not None else 0.0,
                     "decay_se": par_se if par is not None else None, "law": fam.shape,
                     "label": (labels[p.freq] if labels is not None else None)}
                for t in targets:
                    dirs[t]["harmonics"].append(dict(h))
                continue
            c, c_se = lin[0]
            if fam.term == "base":
                for t in targets:
                    dirs[t][fam.coef] += c
                    dirs[t][f"{fam.coef}_se"] = c_se
                continue
            term = {"kind": fam.term, fam.coef: c, f"{fam.coef}_se": c_se}
            if fam.param:
                term.update({fam.param: par, f"{fam.param}_se": par_se})
            if fam.shape:
                term["shape"] = fam.shape
            if fam.basis == "temperature":
                term["reference"] = float(t_ref)
            terms.append(term if sl == 0 else {**term, "direction": sl})
    return FrictionModel("coulomb_viscous", dirs[1], dirs[-1], terms=terms, unit=unit, name=name, rmse=rmse,
                         rmse_holdout=rmse_holdout,
                         notes=[f"found by gearspec discover; standard errors: {fit.se_method or 'not computed'}"])
