"""Fits of the held-out folds that the loop (:mod:`.loop`) makes from the round's design and the
candidates' new columns: a fold's predictions group by group (:func:`predict_groups`) and the
held-out residual of the round's richest model (:func:`full_residual`).  New columns are read as
their blocks, a group's (or a chunk's) rows side by side at a time: no rows x columns copy."""

from __future__ import annotations

import numpy as np

from . import gram
from .candidates import side_by_side
from .context import Round
from .data import DiagnoseData
from .design import solve_normal

__all__ = ["predict_groups", "full_residual"]


def predict_groups(out: np.ndarray, test: np.ndarray, dd: DiagnoseData, X: np.ndarray, beta: np.ndarray,
                   C: list | None = None, beta_c: np.ndarray | None = None) -> None:
    """``out`` at the observations of the groups ``test``: ``X beta`` (+ ``C beta_c``, ``C`` the
    blocks of new columns: a group's rows side by side at a time), group by group on views of the
    rows (no copy of the design, no rows x columns copy of the new columns)."""
    if C is not None and len(C) == 1:
        C = [side_by_side(C)]
    for g in np.flatnonzero(test):
        a, z = dd.starts[g], dd.stops[g]
        out[a:z] = X[a:z] @ beta
        if C is not None:
            out[a:z] += (C[0][a:z] if len(C) == 1 else np.concatenate([c[a:z] for c in C], axis=1)) @ beta_c


def full_residual(rnd: Round, runs: list) -> np.ndarray:
    """Held-out residual of the present model with every promising candidate at once (each as it
    chose its nonlinear parameters in that fold), fitted on the training folds."""
    dd = rnd.dd
    out = np.zeros(len(dd))
    for f in range(rnd.K):
        train = rnd.fold != f
        tr_rows = rnd.rows(train)
        rows = np.flatnonzero(~tr_rows)
        items = [fr.proposals[f] for fr in runs if fr.proposals[f] is not None]
        keep = np.ones(rnd.width, bool)
        for k, _ in items:
            keep &= k
        # this fold's design as column blocks, reduced a chunk of rows at a time (never stacked); the
        # candidates' blocks of columns as they are (:mod:`.gram` puts a chunk's rows side by side)
        cols = rnd.X.masked(keep) + (new := [c for _, prop in items for c in prop.column_blocks(dd)])
        G, b = gram.normals(cols, dd.y, gram.spans(dd.starts, dd.stops, train))
        ref = np.concatenate([rnd.ref_diag[keep]] + [np.einsum("ij,ij->j", c, c) for c in new])
        beta = solve_normal(G, b, reference=ref)
        gram.predict(cols, beta, gram.spans(dd.starts, dd.stops, ~train), out=out)
        out[rows] = dd.y[rows] - out[rows]
    return out
