"""One order tracked against speed (the ``ordertrack`` view of MATLAB's order analysis), with
amplitude and phase as smooth functions of speed and a confidence band, from one ramp or chirp.

Model, on the samples of one direction where the line lies below ``MEASURABLE_FRACTION`` times the
sample's position Nyquist frequency (:func:`~gearspec.spectrum.ordermap.motion`)::

    y = L(v) + a(v) sin(2 pi f theta) + c(v) cos(2 pi f theta) [+ J thetadd] + noise

with ``y = direction * torque`` (the friction magnitude), ``v`` the speed and ``L``, ``a``, ``c``
cubic B-splines in speed on ``knots`` equally spaced interior knots over the speed range the samples
cover.  ``J``: subtracted when given (or declared by the gear spec), else fitted jointly as one
constant (``inertia="fit"`` forces this; ``inertia=0`` leaves the inertia torque to the level and
the residual).  Least squares through normal equations accumulated in chunks (no matrix of all
samples); amplitude ``A(v) = hypot(a, c)`` and phase ``phi(v) = atan2(c, a)`` (``A sin(2 pi f theta +
phi)``) with pointwise standard errors by the delta method from ``sigma^2 (X'X)^-1`` (white noise;
noise coloured near the line makes them optimistic).  Speeds of the grid with no sample near them
(a gap in the speeds covered) are NaN.  Near A = 0 the amplitude is biased upwards (Rice), so a
band's lower edge at 0 means "not distinguished from no line".
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, stats
from scipy.interpolate import BSpline
from threadpoolctl import threadpool_limits

from ..errors import InputError
from ..jsonsafe import plain
from ..recording import Recording
from .analysis import MEASURABLE_FRACTION
from .ordermap import Motion, _default_min_speed, _kinematics, _motion, motion, order_map

__all__ = ["OrderTrack", "order_track", "resolve_line", "OrderAnalysis", "order_analysis", "SPEED_GRID"]

#: speeds at which a track is evaluated
SPEED_GRID = 64
#: a line is tracked at a speed where the samples within half a knot span of it hold together at
#: least this many of its cycles; elsewhere its sine and cosine cannot be told from the level (a line
#: slower than the travel: an output shaft's once-per-turn in a short run), and it is NaN there
MIN_TRACK_CYCLES = 1.0
#: ``order_analysis(workers="auto")`` analyses the two directions in two threads from this many rows
PARALLEL_MIN_SAMPLES = 200_000
_CHUNK = 1 << 15
_DEGREE = 3


@dataclass
class OrderTrack:
    """Amplitude (torque units) of one line against speed (unit/s) in one direction.

    ``speed`` (G grid speeds), ``amplitude``, ``amplitude_se``, ``lower`` and ``upper`` (the band at
    ``level``), ``phase`` (rad) and ``phase_se``, all NaN where the grid has no sample near it;
    ``counts`` samples per grid cell; ``speed_range`` ``[min, max]`` of |v| of the samples used; ``n``
    samples used; ``n_above_nyquist`` samples of the direction left out because the line lies above
    their position Nyquist frequency; ``sigma`` residual standard deviation; ``inertia`` J (given or
    fitted) with ``inertia_se`` (None when given)."""

    frequency: float
    label: str | None
    order: float | None
    direction: int
    unit: str
    speed: np.ndarray
    amplitude: np.ndarray
    amplitude_se: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    phase: np.ndarray
    phase_se: np.ndarray
    counts: np.ndarray
    speed_range: tuple
    n: int
    n_above_nyquist: int
    sigma: float
    level: float
    knots: int
    inertia: float | None
    inertia_se: float | None
    inertia_how: str
    notes: list = field(default_factory=list)

    @property
    def torque_unit(self) -> str:
        return "Nm" if self.unit == "rad" else "N"

    def at(self, speed) -> np.ndarray:
        """Amplitude at ``speed`` (unit/s) interpolated on the grid (NaN outside the range covered)."""
        ok = np.isfinite(self.amplitude)
        if not ok.any():
            return np.full(np.shape(speed), np.nan)
        return np.interp(speed, self.speed[ok], self.amplitude[ok], left=np.nan, right=np.nan)

    def to_dict(self) -> dict:
        return plain({"frequency": self.frequency, "label": self.label, "order": self.order,
                      "direction": self.direction, "unit": self.unit, "torque_unit": self.torque_unit,
                      "speed_unit": f"{self.unit}/s", "level": self.level, "knots": self.knots,
                      "speed_range": list(self.speed_range), "n": self.n, "n_above_nyquist": self.n_above_nyquist,
                      "sigma": self.sigma, "inertia": self.inertia, "inertia_se": self.inertia_se,
                      "inertia_how": self.inertia_how, "speed": self.speed, "amplitude": self.amplitude,
                      "amplitude_se": self.amplitude_se, "lower": self.lower, "upper": self.upper,
                      "phase": self.phase, "phase_se": self.phase_se, "counts": self.counts, "notes": self.notes})


def resolve_line(gear, line, harmonics: int = 4) -> tuple[float, str | None]:
    """``(frequency, label)`` of ``line``: a frequency in cycles per unit of theta (labelled when a
    declared line sits there) or the label of a declared line (up to ``harmonics``)."""
    if isinstance(line, str):
        try:
            return resolve_line(gear, float(line), harmonics)
        except ValueError:
            pass
        for ln in (gear.declared_lines(max_harmonic=harmonics) if gear is not None else []):
            if line in (ln.label, *ln.label.split(" = ")):
                return float(ln.frequency), ln.label
        names = [ln.label for ln in gear.declared_lines(1)] if gear is not None else []
        raise InputError(f"track '{line}': neither a frequency nor a declared line"
                         + (f" (declared: {'; '.join(names)})" if names else " (no gear spec given)"))
    f = float(line)
    if not (math.isfinite(f) and f > 0):
        raise InputError(f"track frequency must be positive (cycles per unit of theta), got {line!r}")
    label = None
    if gear is not None:
        ln = gear.label(f, 1e-6 * f)
        label = ln.label if ln is not None else None
    return f, label


def order_track(rec: Recording, frequency, *, direction: int = 1, knots: int = 4, level: float = 0.95,
                inertia: float | str | None = None, min_speed: float | None = None, gear=None,
                mot: Motion | None = None) -> OrderTrack:
    """Track the line at ``frequency`` (cycles per unit of theta, or a declared line's label) against
    speed in ``direction`` (+1 or -1).

    Parameters
    ----------
    knots : int
        Interior knots of the cubic B-splines in speed (0 to 20): ``knots + 4`` functions each for
        the level, a(v) and c(v).
    level : float
        Confidence level of the pointwise band (between 0 and 1).
    inertia : float, "fit" or None
        J (kg m^2 or kg) subtracted as ``J thetadd``; None: the gear spec's, else fitted; "fit": fitted
        jointly (one constant per direction); 0: not modelled.
    min_speed : float, optional
        As :func:`~gearspec.spectrum.ordermap.motion` (unit/s).
    mot : Motion, optional
        The direction's samples already prepared (must hold the acceleration when J is fitted).

    Returns
    -------
    OrderTrack
    """
    gear = gear if gear is not None else rec.gear
    f, label = resolve_line(gear, frequency)
    _check_options(knots, level)
    J, how = _inertia_choice(inertia, gear)
    m = mot if mot is not None else motion(rec, direction, min_speed=min_speed, inertia=J, need_acc=how == "fitted")
    if how == "fitted" and m.acc is None:
        raise InputError("order_track: the prepared motion has no acceleration to fit the inertia with")
    use = f < MEASURABLE_FRACTION * m.nyquist
    group = _Measured(use)
    group.check(m, f, knots, how)
    with threadpool_limits(limits=1, user_api="blas"):  # small products: BLAS threads only contend
        return _fit_tracks(m, [(f, label)], group, knots, level, J, how, gear)[0]


def _check_options(knots, level) -> None:
    if not (isinstance(knots, (int, np.integer)) and 0 <= knots <= 20):
        raise InputError(f"knots must be an integer from 0 to 20, got {knots!r}")
    if not (0 < level < 1):
        raise InputError(f"level must be between 0 and 1, got {level!r}")


class _Measured:
    """The samples of a direction that measure a line (below ``MEASURABLE_FRACTION`` x their position
    Nyquist frequency): shared by every line with the same samples, so that they are fitted together."""

    def __init__(self, use: np.ndarray):
        self.use = use
        self.n = int(np.count_nonzero(use))
        self.lo = self.hi = None

    def check(self, m: Motion, f: float, knots: int, how: str) -> None:
        """Refuse (one sentence) a line with too few samples, or samples of one speed only."""
        q = 3 * (knots + _DEGREE + 1) + (how == "fitted")
        dname = "positive" if m.direction > 0 else "negative"
        if self.n < 4 * q:
            raise InputError(f"line at {f:.6g} cycles/{m.unit}: {self.n} samples of the {dname} direction lie "
                             f"below {MEASURABLE_FRACTION:g} x their position Nyquist frequency; tracking needs at "
                             f"least {4 * q}")
        if self.lo is None:  # the speeds of the samples measuring the line span the track's knots
            from ._kernels import masked_range

            _, self.lo, self.hi = masked_range(m.speed, self.use)
        if not self.hi > self.lo:
            raise InputError(f"line at {f:.6g} cycles/{m.unit}: the {dname} samples that measure it share one speed")


def _fit_tracks(m: Motion, lines: list, group: _Measured, knots: int, level: float, J, how: str, gear) -> list:
    """The :class:`OrderTrack` of every ``(frequency, label)`` of ``lines``, all measured on the
    samples of ``group`` (checked): one pass over the samples for all of them."""
    lo, hi, n_use = group.lo, group.hi, group.n
    n_basis = knots + _DEGREE + 1
    tk = np.concatenate([[lo] * (_DEGREE + 1), np.linspace(lo, hi, knots + 2)[1:-1], [hi] * (_DEGREE + 1)])
    grid = np.linspace(lo, hi, SPEED_GRID)
    cell = (hi - lo) / (SPEED_GRID - 1)
    edges = np.concatenate([grid - cell / 2, [hi + cell / 2]])
    # with the moments: samples per grid cell, and travel of the samples near each grid speed
    # (within half a knot span): speed x the median step
    mom = _moments(m, group.use, [f for f, _ in lines], tk, how == "fitted", edges)
    normals = _per_line(mom, len(lines), tk, how == "fitted")
    counts, travel = mom[4], mom[5] * m.median_step
    half = max(int(round(0.5 * (SPEED_GRID - 1) / (knots + 1))), 0)
    near = np.convolve(travel, np.ones(2 * half + 1), mode="same")
    tracks = []
    for (f, label), (A, b, yy) in zip(lines, normals):
        beta, cov, sigma = _solve(A, b, yy, n_use)
        out = _evaluate(beta, cov, tk, n_basis, grid, level)
        few = f * near < MIN_TRACK_CYCLES
        for arr in out.values():
            arr[counts == 0] = np.nan  # no sample near this speed: not measured there
            arr[few] = np.nan          # less than a cycle of the line near this speed
        j_fit = float(beta[-1]) if how == "fitted" else J
        j_se = float(math.sqrt(cov[-1, -1])) if how == "fitted" else None
        notes = [f"velocity from the {m.velocity_source}; white-noise standard errors (delta method)"]
        if few.any():
            notes.append(f"not tracked at {int(few.sum())} of {SPEED_GRID} speeds: the samples near them hold less "
                         f"than {MIN_TRACK_CYCLES:g} cycle of the line together")
        tracks.append(OrderTrack(f, label, None if gear is None else gear.order(f), m.direction, m.unit, grid,
                                 out["amp"], out["se"], out["lower"], out["upper"], out["phase"], out["phase_se"],
                                 counts.copy(), (lo, hi), n_use, len(m) - n_use, sigma, float(level), int(knots),
                                 j_fit, j_se, how, notes))
    return tracks


def _grid_cells(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The cell ``i`` with ``edges[i] <= x < edges[i + 1]`` of every ``x`` within ``[edges[0],
    edges[-1])`` (equal cells; as ``np.histogram(x, edges)`` counts them): the rule the track's
    one pass over the samples applies (:func:`~gearspec.spectrum._kernels.grid_cell`)."""
    from ._kernels import grid_cells

    return grid_cells(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(edges, dtype=float))


def _inertia_choice(inertia, gear) -> tuple[float | None, str]:
    """``(J to subtract, how)``: how is "given", "fitted" or "none"."""
    if isinstance(inertia, str):
        if inertia != "fit":
            raise InputError(f"inertia must be a number (kg m^2), 'fit' or None, got '{inertia}'")
        return None, "fitted"
    if inertia is None:
        if gear is not None and gear.inertia:
            return float(gear.inertia), "given"
        return None, "fitted"
    J = float(inertia)
    if not (math.isfinite(J) and J >= 0):
        raise InputError(f"inertia must be >= 0 (kg m^2 or kg), got {inertia!r}")
    return (J, "given") if J > 0 else (None, "none")


def _bspline_basis(x: np.ndarray, tk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The four nonzero cubic B-splines (knots ``tk``, clamped) at ``x`` (within the knots) and the
    index of the first: ``(N (4 x n), first (n,))`` (de Boor's recurrence, vectorised)."""
    p = _DEGREE
    j = np.clip(np.searchsorted(tk, x, side="right") - 1, p, len(tk) - p - 2)
    N = np.empty((p + 1, len(x)))
    N[0] = 1.0
    left = [None] + [x - tk[j + 1 - r] for r in range(1, p + 1)]
    right = [None] + [tk[j + r] - x for r in range(1, p + 1)]
    temp = np.empty(len(x))
    for r in range(1, p + 1):
        saved = np.zeros(len(x))
        for s in range(r):
            np.divide(N[s], right[s + 1] + left[r - s], out=temp)
            np.multiply(right[s + 1], temp, out=N[s])
            N[s] += saved
            np.multiply(left[r - s], temp, out=saved)
        N[r] = saved
    return N, j - p


def _span_polynomials(tk: np.ndarray) -> dict:
    """Per knot span j (``tk[j] < tk[j+1]``): ``C`` (4 x 4) with the four nonzero B-splines on it as
    cubics in the span's own coordinate ``u = (v - tk[j]) / (tk[j+1] - tk[j])``: ``N_(j-3+a)(v) =
    sum_s C[a, s] u^s`` (from the basis at four points of the span: exact for cubics)."""
    p = _DEGREE
    out = {}
    pts = np.array([0.1, 0.4, 0.7, 0.95])
    V = np.vander(pts, p + 1, increasing=True)
    for j in range(p, len(tk) - p - 1):
        h = tk[j + 1] - tk[j]
        if h <= 0:
            continue
        N, first = _bspline_basis(tk[j] + pts * h, tk)
        assert np.all(first == j - p)
        out[j] = np.linalg.solve(V, N.T).T  # N.T[i, a] = sum_s V[i, s] C[a, s]
    return out


def _normal_equations(m: Motion, use: np.ndarray, f: float, tk: np.ndarray, fit_j: bool):
    """``X'X``, ``X'y`` and ``y'y`` of one line's track design (see :func:`_normal_equations_many`)."""
    return _normal_equations_many(m, use, [f], tk, fit_j)[0]


def _normal_equations_many(m: Motion, use: np.ndarray, freqs, tk: np.ndarray, fit_j: bool) -> list:
    """``(X'X, X'y, y'y)`` of the track design of every line of ``freqs`` (the columns: B-splines of
    the level, of a (sine), of c (cosine), then the acceleration when J is fitted) on the samples
    ``use``, exactly, without forming it (``tk``: knots from the lowest to the highest speed of them):
    :func:`_moments`, then :func:`_per_line`."""
    edges = np.array([tk[0], tk[-1]])  # one speed cell: not used here
    return _per_line(_moments(m, use, freqs, tk, fit_j, edges), len(freqs), tk, fit_j)


def _moments(m: Motion, use: np.ndarray, freqs, tk: np.ndarray, fit_j: bool, edges: np.ndarray) -> tuple:
    """The moments of every knot span of the samples ``use`` for the lines ``freqs``, in one pass
    over the samples: ``(P, Q, AJ, yy, counts, travel)`` (see
    :func:`~gearspec.spectrum._kernels.track_sums`; counts and summed speeds per cell of the
    speed grid with ``edges``).

    On a knot span the four B-splines a sample touches are cubics in the span coordinate u, so every
    entry of ``X'X`` is a combination of the moments ``sum u^s g_k g_l`` (s = 0..6; g = 1, sin, cos)
    and ``X'y`` of ``sum u^s g_k y`` (s = 0..3), accumulated in double precision, then combined with
    the spans' polynomials (:func:`_per_line`; ``cos^2 = 1 - sin^2``).  The samples are taken in
    chunks in time order; per chunk the phases are reduced to one cycle in double precision, their
    sines and cosines taken by numpy in single precision, and the compiled kernel sums the moments."""
    from ._kernels import track_gather, track_sums

    nspan = len(tk) - 2 * _DEGREE - 1
    n_f = len(freqs)
    f_arr = np.asarray(freqs, dtype=float)
    P = np.zeros((nspan, 7, 1 + 4 * n_f))
    Q = np.zeros((nspan, 8, 1 + 2 * n_f))
    AJ = np.zeros((nspan, 2))
    counts = np.zeros(len(edges) - 1, np.int64)
    travel = np.zeros(len(edges) - 1)
    acc = m.acc if fit_j else np.zeros(0)
    X, Y, A = np.empty(_CHUNK), np.empty(_CHUNK), np.empty(_CHUNK)
    span = np.empty(_CHUNK, np.intp)
    ph = np.empty((n_f, _CHUNK), np.float32)
    S, C = np.empty_like(ph), np.empty_like(ph)
    yy = 0.0
    for chunk in _chunks(use):
        n = len(chunk)
        track_gather(chunk, m.theta, m.speed, m.y, acc, f_arr, tk, edges, X, Y, A, ph, span, counts, travel)
        np.sin(ph[:, :n], out=S[:, :n])
        np.cos(ph[:, :n], out=C[:, :n])
        yy += track_sums(X[:n], Y[:n], A[:n], span[:n], S[:, :n], C[:, :n], tk, P, Q, AJ)
    return P, Q, AJ, yy, counts, travel


def _per_line(mom: tuple, n_f: int, tk: np.ndarray, fit_j: bool) -> list:
    """``(X'X, X'y, y'y)`` of every line from the moments of :func:`_moments`."""
    P_all, Q_all, AJ, yy = mom[:4]
    nb = len(tk) - _DEGREE - 1
    q = 3 * nb + fit_j
    polys = _span_polynomials(tk)
    n_trig = 1 + 2 * n_f
    out = []
    for li in range(n_f):
        cols = [0, 1 + 2 * li, 2 + 2 * li]
        mom_l = {}
        for jj in polys:
            P, Q = P_all[jj - _DEGREE], Q_all[jj - _DEGREE]
            M = np.empty((7, 6))
            M[:, :3] = P[:, cols]
            M[:, 3:5] = P[:, n_trig + 2 * li:n_trig + 2 * li + 2]
            M[:, 5] = M[:, 0] - M[:, 3]  # cos^2 = 1 - sin^2
            mom_l[jj] = [M, Q[:4, cols], Q[4:, cols] if fit_j else None, AJ[jj - _DEGREE, 0], AJ[jj - _DEGREE, 1]]
        out.append(_assemble(mom_l, polys, nb, q, fit_j) + (yy,))
    return out


def _chunks(use: np.ndarray):
    """The indices of the ``True`` samples of ``use``, at most ``_CHUNK`` at a time, in order, without
    an index of them all (memory: one chunk)."""
    from ._kernels import mask_chunk

    start = 0
    while start < len(use):
        out = np.empty(_CHUNK, np.int64)
        n, start = mask_chunk(use, start, out)
        if n:
            yield out[:n]


#: the moment column of g_k g_l (g = 1, sin, cos)
_PAIR = {(0, 0): 0, (0, 1): 1, (0, 2): 2, (1, 1): 3, (1, 2): 4, (2, 2): 5}


def _assemble(mom: dict, polys: dict, nb: int, q: int, fit_j: bool):
    """``X'X`` and ``X'y`` from the moments of every span (see :func:`_normal_equations`)."""
    A = np.zeros((q, q))
    b = np.zeros(q)
    hankel = np.add.outer(np.arange(4), np.arange(4))
    for jj, C in polys.items():
        M, Y, Ya, aa, ay = mom[jj]
        j0 = jj - _DEGREE
        rows = [np.arange(j0, j0 + 4) + k * nb for k in range(3)]
        for k in range(3):
            for l in range(k, 3):
                blk = C @ M[hankel, _PAIR[(k, l)]] @ C.T
                A[np.ix_(rows[k], rows[l])] += blk
                if l != k:
                    A[np.ix_(rows[l], rows[k])] += blk.T
            b[rows[k]] += C @ Y[:, k]
            if fit_j:
                A[rows[k], q - 1] += C @ Ya[:, k]
                A[q - 1, rows[k]] += C @ Ya[:, k]
        if fit_j:
            A[q - 1, q - 1] += aa
            b[q - 1] += ay
    return A, b


def _solve(A, b, yy, n):
    """Least-squares coefficients, their covariance and the residual standard deviation."""
    q = len(b)
    scale = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(scale, scale)
    try:
        c, low = linalg.cho_factor(As)
        inv = linalg.cho_solve((c, low), np.eye(q))
    except linalg.LinAlgError:
        inv = linalg.pinvh(As)
    inv = inv / np.outer(scale, scale)
    beta = inv @ b
    rss = max(yy - float(beta @ b), 0.0)
    sigma = math.sqrt(rss / max(n - q, 1))
    return beta, sigma**2 * inv, sigma


def _evaluate(beta, cov, tk, nb, grid, level) -> dict:
    """Amplitude, phase and their pointwise errors and band on the speed ``grid``."""
    B = BSpline.design_matrix(grid, tk, _DEGREE).toarray()
    sa, sc = slice(nb, 2 * nb), slice(2 * nb, 3 * nb)
    a, c = B @ beta[sa], B @ beta[sc]
    amp = np.hypot(a, c)
    safe = np.maximum(amp, 1e-300)
    # delta method: d amp / d(alpha, gamma) = (a B, c B) / amp; d phase = (-c B, a B) / amp^2
    Caa, Ccc, Cac = cov[sa, sa], cov[sc, sc], cov[sa, sc]
    vaa = np.einsum("gi,ij,gj->g", B, Caa, B)
    vcc = np.einsum("gi,ij,gj->g", B, Ccc, B)
    vac = np.einsum("gi,ij,gj->g", B, Cac, B)
    se = np.sqrt(np.maximum(a * a * vaa + c * c * vcc + 2 * a * c * vac, 0)) / safe
    ph_se = np.sqrt(np.maximum(c * c * vaa + a * a * vcc - 2 * a * c * vac, 0)) / safe**2
    z = float(stats.norm.ppf(0.5 + level / 2))
    return {"amp": amp, "se": se, "lower": np.maximum(amp - z * se, 0.0), "upper": amp + z * se,
            "phase": np.arctan2(c, a), "phase_se": ph_se}


@dataclass
class OrderAnalysis:
    """Order maps (one per direction that moves enough; None otherwise) and tracks of lines."""

    maps: dict
    tracks: list
    skipped: list
    unit: str

    def to_dict(self) -> dict:
        return plain({"unit": self.unit, "frequency_unit": f"cycles/{self.unit}",
                      "maps": {("positive" if d > 0 else "negative"): (m.to_dict() if m is not None else None)
                               for d, m in self.maps.items()},
                      "tracks": [t.to_dict() for t in self.tracks], "skipped": self.skipped})


def order_analysis(rec: Recording, lines=(), *, gear=None, inertia: float | str | None = None,
                   min_speed: float | None = None, knots: int = 4, level: float = 0.95,
                   map_options: dict | None = None, workers: int | str = "auto") -> OrderAnalysis:
    """The order map of both directions and the track of every line in ``lines`` (frequencies in
    cycles per unit of theta or declared labels), each direction's samples prepared once and the
    lines measured on the same samples fitted in one pass over them.  A direction or line without
    enough measurable samples is listed in ``skipped`` with the reason.  ``workers``: directions
    analysed at once, in threads, with the same results whatever the number; ``"auto"``: two on a
    machine with two or more CPUs when the recording has at least ``PARALLEL_MIN_SAMPLES`` rows."""
    gear = gear if gear is not None else rec.gear
    J, how = _inertia_choice(inertia, gear)
    resolved = [resolve_line(gear, ln) for ln in lines]
    if workers == "auto":
        workers = 2 if (os.cpu_count() or 1) >= 2 and len(rec) >= PARALLEL_MIN_SAMPLES else 1
    if not (isinstance(workers, (int, np.integer)) and workers >= 1):
        raise InputError(f"workers must be 'auto' or a number of threads >= 1, got {workers!r}")
    with threadpool_limits(limits=1, user_api="blas"):  # small products: BLAS threads only contend
        rec.tau, rec.pieces()  # cached by the recording: filled here, before the threads read them
        try:
            kin = _kinematics(rec, bool(J) or how == "fitted")
            if min_speed is None:  # once for both directions (a percentile over all rows)
                min_speed = _default_min_speed(kin[0])
        except InputError as exc:
            kin = exc

        def one(d):
            return _one_direction(rec, d, kin, resolved, gear, J, how, min_speed, knots, level, map_options)

        if workers > 1:
            with ThreadPoolExecutor(max_workers=2, thread_name_prefix="gearspec-order") as pool:
                done = list(pool.map(one, (1, -1)))
        else:
            done = [one(d) for d in (1, -1)]
    maps = {d: mp for d, (mp, _, _) in zip((1, -1), done)}
    return OrderAnalysis(maps, [t for _, tr, _ in done for t in tr], [s for _, _, sk in done for s in sk], rec.unit)


def _one_direction(rec, d, kin, resolved, gear, J, how, min_speed, knots, level, map_options):
    """``(order map or None, tracks, skipped)`` of one direction (see :func:`order_analysis`)."""
    name = "positive" if d > 0 else "negative"
    skipped = []
    try:
        if isinstance(kin, InputError):
            raise kin
        m = _motion(rec, d, kin, min_speed, J, how == "fitted")
    except InputError as exc:
        return None, [], [{"direction": d, "what": "map", "reason": str(exc)}]
    try:
        mp = order_map(rec, direction=d, gear=gear, mot=m, min_speed=min_speed, **(map_options or {}))
    except InputError as exc:
        mp = None
        skipped.append({"direction": d, "what": "map", "reason": str(exc)})
    # lines measured on the same samples (the same mask) are fitted together, reported in their order
    groups = []
    limit = MEASURABLE_FRACTION * m.nyquist if resolved else None  # the highest measurable frequency per sample
    for i, (f, _) in enumerate(resolved):
        use = f < limit
        g = next((g for g in groups if np.array_equal(g[0].use, use)), None)
        if g is None:
            groups.append((_Measured(use), [i]))
        else:
            g[1].append(i)
    out = {}
    for group, members in groups:
        fit = []
        for i in members:
            f, lab = resolved[i]
            try:
                _check_options(knots, level)
                group.check(m, f, knots, how)
                fit.append(i)
            except InputError as exc:
                out[i] = {"direction": d, "what": lab or f"{f:.6g} cycles/{rec.unit}", "frequency": f,
                          "reason": f"{name} direction: {exc}"}
        if fit:
            tracks = _fit_tracks(m, [resolved[i] for i in fit], group, knots, level, J, how, gear)
            out.update(zip(fit, tracks))
    tracks = [out[i] for i in range(len(resolved)) if isinstance(out[i], OrderTrack)]
    return mp, tracks, skipped + [out[i] for i in range(len(resolved)) if not isinstance(out[i], OrderTrack)]
