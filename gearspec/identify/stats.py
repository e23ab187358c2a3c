"""What the fits of :mod:`gearspec.identify` start from: the lines to fit (:func:`harmonic_specs`)
and the exact per-segment sufficient statistics of the samples (:class:`SegmentStats`).

Units: speeds in rad/s (m/s on a linear axis), positions rad (m), frequencies in cycles per unit of
position, friction Nm (N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..core.reduction import GroupNormals, harmonic_columns, normal_equations
from ..errors import InputError
from ..fitdata import FitData
from ..gears import GearTrain, load_gear
from ..spectrum import MEASURABLE_FRACTION, position_nyquist

__all__ = ["MIN_CYCLES", "ConvergenceError", "harmonic_specs", "SegmentStats", "segment_stats", "speed_ranges",
           "pair_se"]

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
class SegmentStats(GroupNormals):
    """Per-segment sufficient statistics of the samples for one direction.

    ``G[s]``, ``b[s]`` (also ``g[s]``), ``yy[s]``, ``n[s]``: normal equations of the local model
    ``[1, sin_k, cos_k]`` on the friction magnitude (:class:`~gearspec.core.reduction.GroupNormals`);
    ``sampled[s, k]``: harmonic k lies below ``nyquist_fraction`` of the
    segment's position Nyquist frequency (its columns are in ``G``, whatever the number of cycles:
    the global model predicts what a partial cycle does to the segment's level); ``active[s, k]``:
    it can also be measured in the segment on its own (it completes
    at least ``min_cycles`` cycles and lies below ``nyquist_fraction`` of the position Nyquist);
    ``speed``, ``load`` (mean), ``sigma2`` (residual variance of the unrestricted local fit).
    """

    segment: np.ndarray = None
    speed: np.ndarray = None
    load: np.ndarray | None = None
    active: np.ndarray = None     # (S, K) bool
    sampled: np.ndarray = None    # (S, K) bool
    cycles: np.ndarray = None     # (S, K) cycles of each line in each segment
    sigma2: np.ndarray = None     # (S,)
    beta_hat: np.ndarray = None   # (S, P)
    rss_hat: np.ndarray = None    # (S,)
    frequencies: np.ndarray = None

    per_group = GroupNormals.per_group + ("segment", "speed", "load", "active", "sampled", "cycles", "sigma2",
                                          "beta_hat", "rss_hat")

    @property
    def g(self) -> np.ndarray:
        """``X^T y`` per segment (``b``)."""
        return self.b


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
        if tag not in cache:
            cache[tag] = _one_segment_stats(data, ii, freqs, min_cycles, nyquist_fraction)
        rows.append(cache[tag])
    K, P = len(freqs), 1 + 2 * len(freqs)
    shape = {"G": (0, P, P), "g": (0, P), "beta_hat": (0, P), "active": (0, K), "sampled": (0, K), "cycles": (0, K)}

    def stack(name):
        return np.array([r[name] for r in rows]) if rows else np.zeros(shape.get(name, (0,)))

    return SegmentStats(stack("G"), stack("g"), stack("yy"), stack("n").astype(int), segment=sids, speed=stack("speed"),
                        load=stack("load") if data.load is not None else None, active=stack("active").astype(bool),
                        sampled=stack("sampled").astype(bool), cycles=stack("cycles"), sigma2=stack("sigma2"),
                        beta_hat=stack("beta_hat"), rss_hat=stack("rss_hat"), frequencies=freqs)


def _one_segment_stats(data: FitData, ii: np.ndarray, freqs: np.ndarray, min_cycles: float,
                       nyquist_fraction: float) -> dict:
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
    G, g, yy = normal_equations(X, y)
    try:
        beta = np.linalg.pinv(G, rcond=1e-12, hermitian=True) @ g
    except np.linalg.LinAlgError as exc:
        raise ConvergenceError(f"the local fit of a segment did not converge ({exc}) with {K} lines; fit fewer "
                               f"lines (--lines)") from exc
    rss = max(yy - beta @ g, 0.0)
    dof = len(ii) - (1 + 2 * int(out["sampled"].sum()))
    out.update(G=G, g=g, yy=yy, beta_hat=beta, rss_hat=rss, sigma2=rss / dof if dof >= 3 else np.nan)
    return out


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


def pair_se(a: float, c: float, cov) -> tuple[float, float]:
    """Standard errors of the amplitude ``hypot(a, c)`` and the phase ``atan2(c, a)`` (rad) of a line
    fitted as ``a sin + c cos`` with covariance ``cov`` (2 x 2) of ``(a, c)``, by the delta method;
    NaN for a zero amplitude.  ``a``, ``c`` and the amplitude in Nm (N)."""
    A = math.hypot(a, c)
    if not A > 0:
        return float("nan"), float("nan")
    ga = np.array([a / A, c / A])
    gp = ga[::-1] * np.array([-1.0, 1.0]) / A     # (-c, a) / A^2 without A^2 (denormal A)
    return float(math.sqrt(max(ga @ cov @ ga, 0))), float(math.sqrt(max(gp @ cov @ gp, 0)))
