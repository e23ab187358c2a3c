"""The nonlinear parameters of a state (Stribeck velocities, decays, frequencies, exponents,
lengths): their standard errors in the joint fit, and their refinement on all data -- bounded
one-dimensional searches (:func:`polish`) and Gauss-Newton steps (:func:`refine`)."""

from __future__ import annotations

import math

import numpy as np

from .data import DiagnoseData
from .design import State, _cov, nonlinear_parameters, solve_normal, with_parameter

__all__ = ["nonlinear_standard_errors", "polish", "refine"]


def nonlinear_standard_errors(state: State, dd: DiagnoseData, X: np.ndarray | None = None,
                              G: np.ndarray | None = None) -> dict:
    """Standard errors of the nonlinear parameters (Stribeck velocities, decays, frequencies,
    exponents, lengths): those of the coefficients of their Taylor columns in the joint least-
    squares fit of all data, ``{uid: {key: se}}`` (white-noise errors, like the linear ones)."""
    X = state.design(dd, taylor=True) if X is None else X
    G = X.T @ X if G is None else G
    beta = solve_normal(G, X.T @ dd.y)
    r = dd.y - X @ beta
    s2 = float(r @ r) / max(len(r) - X.shape[1], 1)
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
    for _ in range(sweeps):
        for i in range(len(blocks)):
            blk = blocks[i]
            if only is not None and blk.uid not in only:
                continue
            params = nonlinear_parameters(blk, dd)
            if not params:
                continue
            others = [b.columns(dd) for j, b in enumerate(blocks) if j != i]
            Xo = np.column_stack(others) if others else np.zeros((len(dd), 0))
            Goo = Xo.T @ Xo
            bo = Xo.T @ y
            for key, val, lo, hi, log in params:
                cur = blocks[i]

                def rss(x, cur=cur, key=key, log=log):
                    b = with_parameter(cur, key, math.exp(x) if log else x)
                    C = b.columns(dd)
                    G = np.block([[Goo, Xo.T @ C], [C.T @ Xo, C.T @ C]])
                    rhs = np.concatenate([bo, C.T @ y])
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
    buf = [np.empty(0)]

    def stacked(cols):
        """The design of ``cols`` stacked into one buffer reused by every step of the refinement
        (the same array as ``np.column_stack``, without a new rows x terms allocation per trial)."""
        p = sum(c.shape[1] for c in cols)
        if buf[0].size < len(y) * p:
            buf[0] = np.empty(len(y) * p)
        X = buf[0][:len(y) * p].reshape(len(y), p)
        if cols:
            np.concatenate(cols, axis=1, out=X)
        return X

    def sse(st):
        X = stacked([b.columns(dd) for b in st.blocks])
        beta = solve_normal(X.T @ X, X.T @ y)
        r = y - X @ beta
        return float(r @ r), beta

    cur, (best, beta) = state, sse(state)
    for _ in range(steps):
        cur = cur.refreshed(beta)
        blocks = list(cur.blocks)
        cols, moves, at = [], [], []     # at: the column of every Taylor coefficient
        for i, b in enumerate(blocks):
            cols.append(b.columns(dd))
            if (only is None or b.uid in only) and b.coef:
                T = b.taylor_columns(dd)
                for j, par in enumerate(nonlinear_parameters(b, dd)):
                    at.append(sum(c.shape[1] for c in cols))
                    cols.append(T[:, j:j + 1])
                    moves.append((i, par))
        if not moves:
            return cur
        X = stacked(cols)
        taylor = solve_normal(X.T @ X, X.T @ y)[at]
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
