"""Standard errors of the joint fit (:mod:`.joint`): a cluster-robust covariance over runs by
default, the covariance of independent samples on request or as a fallback.

Why cluster-robust.  A real bench repeats a run and gets friction levels and line amplitudes a few
percent apart (temperature, lubricant, wear between repetitions); the noise within a run is
coloured (a closed loop, a filtered current) and the position is quantised.  The covariance of
independent samples, ``(J^T J)^-1 s^2``, sees none of that: with 10^5 samples it claims a
precision of 10^-4 of the friction where the runs themselves differ by 1 %.  The cluster-robust
("sandwich") covariance takes the spread of the fit's scores between whole runs instead:
``V = B (sum_c J_c^T A_c r_c r_c^T A_c J_c) B`` with ``B = (J^T J)^-1``, ``J_c``, ``r_c`` the rows
of run ``c`` and ``A_c = (I - H_cc)^-1/2`` (``H_cc`` the run's block of the hat matrix): the CR2
small-sample correction of Bell & McCaffrey (2002), which makes ``V`` unbiased when the errors are
independent and keeps a run that alone pins a parameter from shrinking its own residual.  A
parameter that few runs pin down (a Stribeck static level measured by the slow runs only) has few
effective degrees of freedom even when there are many runs: its variance is itself uncertain and
``+- 1.96 se`` would cover too rarely.  Each parameter's standard error is therefore scaled by
``t_0.975(df) / 1.96`` with its Bell-McCaffrey degrees of freedom ``df`` (the Satterthwaite
approximation of the CR2 variance's distribution), so that ``+- 1.96 se`` is its 95 % interval.

The rows here are the per-segment pseudo-rows of the reduction (:class:`~.stats.SegmentStats`:
``Lt_s (M_s lin - beta_hat_s)``); a run's score ``J_c^T r_c`` equals the sum of its samples'
scores exactly, so this is the sample-level sandwich at the cost of a few rows per segment.

References: Bell, R. M., McCaffrey, D. F. (2002), Bias reduction in standard errors for linear
regression with multi-stage samples, Survey Methodology 28(2); Cameron, A. C., Miller, D. L.
(2015), A practitioner's guide to cluster-robust inference, J. Human Resources 50(2).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from ..model import Direction
from .stats import ConvergenceError

__all__ = ["SE_METHODS", "CLUSTER_MARGIN", "jacobian", "clusters_of", "fit_covariance", "small_sample_factor"]

#: the ``se`` settings of :class:`~.joint.JointFit`: ``covariance`` is the cluster-robust covariance
#: (over runs, else segments; the default), ``independent`` the covariance of independent samples
#: (what ``covariance`` was up to gearspec 0.5), ``bootstrap`` refits on resampled segments
SE_METHODS = ("covariance", "independent", "bootstrap")

#: a cluster-robust covariance needs at least this many clusters more than parameters (its middle
#: matrix has rank <= clusters - 1); with fewer, the fit falls back to independent samples and says so
CLUSTER_MARGIN = 2

#: eigenvalues of ``I - H_cc`` are held at least this large (a run that alone pins a parameter:
#: its residual is inflated by at most 1 / sqrt of it, 10x)
_MIN_RESIDUAL_FRACTION = 1e-2

#: the degrees of freedom's |GG|_F^2 from p x p products is trusted when it keeps at least this share of
#: the terms it is the difference of; below, it is summed from GG's rows (see :func:`_cr2`)
_DF_CANCEL = 1e-4

_Z975 = float(stats.norm.ppf(0.975))


def jacobian(fun, z: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``z`` (relative step 1e-6)."""
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


def clusters_of(segment_ids: np.ndarray, segments, n_params: int) -> tuple[np.ndarray | None, str]:
    """The clusters of a direction's segments for the cluster-robust covariance: ``(ids, what)``.

    Runs (the ``run`` of each segment in ``segments``, a FitData's table) when there are at least
    ``n_params + CLUSTER_MARGIN`` of them; else the segments themselves when there are that many
    (``what`` says the runs were too few); else ``(None, why)``: too few for a cluster-robust
    estimate."""
    need = n_params + CLUSTER_MARGIN
    seg_ids = np.asarray(segment_ids)
    runs = None
    if segments is not None and len(segments) and "run" in segments and "segment" in segments:
        run_of = dict(zip(segments["segment"].astype(int), segments["run"]))
        runs = np.array([run_of.get(int(s), -1 - int(s)) for s in seg_ids])
    n_runs = len(np.unique(runs)) if runs is not None else 0
    if n_runs >= need:
        return runs, f"cluster-robust (CR2, t-scaled) over {n_runs} runs"
    if len(np.unique(seg_ids)) >= need:
        return seg_ids, (f"cluster-robust (CR2, t-scaled) over {len(np.unique(seg_ids))} segments (only {n_runs} "
                         f"runs for {n_params} parameters)")
    return None, (f"covariance of independent samples: only {n_runs} runs and {len(np.unique(seg_ids))} segments "
                  f"for {n_params} parameters, too few for a cluster-robust estimate; the errors ignore scatter "
                  f"between runs and are likely too small")


def _bread(J: np.ndarray) -> np.ndarray:
    """``(J^T J)^-1`` from the column-scaled normal matrix (columns differ in scale by decades)."""
    cn = np.sqrt(np.sum(J * J, axis=0))
    cn[cn == 0] = 1.0
    Js = J / cn
    return np.linalg.pinv(Js.T @ Js, rcond=1e-12, hermitian=True) / np.outer(cn, cn)


def _residual_maker(Jc: np.ndarray, bread: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A_c = (I - H_cc)^-1/2`` of clusters with rows ``Jc`` (``H_cc = Jc B Jc^T``, ``B`` = ``bread``)
    without forming the rows x rows matrices: ``A_c = I + W diag(s) W^T``.  ``H_cc`` has rank at most
    p: with ``Jc = Q R`` (reduced QR) it is ``Q (R B R^T) Q^T``, so ``I - H_cc`` has the eigenvalues
    ``1 - mu`` (``mu``: those of ``R B R^T``, eigenvectors ``W = Q V``) and 1 on the rest; each
    eigenvalue held at least :data:`_MIN_RESIDUAL_FRACTION`, as in the dense form
    ``U clip(lambda)^-1/2 U^T`` it replaces (the same matrix; cost rows x p^2, not rows^3).
    ``Jc`` may be a stack ``(clusters, rows, p)`` of clusters of one size: one batched QR and
    eigen-decomposition for all of them."""
    Qc, Rc = np.linalg.qr(Jc)
    M = Rc @ bread @ np.swapaxes(Rc, -1, -2)
    mu, V = np.linalg.eigh(0.5 * (M + np.swapaxes(M, -1, -2)))
    return Qc @ V, 1.0 / np.sqrt(np.clip(1.0 - mu, _MIN_RESIDUAL_FRACTION, None)) - 1.0


def _cr2(J: np.ndarray, r: np.ndarray, row_cluster: np.ndarray, bread: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The CR2 covariance ``B (sum_c u_c u_c^T) B`` with ``u_c = J_c^T A_c r_c``, and the Bell-McCaffrey
    degrees of freedom of each parameter (see :func:`fit_covariance`).  Clusters of the same number
    of rows are handled as one stack (free motion has thousands of small blocks)."""
    p = J.shape[1]
    order = np.argsort(row_cluster, kind="stable")
    _, starts, sizes = np.unique(row_cluster[order], return_index=True, return_counts=True)
    U, D, Q = [], [], []   # per cluster: u_c (p), |g_c|^2 per parameter (p), Q_c = J_c^T g_c (p, p)
    for n_c in np.unique(sizes):
        pick = starts[sizes == n_c]
        rows = order[pick[:, None] + np.arange(n_c)]                    # (k, n_c): row indices
        Jc, rc = J[rows], r[rows]                                        # (k, n_c, p), (k, n_c)
        W, s = _residual_maker(Jc, bread)
        Wt = np.swapaxes(W, -1, -2)
        Arc = rc + np.einsum("kim,km->ki", W, s * np.einsum("kim,ki->km", W, rc))   # A_c r_c
        U.append(np.einsum("kip,ki->kp", Jc, Arc))
        AJ = Jc + W @ (s[:, :, None] * (Wt @ Jc))
        g = AJ @ bread                                                   # column j: g_c of parameter j
        D.append(np.einsum("kij,kij->kj", g, g))
        Q.append(np.swapaxes(Jc, -1, -2) @ g)                            # (k, p, p): [:, :, j] = Q_c of j
    U, D, Q = np.concatenate(U), np.concatenate(D), np.concatenate(Q)
    meat = U.T @ U
    # Bell-McCaffrey: for parameter j, with G = (I - H) [g_1 .. g_C], G^T G = GG = diag(D_j) - Q_j^T B Q_j
    # (Q_j: p x C, column c = Q_c of j); df = tr(GG)^2 / |GG|_F^2.  With many clusters (free motion's
    # blocks) from p x p products: tr(GG) = sum D_j - tr(B M_j), |GG|_F^2 = sum D_j^2
    # - 2 sum_c D_cj q_c^T B q_c + tr((B M_j)^2), M_j = Q_j Q_j^T (cost C p^2, not C^2 p).  That sum
    # cancels where GG is nearly 0 (a parameter one cluster pins): when it keeps less than
    # _DF_CANCEL of its terms, |GG|_F^2 is summed from GG's rows instead, a block of rows at a time.
    df = np.empty(p)
    for j in range(p):
        Qj, Dj = Q[:, :, j], D[:, j]                                     # (C, p): rows q_c
        BM = bread @ (Qj.T @ Qj)
        diag = np.einsum("cp,pq,cq->c", Qj, bread, Qj)
        big = float(Dj @ Dj + np.sum(BM * BM.T))
        den = big - 2.0 * float(Dj @ diag)
        if not den > _DF_CANCEL * big:
            den = _frobenius2(Dj, Qj, bread)
        tr = float(Dj.sum() - np.trace(BM))
        df[j] = tr ** 2 / den if den > 0 else np.inf
    return bread @ meat @ bread, df


def _frobenius2(Dj: np.ndarray, Qj: np.ndarray, bread: np.ndarray, block: int = 512) -> float:
    """``|diag(Dj) - Qj B Qj^T|_F^2`` summed a block of rows at a time (memory block x C)."""
    QB = Qj @ bread
    total = 0.0
    for a in range(0, len(Dj), block):
        rows = QB[a:a + block] @ Qj.T                                   # (block, C) of Q B Q^T
        rows[np.arange(len(rows)), np.arange(a, a + len(rows))] -= Dj[a:a + block]
        total += float(np.sum(rows * rows))
    return total


def small_sample_factor(df) -> np.ndarray:
    """``t_0.975(df) / z_0.975``: the factor on a standard error that makes ``+- 1.96 se`` a 95 %
    interval of a t distribution with ``df`` degrees of freedom (at least 1)."""
    df = np.maximum(np.asarray(df, dtype=float), 1.0)
    return np.where(np.isfinite(df), stats.t.ppf(0.975, np.where(np.isfinite(df), df, 1.0)), _Z975) / _Z975


def fit_covariance(J: np.ndarray, r: np.ndarray, s2: float, *, method: str = "covariance",
                   segment_of_row: np.ndarray | None = None, cluster_of_segment: np.ndarray | None = None,
                   fallback: str = "") -> tuple[np.ndarray, str]:
    """The covariance of the fitted parameters and how it was computed: ``(cov, se_method)``.

    ``J`` (rows x p), ``r`` (rows): Jacobian and residual of the weighted fit at the optimum;
    ``s2``: the residual variance per unit weight (for the covariance of independent samples,
    ``(J^T J)^-1 s2``).  ``method`` "covariance": cluster-robust (CR2, see the module docstring)
    with the rows grouped by ``cluster_of_segment[segment_of_row]``; None clusters (too few,
    :func:`clusters_of`) fall back to independent samples with ``fallback`` as the method's
    sentence.  ``method`` "independent": the covariance of independent samples."""
    p = J.shape[1]
    if method == "covariance" and cluster_of_segment is not None:
        bread = _bread(J)
        cov, df = _cr2(J, r, np.asarray(cluster_of_segment)[segment_of_row], bread)
        f = small_sample_factor(df)
        return cov * np.outer(f, f), fallback
    try:
        cov = np.linalg.inv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.nan)
    return cov, (fallback if method == "covariance" else "covariance of independent samples")


# ---------------------------------------------------------------------- the inertia of both directions
def _common_inertia(inertias: dict, unit: str) -> tuple[float, float, str]:
    """One inertia from the two directions' estimates ``{direction: (J, se)}``: their mean weighted
    by the inverse variances, its standard error, and a note (that says when they disagree by more
    than three standard errors of their difference: a torque or inertia that is not the same both
    ways, e.g. gravity or a direction-dependent efficiency)."""
    ok = {d: (J, se) for d, (J, se) in inertias.items() if np.isfinite(J) and np.isfinite(se) and se > 0}
    if not ok:
        raise ConvergenceError("the inertia could not be identified from the free motion (no finite estimate); "
                               "give it in the gear spec (inertia = ...) or record faster changes of speed")
    w = {d: 1.0 / se ** 2 for d, (_, se) in ok.items()}
    J = sum(w[d] * ok[d][0] for d in ok) / sum(w.values())
    J_se = math.sqrt(1.0 / sum(w.values()))
    unit_J = "kg m^2" if unit == "rad" else "kg"
    each = ", ".join(f"{d} {ok[d][0]:.4g} +- {ok[d][1]:.2g}" for d in ok)
    note = (f"inertia identified with the friction from the free motion: {J:.4g} +- {J_se:.2g} {unit_J} "
            f"({each}); the friction refitted with it held")
    if len(ok) == 2:
        (Ja, sa), (Jb, sb) = ok.values()
        z = abs(Ja - Jb) / math.hypot(sa, sb)
        if z > 3:
            note += (f"; warning: the two directions disagree by {z:.1f} standard errors (a torque that is not the "
                     f"same both ways, such as gravity, or a lag between torque and position?)")
    return J, J_se, note


def _carry_se(free: Direction, held: Direction) -> None:
    """Standard errors of the fit with the inertia free onto the same parameters of the fit with it
    held (where both fitted the same parameters and lines)."""
    for k, se in free.se.items():
        if held.values.get(k) is not None and free.values.get(k) is not None and se is not None:
            held.set(k, held.values[k], max(se, held.se.get(k) or 0.0))
    if len(free.harmonics) == len(held.harmonics):
        for hf, hh in zip(free.harmonics, held.harmonics):
            for key, se in hf.se.items():
                if se is not None and np.isfinite(se):
                    hh.se[key] = max(se, hh.se.get(key) or 0.0)
