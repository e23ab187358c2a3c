"""The nonlinear parameters of a state (Stribeck velocities, decays, frequencies, exponents,
lengths): which a block has (:func:`nonlinear_parameters`), their standard errors in the joint fit,
and their refinement on all data -- bounded one-dimensional searches (:func:`polish`) and
Gauss-Newton steps (:func:`refine`)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .data import DiagnoseData
from ..model import DIRECTIONS, FrictionModel
from .design import _DNAME, BaseBlock, Block, HarmonicBlock, State, TermBlock, _cov, solve_normal
from . import gram

__all__ = ["nonlinear_standard_errors", "polish", "refine", "nonlinear_parameters", "with_parameter", "travel_range"]


def nonlinear_standard_errors(state: State, dd: DiagnoseData, cols: list | None = None,
                              G: np.ndarray | None = None, b: np.ndarray | None = None) -> dict:
    """Standard errors of the nonlinear parameters (Stribeck velocities, decays, frequencies,
    exponents, lengths): those of the coefficients of their Taylor columns in the joint least-
    squares fit of all data, ``{uid: {key: se}}`` (white-noise errors, like the linear ones).
    ``cols``: every block's columns with its Taylor columns (:meth:`Block.columns`), ``G, b``: their
    normal equations on all data when known; reduced a chunk of rows at a time (no stacked design)."""
    cols = [blk.columns(dd, taylor=True) for blk in state.blocks] if cols is None else cols
    ranges = gram.every_row(len(dd))
    if G is None or b is None:
        G, b = gram.normals(cols, dd.y, ranges)
    beta = solve_normal(G, b)
    s2 = gram.rss(cols, beta, dd.y, ranges) / max(len(dd) - len(b), 1)
    cov = _cov(G, s2)
    out = {}
    for blk, (a, z) in zip(state.blocks, state.spans(dd, taylor=True)):
        keys = [p[0] for p in nonlinear_parameters(blk, dd)] if blk.coef else []
        if not keys:
            continue
        k0 = a + len(blk.names)
        out[blk.uid] = {key: float(np.sqrt(max(cov[k0 + j, k0 + j], 0.0))) for j, key in enumerate(keys)
                        if np.isfinite(cov[k0 + j, k0 + j])}
    return out


def polish(state: State, dd: DiagnoseData, *, sweeps: int = 2, only=None) -> State:
    """Refine the nonlinear parameters of the blocks (:func:`nonlinear_parameters`) by bounded
    one-dimensional searches of the least-squares error, every linear parameter refitted at each
    trial, block by block, ``sweeps`` times (``only``: uids of the blocks to refine).  The linear
    refits of the loop hold nonlinear parameters fixed; this keeps them where the present model
    wants them (the baseline's Stribeck velocity was fitted without the effects found since)."""
    from scipy.optimize import minimize_scalar

    blocks = list(state.blocks)
    y = dd.y
    yy = float(y @ y)
    ranges = gram.every_row(len(y))
    for _ in range(sweeps):
        for i in range(len(blocks)):
            blk = blocks[i]
            if only is not None and blk.uid not in only:
                continue
            params = nonlinear_parameters(blk, dd)
            if not params:
                continue
            # the other blocks' columns (not stacked: their normals a chunk of rows at a time)
            Xo = [b.columns(dd) for j, b in enumerate(blocks) if j != i]
            Goo, bo = gram.normals(Xo, y, ranges)
            for key, val, lo, hi, log in params:
                cur = blocks[i]

                def rss(x, cur=cur, key=key, log=log, Xo=Xo, Goo=Goo, bo=bo):
                    b = with_parameter(cur, key, math.exp(x) if log else x)
                    # the border of the normal equations of [others | this block]; the solve (an
                    # eigendecomposition) reads the lower triangle of G only
                    CtX, CtC, Cty = gram.bordered(Xo, [b.columns(dd)], y, ranges)
                    G = np.block([[Goo, CtX.T], [CtX, CtC]])
                    rhs = np.concatenate([bo, Cty])
                    beta = solve_normal(G, rhs)
                    return yy - float(beta @ rhs)

                if not hi > lo:
                    continue
                val = min(max(val, lo), hi)
                a, z, x0 = (math.log(lo), math.log(hi), math.log(val)) if log else (lo, hi, val)
                r0 = rss(x0)
                res = minimize_scalar(rss, bounds=(a, z), method="bounded",
                                      options={"xatol": 2e-3 * (abs(z - a)), "maxiter": 25})
                if res.fun < r0:
                    blocks[i] = with_parameter(cur, key, math.exp(res.x) if log else float(res.x))
    return State(blocks, state.template, state.symmetric)


def refine(state: State, dd: DiagnoseData, *, only=None, steps: int = 4) -> State:
    """A few Gauss-Newton steps on the nonlinear parameters of the blocks ``only`` (uids; all
    by default): each step is one least-squares fit of the plain columns and the Taylor columns
    (:meth:`Block.taylor_columns`), whose coefficients are the steps (clipped to a factor 2 for
    scale parameters and to the bounds; halved while the error does not fall).  A cheap
    :func:`polish` for the held-out test, where every candidate needs one."""
    y = dd.y
    ranges = gram.every_row(len(y))

    def sse(st):
        # the blocks' columns side by side, reduced a chunk of rows at a time (never stacked)
        cols = [b.columns(dd) for b in st.blocks]
        beta = solve_normal(*gram.normals(cols, y, ranges))
        return gram.rss(cols, beta, y, ranges), beta

    cur, (best, beta) = state, sse(state)
    for _ in range(steps):
        cur = cur.refreshed(beta)
        blocks = list(cur.blocks)
        moves, at, taylor_of = [], [], []     # at: the column of every Taylor coefficient
        p = 0
        for i, b in enumerate(blocks):
            p += len(b.names)
            if (only is None or b.uid in only) and b.coef:
                pars = nonlinear_parameters(b, dd)
                taylor_of.append(bool(pars))
                for par in pars:
                    at.append(p)
                    p += 1
                    moves.append((i, par))
            else:
                taylor_of.append(False)
        if not moves:
            return cur

        # every block's columns, then its Taylor columns (one per nonlinear parameter)
        cols = []
        for b, t in zip(blocks, taylor_of):     # (its plain columns, then its Taylor columns)
            cols.append(b.columns(dd, taylor=t))
        taylor = solve_normal(*gram.normals(cols, y, ranges))[at]
        del cols
        improved = False
        for scale in (1.0, 0.5, 0.25):
            trial = list(blocks)
            for (i, (key, val, lo, hi, log)), dlt in zip(moves, taylor):
                new = val + scale * dlt
                if log:
                    new = min(max(new, val / 2), val * 2)
                new = min(max(new, lo), hi)
                trial[i] = with_parameter(trial[i], key, new)
            st = State(trial, cur.template, cur.symmetric)
            e, b2 = sse(st)
            if e < best:
                cur, best, beta, improved = st, e, b2, True
                break
        if not improved:
            break
    return cur.refreshed(beta)


# ---------------------------------------------------------------------- nonlinear parameters
def nonlinear_parameters(blk: Block, dd: DiagnoseData) -> list[tuple]:
    """The nonlinear parameters of a block the polish refines: ``(key, value, lo, hi, log)``.

    Base law: every Stribeck velocity (within a factor 4); lines: decay constants (their own law,
    in units of the top speed) and, for lines the loop found, the frequency (within half a
    resolution step); terms: exponent, Stribeck velocity and presliding length.
    """
    out = []
    top, low = _speed_bounds(dd)
    # speed-like parameters stay within a decade below the slowest and three times the fastest speed
    s_lo, s_hi = low / 10, 3 * top
    if isinstance(blk, BaseBlock):
        for d, nl in blk.nonlin:
            for k, v in nl.items():
                if v is not None and v > 0:
                    out.append((("base", d, k), float(v), max(v / 4, s_lo), min(v * 4, s_hi), True))
    elif isinstance(blk, HarmonicBlock):
        for d, law in blk.law:
            dec = float(dict(blk.decay).get(d, 0.0))
            bounds = {"exp": (min(dec, 0.0) - 2.0 / top, max(dec, 0.0) + 10.0 / top),
                      "rational": (0.0, max(dec, 0.0) + 10.0 / top), "power": (0.0, max(dec, 0.0) + 6.0)}
            if law in bounds:
                out.append((("decay", d), dec, *bounds[law], False))
        if blk.found and dd.fit.theta is not None:
            span = _longest_span(dd)
            f = blk.frequency
            out.append((("frequency",), f, f - 0.5 / span, f + 0.5 / span, False))
    elif isinstance(blk, TermBlock):
        for k, v in blk.fixed:
            if k == "exponent":
                out.append((("fixed", k), float(v), 0.05, 4.0, False))
            elif k == "v_s" and v > 0:
                out.append((("fixed", k), float(v), max(v / 4, s_lo), min(v * 4, s_hi), True))
            elif k == "length" and v > 0 and dd.travel is not None:
                t_lo, t_hi = travel_range(dd)
                if t_hi > t_lo:
                    out.append((("fixed", k), float(v), max(v / 4, t_lo), min(v * 4, t_hi), True))
    return out


def _speed_bounds(dd: DiagnoseData) -> tuple[float, float]:
    """The largest speed of the samples (1 when none moves) and the smallest nonzero one (1 % of
    the largest when none), cached on the data."""
    hit = dd.cache.get("speed_bounds")
    if hit is not None and hit[0] is dd.fit.v:
        return hit[1]
    sp = np.abs(dd.fit.v)
    top = float(np.max(sp)) if len(sp) else 1.0
    top = top if top > 0 else 1.0
    low = float(np.min(sp[sp > 0])) if np.any(sp > 0) else top / 100
    dd.cache["speed_bounds"] = (dd.fit.v, (top, low))
    return top, low


def _longest_span(dd: DiagnoseData) -> float:
    """The longest travel of one held-out group (1 when there is none), cached on the data."""
    hit = dd.cache.get("longest_span")
    if hit is not None and hit[0] is dd.fit.theta:
        return hit[1]
    th = dd.at("theta")
    span = max((float(np.ptp(th[a:z])) for a, z in zip(dd.starts, dd.stops)), default=0.0) or 1.0
    dd.cache["longest_span"] = (dd.fit.theta, span)
    return span


def travel_range(dd: DiagnoseData) -> tuple[float, float]:
    """Presliding lengths the data can resolve: from the median step between consecutive
    observations of a moving segment (shorter is a spike at one sample) to the longest travel
    after a reversal."""
    tr = dd.at("travel")
    fin = tr[np.isfinite(tr) & (tr > 0)] if tr is not None else np.zeros(0)
    if not len(fin):
        return 0.0, 0.0
    th = dd.at("theta")
    steps = np.concatenate([np.abs(np.diff(th[a:z])) for a, z in zip(dd.starts, dd.stops) if z - a > 2]
                           or [np.zeros(0)])
    steps = steps[steps > 0]
    lo = float(np.median(steps)) if len(steps) else float(np.min(fin))
    return lo, float(np.max(fin))


def with_parameter(blk: Block, key: tuple, value: float) -> Block:
    """A copy of ``blk`` (same uid) with one nonlinear parameter changed."""
    if key[0] == "base":
        _, d, k = key
        nl = tuple((dd_, {**x, k: value} if dd_ == d else x) for dd_, x in blk.nonlin)
        return replace(blk, nonlin=nl)
    if key[0] == "decay":
        d = key[1]
        return replace(blk, decay=tuple((k, value if k == d else v) for k, v in blk.decay))
    if key[0] == "frequency":
        return replace(blk, frequency=float(value))
    if key[0] == "fixed":
        k = key[1]
        return replace(blk, fixed=tuple((kk, value if kk == k else v) for kk, v in blk.fixed))
    raise KeyError(key)


def write_nonlinear_se(m: FrictionModel, blk: Block, ses: dict, new_terms: list) -> None:
    """The standard errors ``ses`` of a block's nonlinear parameters into the model ``m`` (its new terms ``new_terms``)."""
    for key, se in ses.items():
        se = float(se)
        if key[0] == "base":
            _, d, k = key
            for nm in (DIRECTIONS if d == 0 else (_DNAME[d],)):
                m.directions[nm].se[k] = se
        elif key[0] in ("decay", "frequency"):
            names = DIRECTIONS if (key[0] == "frequency" or key[1] == 0) else (_DNAME[key[1]],)
            for nm in names:
                for h in m.directions[nm].harmonics:
                    if math.isclose(h.frequency, blk.frequency, rel_tol=1e-12):
                        h.se[key[0]] = se
        elif key[0] == "fixed":
            for t in new_terms:
                t[key[1] + "_se"] = se
