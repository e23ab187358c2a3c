"""Sparse regression over the library: pysindy's optimisers (scikit-learn regressors) run
unchanged on the exact pseudo rows of :mod:`.moments` and give what they would give on the samples.

Columns and friction are scaled to unit RMS over the samples, so a threshold reads as "the
smallest term worth keeping, as a fraction of the friction's RMS".  Inclusion probabilities come
from a bootstrap over *whole segments* (or runs), done here around the optimiser:
pysindy's ``EnsembleOptimizer(bagging=True)`` draws single rows, which would split a segment's
pseudo rows apart.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import InputError

__all__ = ["make_optimizer", "OPTIMIZERS", "Scaled", "path", "bootstrap_inclusion"]

OPTIMIZERS = ("stlsq", "sr3")


def make_optimizer(method: str, threshold: float, alpha: float, n_rows: float, free=None):
    """A pysindy optimiser for one threshold on standardised columns.

    ``stlsq``: sequentially thresholded ridge regression (ridge weight ``alpha * n_rows``, i.e.
    ``alpha`` relative to the squared norm of a standardised column); ``sr3``: SR3 with an L0
    penalty equivalent to hard thresholding at ``threshold``.  ``free``: boolean mask of the
    columns that are thresholded (the others are always kept, unpenalised); None: all.
    """
    import pysindy as ps

    if method == "stlsq":
        sparse_ind = None if free is None or np.all(free) else [int(i) for i in np.flatnonzero(free)]
        return ps.STLSQ(threshold=threshold, alpha=alpha * n_rows, max_iter=25, unbias=False, sparse_ind=sparse_ind)
    if method == "sr3":
        nu = 1.0
        lam = ps.SR3.calculate_l0_weight(threshold, nu)
        if free is None or np.all(free):
            return ps.SR3(reg_weight_lam=lam, relax_coeff_nu=nu, regularizer="L0", max_iter=200, unbias=False)
        return ps.SR3(reg_weight_lam=np.where(free, lam, 0.0)[None, :], relax_coeff_nu=nu, regularizer="weighted_l0",
                      max_iter=200, unbias=False)
    raise InputError(f"optimizer must be one of {', '.join(OPTIMIZERS)}, got '{method}'")


class Scaled:
    """Pseudo rows with columns and target scaled to unit RMS over the samples."""

    def __init__(self, X: np.ndarray, q: np.ndarray, N: float, yy: float):
        self.N = float(N)
        self.col_rms = np.sqrt(np.sum(X * X, axis=0) / self.N)
        self.live = self.col_rms > 1e-12 * max(float(np.max(self.col_rms)) if len(self.col_rms) else 1.0, 1e-300)
        self.y_rms = np.sqrt(yy / self.N) if yy > 0 else 1.0
        cr = np.where(self.live, self.col_rms, 1.0)
        self.X = X / cr
        self.X[:, ~self.live] = 0.0
        self.q = q / self.y_rms


def _fit(method, threshold, alpha, sc: Scaled, free=None) -> np.ndarray:
    """Standardised coefficients of one optimiser run (dead columns excluded)."""
    X = sc.X[:, sc.live]
    opt = make_optimizer(method, threshold, alpha, sc.N, None if free is None else np.asarray(free)[sc.live])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        opt.fit(X, sc.q)
    w_live = np.zeros(X.shape[1])
    sparse_ind = getattr(opt, "sparse_ind", None)
    if sparse_ind is not None:
        # pysindy's STLSQ returns the thresholded columns in coef_, the others apart
        w_live[sparse_ind] = np.asarray(opt.coef_).reshape(-1)
        rest = np.setxor1d(sparse_ind, np.arange(X.shape[1]))
        w_live[rest] = np.asarray(opt.optvar_non_sparse_).reshape(-1)
    else:
        w_live[:] = np.asarray(opt.coef_).reshape(-1)
    w = np.zeros(sc.X.shape[1])
    w[sc.live] = w_live
    return w


def path(sc: Scaled, thresholds, method: str = "stlsq", alpha: float = 1e-4, free=None,
         max_columns: int | None = None) -> list[np.ndarray]:
    """Standardised coefficients at every threshold (from the largest down); stops early once two
    thresholds in a row select more than ``max_columns`` columns (the path only gets denser)."""
    out = []
    dense = 0
    for t in thresholds:
        w = _fit(method, float(t), alpha, sc, free)
        out.append(w)
        if max_columns is not None and np.count_nonzero(w) > max_columns:
            dense += 1
            if dense >= 2:
                break
    return out


def bootstrap_inclusion(X, m, threshold: float, *, by: str = "segment", n_models: int = 50,
                        method: str = "stlsq", alpha: float = 1e-4, seed: int = 0, free=None,
                        column_groups=None, progress=None) -> np.ndarray:
    """Fraction of segment-bootstrap replicates in which each column is selected.

    ``X``: the library design on the pseudo rows of ``m``, a
    :class:`~.blocks.SegmentDesign` (reduced a block of segments at a time) or an array (S*K, p).
    Groups (segments or runs) are drawn with replacement; each replicate is scaled afresh and
    fitted at ``threshold``.  ``column_groups`` (p,): a group index per column (-1: none); then the
    fraction of replicates in which any column of each group is selected, (max group + 1,).
    ``progress``: called with one line of text after every 10 replicates but the last.
    """
    from .forked import fits_map
    from .blocks import SegmentDesign

    rng = np.random.default_rng(seed)
    g = m.groups(by)
    ug = np.unique(g)
    members = [np.flatnonzero(g == u) for u in ug]
    design = X if isinstance(X, SegmentDesign) else SegmentDesign(m, np.ones((m.S, 0)), np.zeros(0, int), X)
    cg = None if column_groups is None else np.asarray(column_groups, dtype=int)
    hits = np.zeros(design.shape[1] if cg is None else int(cg.max()) + 1)
    # the replicates drawn in turn, fitted at once (forked_map), counted in turn
    picks = [np.concatenate([members[i] for i in rng.integers(0, len(ug), len(ug))]) for _ in range(n_models)]
    sels = fits_map(lambda pick: _fit(method, threshold, alpha, Scaled(*design.reduce(pick)), free) != 0, picks)
    for i, sel in enumerate(sels):
        if cg is None:
            hits += sel
        else:
            hits[np.unique(cg[sel & (cg >= 0)])] += 1
        if progress is not None and (i + 1) % 10 == 0 and i + 1 < n_models:
            progress(f"{i + 1} of {n_models} bootstrap replicates")
    return hits / max(n_models, 1)
