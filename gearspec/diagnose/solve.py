"""Least squares from normal equations, as every fit of the closed loop solves them: columns scaled
to unit norm, directions the data do not determine left at 0 (:func:`solve_normal`), and the
covariance of the coefficients (:func:`_cov`)."""

from __future__ import annotations

import numpy as np

__all__ = ["solve_normal"]


def solve_normal(G: np.ndarray, b: np.ndarray, rcond: float = 1e-10, reference: np.ndarray | None = None
                 ) -> np.ndarray:
    """Least-squares coefficients from normal equations, columns scaled to unit norm first;
    directions the data do not determine get 0 (pseudo-inverse).  A column that is (nearly) zero
    in these data -- below 1e-12 of the largest, or below 1e-6 of its size in ``reference`` (the
    diagonal of the normal equations of all data: a fold that lacks what the column describes) --
    gets coefficient 0 rather than a huge one that would explode where the column is not zero."""
    d = np.sqrt(np.clip(np.diag(G), 0, None))
    ok = d > 1e-12 * (d.max() if len(d) else 0.0)
    if reference is not None:
        ok &= d > 1e-6 * np.sqrt(np.clip(reference, 0, None))
    beta = np.zeros(len(b))
    if not ok.any():
        return beta
    s = d[ok]
    Gs = G[np.ix_(ok, ok)] / np.outer(s, s)
    bs = b[ok] / s
    lam, U = np.linalg.eigh(Gs)
    keep = lam > rcond * max(lam.max(), 1e-300)
    inv = (U[:, keep] / lam[keep]) @ U[:, keep].T
    beta[ok] = (inv @ bs) / s
    return beta


def _cov(G: np.ndarray, s2: float, rcond: float = 1e-10) -> np.ndarray:
    d = np.sqrt(np.clip(np.diag(G), 0, None))
    ok = d > 0
    C = np.full(G.shape, np.nan)
    if not ok.any():
        return C
    s = d[ok]
    Gs = G[np.ix_(ok, ok)] / np.outer(s, s)
    lam, U = np.linalg.eigh(Gs)
    keep = lam > rcond * max(lam.max(), 1e-300)
    inv = (U[:, keep] / lam[keep]) @ U[:, keep].T
    C[np.ix_(ok, ok)] = inv / np.outer(s, s) * s2
    return C
