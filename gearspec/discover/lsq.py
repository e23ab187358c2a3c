"""Least squares on a law's pseudo-row design through its p x p normal matrix, for the many
evaluations of one refinement (:func:`.law.fit_law`): the coefficients and the projections the
variable-projection Jacobian needs, without a QR (and an explicit Q) of the S*K x p design at
every evaluation.

Accuracy: the normal matrix squares the condition number, so every solve is refined against the
design itself (``c += N^-1 X^T (y - X c)``) until the correction is at rounding level; a design
whose Cholesky factor is too ill-conditioned for that, or where the refinement does not settle, is
refused (``None``) and the caller takes the QR / SVD path of :func:`.law._solve`.  The residual
``y - X c`` is computed from the design, so the residual sum of squares (stationary in ``c``) agrees
with the QR path's to rounding.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

__all__ = ["NormalSolver"]

#: smallest ratio of the Cholesky factor's diagonal (the |diagonal| of the column-scaled design's
#: R) to its largest element for which the normal equations are used: the condition number of the
#: normal matrix is then about 1e10 or less, and one refinement step reduces the error of a solve
#: by about eps x that (1e-6 or better).  The QR path's own rank test is at 1e-8.
MIN_RATIO = 1e-5
#: refinement steps at most; they stop when the correction is below TOL x the coefficients' size
#: or stops shrinking (the rounding floor, eps x the design's condition number: the QR path's own
#: accuracy); a solve whose last correction is still above ACCEPT x their size is refused
MAX_STEPS = 5
TOL = 1e-15
ACCEPT = 1e-9
#: a first correction below FIRST x the size leaves the refined coefficients at the rounding floor
FIRST = 1e-7
#: smaller designs (rows x columns) are left to QR, which is as fast there (measured: 0.85x at
#: 240 x 12, 1.4x at 720 x 12, 1.0x at 530 x 20, 2.3x at 2400 x 12 on captured discover fits)
MIN_SIZE = 20000


class NormalSolver:
    """Least squares ``min |y - X c|`` for one design ``X`` (n, p) and any number of targets.

    Build with :meth:`of`, which returns None when the design is too ill-conditioned for the normal
    equations (the caller falls back to QR).  Coefficients are returned in the units of ``X``'s
    columns (the column scaling is internal).
    """

    def __init__(self, X: np.ndarray, nrm: np.ndarray, factor):
        self.X, self.nrm, self.factor = X, nrm, factor

    @classmethod
    def of(cls, X) -> "NormalSolver | None":
        """The solver of the design ``X`` (n, p), or None (too small or too ill-conditioned for the
        normal equations).  ``X`` may also be given as ``(Xn, nrm)``: the design with its columns
        already divided by their norms ``nrm`` (all > 0), built so in one pass where the norms are
        known beforehand (:func:`.law.fit_law`)."""
        if isinstance(X, tuple):
            Xn, nrm = X
        else:
            Xn, nrm = X, None
        if Xn.shape[0] < Xn.shape[1] or Xn.shape[1] == 0 or Xn.size < MIN_SIZE:
            return None
        if nrm is None:
            nrm = np.sqrt(np.sum(X * X, axis=0))
            if np.any(nrm == 0):
                return None
            Xn = X / nrm
        N = Xn.T @ Xn
        try:
            L = np.linalg.cholesky(N)
        except np.linalg.LinAlgError:
            return None
        d = np.diag(L)
        if not (np.all(np.isfinite(d)) and d.min() > MIN_RATIO * d.max()):
            return None
        # the inverse of the triangular factor: a solve is then two small products (no per-call
        # overhead of a LAPACK wrapper, which dominates for the small designs of short recordings)
        Li = solve_triangular(L, np.eye(len(d)), lower=True, check_finite=False)
        return cls(Xn, nrm, Li)

    def coef_scaled(self, y: np.ndarray) -> np.ndarray | None:
        """Coefficients of the column-scaled design (refined) for the target ``y`` (n,) or the
        targets ``y`` (n, m), every column refined until it settles; None when the refinement of
        one does not settle at rounding level."""
        Xn, Li = self.X, self.factor
        c = Li.T @ (Li @ (Xn.T @ y))
        prev, ok = np.inf, False
        for k in range(MAX_STEPS):
            dc = Li.T @ (Li @ (Xn.T @ (y - Xn @ c)))
            c = c + dc
            size, step = np.maximum(np.max(np.abs(c), axis=0), 1e-300), np.max(np.abs(dc), axis=0)
            # the first correction is the normal equations' error (about eps x cond^2); once it
            # is below FIRST, the refined c is at the rounding floor
            done = (step <= TOL * size) | ((k == 0) & (step <= FIRST * size))
            if np.all(done):
                ok = True
                break
            ok = bool(np.all(done | (step <= ACCEPT * size)))
            if np.all(done | (step > 0.5 * prev)):         # stagnating: at the rounding floor
                break
            prev = np.where(done, 0.0, step)
        return c if ok else None

    def solve(self, y: np.ndarray) -> np.ndarray | None:
        """Coefficients of ``X`` (None: refused, see :meth:`coef_scaled`)."""
        c = self.coef_scaled(y)
        return None if c is None else c / self.nrm

    def residual(self, v: np.ndarray) -> np.ndarray | None:
        """``v`` (n,) or the columns of ``v`` (n, m) minus their projections on the column space of
        ``X`` (None: refused)."""
        c = self.coef_scaled(v)
        return None if c is None else v - self.X @ c

