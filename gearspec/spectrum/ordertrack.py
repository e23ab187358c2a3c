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
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, stats
from scipy.interpolate import BSpline

from ..errors import InputError
from ..jsonsafe import plain
from ..recording import Recording
from .analysis import MEASURABLE_FRACTION
from .ordermap import Motion, motion, order_map

__all__ = ["OrderTrack", "order_track", "resolve_line", "OrderAnalysis", "order_analysis", "SPEED_GRID"]

#: speeds at which a track is evaluated
SPEED_GRID = 64
_CHUNK = 1 << 16
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
    if not (isinstance(knots, (int, np.integer)) and 0 <= knots <= 20):
        raise InputError(f"knots must be an integer from 0 to 20, got {knots!r}")
    if not (0 < level < 1):
        raise InputError(f"level must be between 0 and 1, got {level!r}")
    J, how = _inertia_choice(inertia, gear)
    m = mot if mot is not None else motion(rec, direction, min_speed=min_speed, inertia=J, need_acc=how == "fitted")
    if how == "fitted" and m.acc is None:
        raise InputError("order_track: the prepared motion has no acceleration to fit the inertia with")
    use = f < MEASURABLE_FRACTION * m.nyquist
    n_use = int(np.count_nonzero(use))
    n_basis = knots + _DEGREE + 1
    q = 3 * n_basis + (how == "fitted")
    dname = "positive" if m.direction > 0 else "negative"
    if n_use < 4 * q:
        raise InputError(f"line at {f:.6g} cycles/{rec.unit}: {n_use} samples of the {dname} direction lie below "
                         f"{MEASURABLE_FRACTION:g} x their position Nyquist frequency; tracking needs at least {4 * q}")
    sp = m.speed[use]
    lo, hi = float(sp.min()), float(sp.max())
    if not hi > lo:
        raise InputError(f"line at {f:.6g} cycles/{rec.unit}: the {dname} samples that measure it share one speed")
    tk = np.concatenate([[lo] * (_DEGREE + 1), np.linspace(lo, hi, knots + 2)[1:-1], [hi] * (_DEGREE + 1)])
    A, b, yy = _normal_equations(m, use, f, tk, how == "fitted")
    beta, cov, sigma = _solve(A, b, yy, n_use)
    grid = np.linspace(lo, hi, SPEED_GRID)
    out = _evaluate(beta, cov, tk, n_basis, grid, level)
    cell = (hi - lo) / (SPEED_GRID - 1)
    counts = np.histogram(sp, bins=np.concatenate([grid - cell / 2, [hi + cell / 2]]))[0]
    for arr in out.values():
        arr[counts == 0] = np.nan  # no sample near this speed: not measured there
    j_fit = float(beta[-1]) if how == "fitted" else J
    j_se = float(math.sqrt(cov[-1, -1])) if how == "fitted" else None
    notes = [f"velocity from the {m.velocity_source}; white-noise standard errors (delta method)"]
    return OrderTrack(f, label, None if gear is None else gear.order(f), m.direction, m.unit, grid, out["amp"],
                      out["se"], out["lower"], out["upper"], out["phase"], out["phase_se"], counts, (lo, hi), n_use,
                      len(m) - n_use, sigma, float(level), int(knots), j_fit, j_se, how, notes)


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
    """``X'X``, ``X'y`` and ``y'y`` of the track's design (the columns: B-splines of the level, of a
    (sine), of c (cosine), then the acceleration when J is fitted), exactly, without forming it.

    On a knot span the four B-splines a sample touches are cubics in the span coordinate u, so every
    entry of ``X'X`` is a combination of the moments ``sum u^s g_k g_l`` (s = 0..6; g = 1, sin, cos)
    and ``X'y`` of ``sum u^s g_k y`` (s = 0..3): a 7 x 6 and a 4 x 3 product per run of samples in
    one span, accumulated in double precision, then combined with the spans' polynomials."""
    nb = len(tk) - _DEGREE - 1
    q = 3 * nb + fit_j
    polys = _span_polynomials(tk)
    mom = {j: [np.zeros((7, 6)), np.zeros((4, 3)), np.zeros((4, 3)), 0.0, 0.0] for j in polys}
    yy = 0.0
    idx = np.flatnonzero(use)
    lo, hi = tk[0], tk[-1]
    p = _DEGREE
    for i in range(0, len(idx), _CHUNK):
        r = idx[i:i + _CHUNK]
        x = np.clip(m.speed[r], lo, hi)
        j = np.clip(np.searchsorted(tk, x, side="right") - 1, p, len(tk) - p - 2)
        u = (x - tk[j]) / (tk[j + 1] - tk[j])
        U = np.empty((7, len(r)))
        U[0] = 1.0
        for k in range(1, 7):
            np.multiply(U[k - 1], u, out=U[k])
        ph = np.mod(f * m.theta[r], 1.0).astype(np.float32)
        ph *= np.float32(2 * np.pi)
        y = m.y[r]
        G = np.empty((6, len(r)))  # 1, s, c, s^2, s c, c^2
        G[0] = 1.0
        G[1] = np.sin(ph)
        G[2] = np.cos(ph)
        np.multiply(G[1], G[1], out=G[3])
        np.multiply(G[1], G[2], out=G[4])
        np.multiply(G[2], G[2], out=G[5])
        Gy = G[:3] * y
        Ga = G[:3] * m.acc[r] if fit_j else None
        yy += float(y @ y)
        cuts = np.concatenate(([0], np.flatnonzero(np.diff(j)) + 1, [len(r)]))
        for a, e in zip(cuts[:-1], cuts[1:]):
            acc = mom[int(j[a])]
            acc[0] += U[:, a:e] @ G[:, a:e].T
            acc[1] += U[:4, a:e] @ Gy[:, a:e].T
            if fit_j:
                acc[2] += U[:4, a:e] @ Ga[:, a:e].T
                acc[3] += float(Ga[0, a:e] @ m.acc[r][a:e])
                acc[4] += float(Ga[0, a:e] @ y[a:e])
    return _assemble(mom, polys, nb, q, fit_j) + (yy,)


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
                   map_options: dict | None = None) -> OrderAnalysis:
    """The order map of both directions and the track of every line in ``lines`` (frequencies in
    cycles per unit of theta or declared labels), each direction's samples prepared once.  A
    direction or line without enough measurable samples is listed in ``skipped`` with the reason."""
    gear = gear if gear is not None else rec.gear
    J, how = _inertia_choice(inertia, gear)
    maps, tracks, skipped = {}, [], []
    resolved = [resolve_line(gear, ln) for ln in lines]
    for d in (1, -1):
        name = "positive" if d > 0 else "negative"
        try:
            m = motion(rec, d, min_speed=min_speed, inertia=J, need_acc=how == "fitted")
        except InputError as exc:
            skipped.append({"direction": d, "what": "map", "reason": str(exc)})
            maps[d] = None
            continue
        try:
            maps[d] = order_map(rec, direction=d, gear=gear, mot=m, min_speed=min_speed, **(map_options or {}))
        except InputError as exc:
            maps[d] = None
            skipped.append({"direction": d, "what": "map", "reason": str(exc)})
        for f, lab in resolved:
            try:
                tracks.append(order_track(rec, f, direction=d, knots=knots, level=level,
                                          inertia=J if how == "given" else ("fit" if how == "fitted" else 0),
                                          gear=gear, mot=m))
            except InputError as exc:
                skipped.append({"direction": d, "what": lab or f"{f:.6g} cycles/{rec.unit}", "frequency": f,
                                "reason": f"{name} direction: {exc}"})
    return OrderAnalysis(maps, tracks, skipped, rec.unit)
