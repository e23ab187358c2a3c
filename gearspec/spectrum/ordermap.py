"""Order analysis of motion at varying speed: the angle-domain view of whole motions per direction
(:func:`motion`) and the order map (:func:`order_map`), amplitude over order and speed, the
``rpmordermap`` view of MATLAB's order analysis.  One order tracked against speed with a confidence
band is :func:`~gearspec.spectrum.ordertrack.order_track`.

The samples of every run are split into pieces of one direction of motion (``direction * v`` above
``min_speed``; ``v`` the recording's ``velocity`` channel, else the Savitzky-Golay derivative of
:func:`gearspec.segment.derivatives`).  The position Nyquist frequency is known sample by sample:
the package's rule (:func:`~gearspec.spectrum.analysis.position_nyquist`) applied to consecutive
blocks of ``NYQUIST_BLOCK`` samples of each piece; a line is measurable on a sample when it lies
below ``MEASURABLE_FRACTION`` times that sample's position Nyquist frequency.

Order map (method, chosen for cost): each piece's friction magnitude ``direction * (torque - J
thetadd)`` is resampled linearly onto one position grid (spacing ``1 / (2 f_grid)``, the same for
every piece, so every window has the same order bins; the interpolation's response sinc^2(f ds) at
the window's sample spacing ds divided out), cut into windows of ``window`` grid points with 50 %
overlap, detrended (a line per window), Hann-windowed and transformed (amplitude-calibrated: a
sinusoid of amplitude A reads A at its bin). Each window gets its speed (travel / duration) and the
position Nyquist of the samples inside it (the lowest of their blocks). A cell (speed bin, order) is
the root-mean-square amplitude of the windows of that bin where the order is measurable; where no
window of the bin measures it the cell is NaN, never a number. Cost: about one FFT of the samples
(the grid has about as many points as samples), no matrix of samples x orders. Given ``orders``,
each window is projected on exactly those frequencies instead (no scalloping; the FFT grid reads a
line between two bins up to 15 % low). The root-mean-square of windows reads ``sqrt(A^2 +
noise^2)``: the bin's ``noise`` (median amplitude of its cells) says where a cell is
indistinguishable from noise.
Amplitudes with standard errors and confidence bands come from :func:`order_track`'s regression.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from threadpoolctl import threadpool_limits

from ..errors import InputError
from ..jsonsafe import plain
from ..recording import Recording
from .analysis import MEASURABLE_FRACTION, rows_position_nyquist

__all__ = ["Motion", "motion", "OrderMap", "order_map", "NYQUIST_BLOCK", "MIN_SPEED_FRACTION", "MIN_PIECE"]

#: samples per block over which the position Nyquist frequency is computed (a few tenths of a
#: second at 1 kHz: short against a speed change, long enough for the 95th percentile of spacings)
NYQUIST_BLOCK = 256
#: default ``min_speed``: this fraction of the 99th percentile of |v| (slower samples are rest or
#: reversal: neither direction)
MIN_SPEED_FRACTION = 0.02
#: pieces of one direction shorter than this many samples are left out (counted in ``excluded``)
MIN_PIECE = 16
#: window lengths (grid points) ``window="auto"`` chooses from
AUTO_WINDOWS = (32, 64, 128, 256)
#: windows transformed at once (memory: this x window points)
_WINDOW_BATCH = 2048


@dataclass
class Motion:
    """The samples of a recording moving one way, concatenated piece by piece (SI units).

    ``theta`` (rad or m), ``speed`` (|v|, unit/s), ``y`` the friction magnitude ``direction *
    (torque - J thetadd)`` (Nm or N; J removed only when ``inertia`` is given), ``acc`` (unit/s^2, or
    None when not computed), ``t`` (s), ``nyquist`` the position Nyquist frequency of each sample's
    block (cycles per unit of theta), ``bounds`` the ``(start, stop)`` of every piece in these arrays,
    ``excluded`` rows of the recording not in this direction's pieces, per reason."""

    direction: int
    unit: str
    t: np.ndarray
    theta: np.ndarray
    speed: np.ndarray
    y: np.ndarray
    acc: np.ndarray | None
    nyquist: np.ndarray
    bounds: list
    min_speed: float
    inertia: float | None
    velocity_source: str
    excluded: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.theta)

    @cached_property
    def median_step(self) -> float:
        """The median time step between consecutive samples (s; 0 for fewer than two), computed once."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0


def _check_direction(direction) -> int:
    if direction not in (1, -1):
        raise InputError(f"direction must be +1 or -1, got {direction!r}")
    return int(direction)


def motion(rec: Recording, direction: int = 1, *, min_speed: float | None = None, inertia: float | None = None,
           need_acc: bool = False, deriv_window: int | None = None) -> Motion:
    """The pieces of ``rec`` moving in ``direction`` (+1 or -1) faster than ``min_speed`` (unit/s;
    default ``MIN_SPEED_FRACTION`` x the 99th percentile of |v|), with the position Nyquist frequency
    of every sample.  ``inertia`` (kg m^2 or kg): ``J * thetadd`` is subtracted from the torque;
    ``need_acc``: keep the acceleration (unit/s^2) for a fit of J."""
    d = _check_direction(direction)
    return _motion(rec, d, _kinematics(rec, bool(inertia) or need_acc, deriv_window), min_speed, inertia, need_acc)


def _kinematics(rec: Recording, need_acc: bool = False, deriv_window: int | None = None) -> tuple:
    """``(v, acc, source)``: the velocity of every row (unit/s: the ``velocity`` channel, else the
    Savitzky-Golay derivative of :func:`gearspec.segment.derivatives`), the acceleration (unit/s^2;
    None unless ``need_acc`` or the recording has no velocity channel) and where v came from: what
    :func:`motion` needs, computed once for both directions."""
    from ..segment import derivatives

    has_v = "velocity" in rec.data
    acc = None
    if not has_v or need_acc:
        v_d, acc = derivatives(rec, deriv_window)
    v = rec.channel("velocity").astype(float) if has_v else v_d
    return v, acc, "velocity channel" if has_v else "Savitzky-Golay derivative of theta"


def _default_min_speed(v: np.ndarray) -> float:
    """``MIN_SPEED_FRACTION`` x the 99th percentile of the finite |v| (unit/s; 0 without any)."""
    a = np.abs(v)
    if not np.isfinite(a).all():
        a = a[np.isfinite(a)]
    return MIN_SPEED_FRACTION * _percentile_99(a) if len(a) else 0.0


def _percentile_99(a: np.ndarray) -> float:
    """``np.percentile(a, 99)`` (linear interpolation between the two order statistics around rank
    ``0.99 (n - 1)``), without partitioning all of ``a`` (overwritten): the values at or above the
    99th percentile of every 64th value hold both order statistics unless that guess is too high
    (checked by counting; then all of ``a`` is partitioned)."""
    n = len(a)
    if n < 1 << 16:
        return float(np.percentile(a, 99, overwrite_input=True))
    pos = 0.99 * (n - 1)
    lo = int(math.floor(pos))
    guess = np.percentile(a[::64], 98.0)
    top = a[a >= guess]
    below = n - len(top)  # values under the guess: the ranks of top start there
    if below > lo:
        return float(np.percentile(a, 99, overwrite_input=True))
    k = (lo - below, min(lo + 1, n - 1) - below)
    top.partition(k)
    x0, x1 = float(top[k[0]]), float(top[k[1]])
    return x0 + (x1 - x0) * (pos - lo)


def _motion(rec: Recording, d: int, kin: tuple, min_speed, inertia, need_acc: bool) -> Motion:
    """:func:`motion` from the :func:`_kinematics` of the recording."""
    v, acc, source = kin
    if min_speed is None:
        min_speed = _default_min_speed(v)
    if not (math.isfinite(min_speed) and min_speed >= 0):
        raise InputError(f"min_speed must be a speed >= 0 in {rec.unit}/s, got {min_speed!r}")
    from ._kernels import direction_runs, gather_runs

    # the pieces: runs of moving samples (d v > min_speed; with J removed, a finite acceleration)
    # within each stretch of the recording, at least MIN_PIECE long, gathered in one pass
    sub_j = bool(inertia) and acc is not None
    stretches = np.array([(a, b) for _, a, b in rec.pieces()], dtype=np.int64).reshape(-1, 2)
    no_acc = np.zeros(0)
    rs = np.empty(len(v) // MIN_PIECE + len(stretches) + 1, np.int64)
    re = np.empty_like(rs)
    n_runs, n_moving = direction_runs(v, float(min_speed), d, acc if sub_j else no_acc, sub_j,
                                      stretches[:, 0], stretches[:, 1], MIN_PIECE, rs, re)
    rs, re = rs[:n_runs], re[:n_runs]
    lengths = re - rs
    ends = np.cumsum(lengths)
    bounds = [(int(e - k), int(e)) for e, k in zip(ends, lengths)]
    n = int(ends[-1]) if len(ends) else 0
    excluded = {"other direction or slower than min_speed": len(rec) - n_moving,
                f"pieces shorter than {MIN_PIECE} samples": n_moving - n}
    keep_acc = bool(need_acc and acc is not None)
    t, theta, speed, y = (np.empty(n) for _ in range(4))
    acc_m = np.empty(n if keep_acc else 0)
    gather_runs(rs, re, rec.t, rec.theta, v, rec.tau, acc if acc is not None else no_acc,
                float(inertia) if sub_j else 0.0, d, keep_acc, t, theta, speed, y, acc_m)
    nyq = _block_nyquist(theta, bounds)
    return Motion(d, rec.unit, t, theta, speed, y, acc_m if keep_acc else None, nyq, bounds, float(min_speed),
                  inertia if inertia else None, source, excluded)


def _block_nyquist(theta: np.ndarray, bounds) -> np.ndarray:
    """The position Nyquist frequency of every sample: the package's rule
    (:func:`~gearspec.spectrum.analysis.position_nyquist`: half the inverse of the 95th percentile of
    the nonzero spacings, in single precision) over consecutive blocks of ``NYQUIST_BLOCK`` samples of
    every piece ``(start, stop)`` of ``theta`` (the pieces one after the other; a piece's last block
    joined to its neighbour when shorter than half a block), the spacing into the block included (a
    block of one sample at the start of a piece has none: inf).  All blocks at once: each block's
    spacings a row of one array, padded with NaN (sorted last, as in the rule), rows sorted; the same
    numbers as the rule applied block by block."""
    sp = np.empty(max(len(theta) - 1, 0), np.float32)  # as position_nyquist: a double difference, rounded
    np.subtract(theta[1:], theta[:-1], out=sp, casting="unsafe")
    np.abs(sp, out=sp)
    n_p = np.array([e - s for s, e in bounds], dtype=np.int64)
    if not len(n_p):
        return np.empty(len(theta))
    # per piece: blocks of NYQUIST_BLOCK samples, the last one joined to its neighbour when shorter
    # than half a block; per block: first sample, first and end spacing
    n_blk = -(-n_p // NYQUIST_BLOCK)
    n_blk -= (n_blk > 1) & (n_p - (n_blk - 1) * NYQUIST_BLOCK < NYQUIST_BLOCK // 2)
    k = _local_index(n_blk)
    s0 = np.repeat(np.array([s for s, _ in bounds], dtype=np.int64), n_blk)
    start = k * NYQUIST_BLOCK
    end = np.where(k == np.repeat(n_blk, n_blk) - 1, np.repeat(n_p, n_blk), start + NYQUIST_BLOCK)
    first, lo, hi = s0 + start, s0 + np.maximum(start - 1, 0), s0 + end - 1
    length = hi - lo
    nyq = np.empty(len(first))
    # most blocks hold exactly NYQUIST_BLOCK spacings (a view of them per block); the others (a
    # piece's first and last) are padded with NaN to the longest
    full = length == NYQUIST_BLOCK
    if full.any():
        nyq[full] = rows_position_nyquist(sliding_window_view(sp, NYQUIST_BLOCK)[lo[full]], length[full])
    if not full.all():
        width = max(int(length[~full].max()), 1)
        padded = np.concatenate([sp, np.full(width, np.nan, np.float32)])
        rows = sliding_window_view(padded, width)[lo[~full]]
        rows[np.arange(width)[None, :] >= length[~full, None]] = np.nan
        nyq[~full] = rows_position_nyquist(rows, length[~full])
    return np.repeat(nyq, np.diff(np.append(first, len(theta))))


# ---------------------------------------------------------------------- the order map
@dataclass
class OrderMap:
    """Amplitude over order and speed for one direction (see the module's docstring).

    ``frequency`` (K, cycles per unit of theta), ``order`` (K, per output turn; None without a gear
    train), ``order_reference`` (K, per turn of the reference shaft; None on a linear axis),
    ``speed_edges`` (B + 1, unit/s), ``speed`` (B, mean window speed, NaN when empty), ``amplitude``
    (B x K, torque units, NaN where not measurable), ``windows`` (B x K, windows averaged per cell),
    ``limit`` (B, the highest frequency measured in the bin: ``MEASURABLE_FRACTION`` x the highest
    window Nyquist), ``noise`` (B, median cell amplitude; NaN for fewer than 16 frequencies), ``samples`` (B)."""

    direction: int
    unit: str
    frequency: np.ndarray
    order: np.ndarray | None
    order_reference: np.ndarray | None
    speed_edges: np.ndarray
    speed: np.ndarray
    amplitude: np.ndarray
    windows: np.ndarray
    limit: np.ndarray
    noise: np.ndarray
    samples: np.ndarray
    resolution: float
    window: int
    method: str
    min_speed: float
    notes: list = field(default_factory=list)

    @property
    def torque_unit(self) -> str:
        return "Nm" if self.unit == "rad" else "N"

    def cell(self, frequency: float, speed: float) -> float:
        """The amplitude (torque units) of the cell nearest ``frequency`` in the bin holding ``speed``."""
        b = int(np.searchsorted(self.speed_edges, speed, side="right")) - 1
        if not 0 <= b < len(self.speed):
            return float("nan")
        return float(self.amplitude[b, int(np.argmin(np.abs(self.frequency - frequency)))])

    def to_dict(self) -> dict:
        return plain({"direction": self.direction, "unit": self.unit, "torque_unit": self.torque_unit,
                      "frequency_unit": f"cycles/{self.unit}", "speed_unit": f"{self.unit}/s",
                      "method": self.method, "window": self.window, "resolution": self.resolution,
                      "min_speed": self.min_speed, "frequency": self.frequency, "order": self.order,
                      "order_reference": self.order_reference, "speed_edges": self.speed_edges,
                      "speed": self.speed, "samples": self.samples, "limit": self.limit, "noise": self.noise,
                      "amplitude": self.amplitude, "windows": self.windows, "notes": self.notes})


def order_map(rec: Recording, *, direction: int = 1, orders=None, speed_bins: int | np.ndarray = 16,
              max_frequency: float | None = None, window: int | str = "auto", min_speed: float | None = None,
              inertia: float | None = None, gear=None, mot: Motion | None = None) -> OrderMap:
    """The order map of ``rec`` in ``direction`` (+1 or -1).

    Parameters
    ----------
    orders : array of float, optional
        Frequencies (cycles per unit of theta) to read exactly; default the FFT bins of a window up
        to ``max_frequency``.
    speed_bins : int or array
        Number of equal speed bins from ``min_speed`` to the fastest window, or their edges (unit/s).
    max_frequency : float, optional
        Highest frequency of the position grid (cycles/unit); default the Nyquist frequency of the
        mean position spacing (the grid then has about as many points as samples), raised to cover
        ``orders`` (at most four grid points per sample).
    window : int or "auto"
        Grid points per window (>= 16); the order resolution is ``2 max_frequency / window``.
        "auto": the longest of 32, 64, 128, 256 that the median piece holds four times.
    min_speed, inertia
        As :func:`motion`; ``inertia`` defaults to the gear spec's (kg m^2 or kg).
    gear : GearTrain, optional
        For orders per output turn (default the recording's).

    Returns
    -------
    OrderMap
    """
    d = _check_direction(direction)
    gear = gear if gear is not None else rec.gear
    if inertia is None and gear is not None:
        inertia = gear.inertia
    if not (window == "auto" or (isinstance(window, (int, np.integer)) and window >= 16)):
        raise InputError(f"window must be 'auto' or an integer number of grid points >= 16, got {window!r}")
    m = mot if mot is not None else motion(rec, d, min_speed=min_speed, inertia=inertia)
    if len(m) < (window if window != "auto" else AUTO_WINDOWS[0]):
        raise InputError(f"{', '.join(rec.sources) or 'recording'}: {len(m)} samples move in the "
                         f"{'positive' if d > 0 else 'negative'} direction faster than {m.min_speed:.3g} "
                         f"{rec.unit}/s; an order map needs at least {window}")
    travel = sum(abs(m.theta[e - 1] - m.theta[s]) for s, e in m.bounds)
    f_grid = float(max_frequency) if max_frequency is not None else 0.5 * len(m) / max(travel, 1e-300)
    given = orders is not None
    if given:
        orders = np.atleast_1d(np.asarray(orders, dtype=float))
        if not len(orders) or not np.all(np.isfinite(orders) & (orders > 0)):
            raise InputError("orders must be positive frequencies in cycles per unit of theta")
        f_grid = max(f_grid, float(orders.max()) / MEASURABLE_FRACTION)
    f_grid = min(f_grid, 2.0 * len(m) / max(travel, 1e-300))  # at most four grid points per sample
    spacing = 0.5 / f_grid
    if window == "auto":
        window = _auto_window(m, spacing)
    length = window * spacing
    freq = orders if given else np.arange(1, window // 2 + 1) / length
    with threadpool_limits(limits=1, user_api="blas"):  # small products: BLAS threads only contend
        wins = _window_spectra(m, spacing, window, freq if given else None)
    if not len(wins[0]):
        name = "positive" if d > 0 else "negative"
        raise InputError(f"{', '.join(rec.sources) or 'recording'}: no piece of the {name} "
                         f"direction travels one window ({window} points at {spacing:.3g} {rec.unit}: "
                         f"{window * spacing:.3g} {rec.unit}) without stopping; give a smaller window")
    edges = _speed_edges(speed_bins, m.min_speed, wins[0])
    return _bin_windows(m, wins, edges, freq, gear, window, length, "projection on given frequencies" if given
                        else "Hann FFT of windows resampled over position")


def _auto_window(m: Motion, spacing: float) -> int:
    """The longest of ``AUTO_WINDOWS`` grid points that the median piece (by travel) holds at
    least four times (short moves: short windows, so that each covers a narrow range of speeds)."""
    travel = np.array([abs(m.theta[e - 1] - m.theta[s]) for s, e in m.bounds])
    median = float(np.median(travel)) / spacing if len(travel) else 0.0
    fits = [w for w in AUTO_WINDOWS if 4 * w <= median]
    return max(fits) if fits else AUTO_WINDOWS[0]


def _speed_edges(speed_bins, lo: float, speeds: np.ndarray) -> np.ndarray:
    if np.ndim(speed_bins) == 0:
        nb = int(speed_bins)
        if nb < 1:
            raise InputError(f"speed_bins must be a positive number of bins or their edges, got {speed_bins!r}")
        hi = float(speeds.max()) if len(speeds) else lo + 1.0
        return np.linspace(lo, hi * (1 + 1e-9), nb + 1)
    edges = np.asarray(speed_bins, dtype=float)
    if edges.ndim != 1 or len(edges) < 2 or not np.all(np.diff(edges) > 0):
        raise InputError("speed_bins edges must be increasing speeds (unit/s), at least two")
    return edges


def _window_layout(m: Motion, spacing: float, window: int):
    """The position grid of every piece (concatenated) and, per window: its first grid point there,
    its speed (unit/s: travel / duration), the lowest position Nyquist frequency of its samples
    (cycles/unit), its samples, and its mean sample spacing (unit).  One pass over the pieces for
    what needs a piece's own samples (interpolation, searches); the rest over all windows at once."""
    from ._kernels import layout_sizes, window_layout

    # position along the direction of motion (increasing in both directions); time order kept
    th_all = m.theta if m.direction > 0 else -m.theta
    bounds = np.array(m.bounds, dtype=np.int64).reshape(-1, 2)
    g0s, n_grids, n_wins = layout_sizes(th_all, bounds[:, 0], bounds[:, 1], float(spacing), int(window))
    n_g, n_w, n_p = int(n_grids.sum()), int(n_wins.sum()), int(np.count_nonzero(n_wins))
    outs = (np.empty(n_g), np.empty(n_w, np.int64), np.empty(n_w), np.empty(n_w), np.empty(n_w),
            np.empty(n_w + n_p, np.int64), np.empty(n_w, np.int64), np.empty(n_p, np.int64),
            np.empty(n_p, np.int64), np.empty(n_p, np.int64))
    window_layout(th_all, m.y, m.t, bounds[:, 0], bounds[:, 1], float(spacing), int(window), g0s,
                  (n_grids, n_wins), outs)
    grid, first, th_a, th_b, durs, halfs, i_b, n_win, start, ends = outs
    if not len(grid):
        z = np.zeros(0)
        return z, np.zeros(0, int), z, z, np.zeros(0, int), z
    # sample indices in the motion: each half-window edge's last sample at or before it, and each
    # window's first sample after its end (both within the window's piece)
    s_h, e_h = np.repeat(start, n_win + 1), np.repeat(ends, n_win + 1)
    halfs = np.minimum(np.maximum(halfs - 1, 0) + s_h, e_h - 1)
    i_b = np.minimum(i_b + 1 + np.repeat(start, n_win), np.repeat(ends, n_win))
    # the lowest Nyquist of each half window (a reduceat over every piece's half-window edges and
    # its end: the segment from a piece's end to the next piece's first edge is not used)
    last = np.cumsum(n_win + 1) - 1  # the end of the last window's first half, per piece
    idx = np.insert(halfs, last + 1, ends)
    if idx[-1] == len(m.nyquist):
        idx = idx[:-1]
    h_min = np.minimum.reduceat(m.nyquist, idx)
    pos = np.repeat(np.cumsum(n_win + 2) - (n_win + 2), n_win) + _local_index(n_win)
    nyqs = np.minimum(h_min[pos], h_min[pos + 1])
    counts = i_b - np.delete(halfs, last)
    travel = th_b - th_a
    speeds = travel / np.abs(durs)
    # linear interpolation between samples spaced ds reads a line at f low by sinc^2(f ds)
    # (the triangle kernel's response): divided out per window at its mean sample spacing
    ds = travel / np.maximum(counts - 1, 1)
    return grid, first, speeds, nyqs, counts, ds


def _local_index(n: np.ndarray) -> np.ndarray:
    """0 .. n_i - 1 for every group of ``n_i`` items, concatenated."""
    return np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)


def _window_spectra(m: Motion, spacing: float, window: int, freq: np.ndarray | None):
    """Per window of every piece: speed (unit/s), position Nyquist (cycles/unit), samples, and the
    squared calibrated amplitude at each frequency (FFT bins 1..window/2 or ``freq``), the windows
    of all pieces transformed together in batches."""
    grid, first, speeds, nyqs, counts, ds = _window_layout(m, spacing, window)
    hann = np.hanning(window + 2)[1:-1]
    gain = 2.0 / hann.sum()
    ramp = np.arange(window) - 0.5 * (window - 1)
    ramp /= np.sqrt(ramp @ ramp)
    f_k = freq if freq is not None else np.arange(1, window // 2 + 1) / (window * spacing)
    if freq is not None:  # projection on exact frequencies (the window's grid from 0)
        k = np.arange(window) * spacing
        proj = (hann[:, None] * np.exp(-2j * np.pi * k[:, None] * freq[None, :])) * gain
    # a straight line per window taken out (the friction level and slow position-dependent forces,
    # which a Hann window would leak into the lowest orders): the transform is linear, so the
    # transform of the window minus its line is the window's transform minus its mean and slope
    # times the transforms of a constant and of the ramp (computed once)
    line = np.stack([np.full(window, 1.0 / window), ramp], axis=1)  # (window, 2): mean and slope
    basis = np.stack([np.ones(window), ramp])  # the constant and the unit ramp
    if freq is None:
        T_line = np.fft.rfft(basis * hann, axis=1)[:, 1:window // 2 + 1] * gain
    else:
        T_line = basis @ proj
    power = np.empty((len(first), len(f_k)))
    rows = sliding_window_view(grid, window) if len(grid) >= window else None
    # pi x the window's mean sample spacing x the frequency: the interpolation's response
    # sinc^2 divided out (single precision: a correction factor, good to 1e-6)
    pi_f = (np.pi * f_k).astype(np.float32)
    for j in range(0, len(first), _WINDOW_BATCH):
        sel = first[j:j + _WINDOW_BATCH]
        b = rows[sel]  # a copy of the windows (they overlap in the grid)
        coef = b @ line
        if freq is None:
            b *= hann
            X = np.fft.rfft(b, axis=1)[:, 1:window // 2 + 1]
            X *= gain
        else:
            X = b @ proj
        X -= coef @ T_line
        z = np.multiply.outer(ds[j:j + _WINDOW_BATCH].astype(np.float32), pi_f)
        resp = np.sin(z)
        resp /= z
        np.square(resp, out=resp)
        np.maximum(resp, 0.1, out=resp)
        np.square(resp, out=resp)
        p = power[j:j + _WINDOW_BATCH]
        np.square(X.real, out=p)
        p += np.square(X.imag)
        p /= resp
    return speeds, nyqs, counts, power


def _bin_windows(m: Motion, wins, edges, freq, gear, window, length, method) -> OrderMap:
    """Windows into speed bins: root-mean-square amplitude of the windows measuring each cell."""
    speeds, nyqs, counts, power = wins
    nb, k = len(edges) - 1, len(freq)
    b = np.searchsorted(edges, speeds, side="right") - 1
    ok = (b >= 0) & (b < nb)
    # a cell counts a window only where its frequency is measurable there (the Nyquist mask); the
    # windows of each bin summed in their order
    from ._kernels import bin_sums

    p_sum = np.zeros((nb, k))
    n_win = np.zeros((nb, k), int)
    order = np.flatnonzero(ok)
    order = order[np.argsort(b[order], kind="stable")]
    bin_sums(order, b, power, MEASURABLE_FRACTION * nyqs, np.asarray(freq, float), p_sum, n_win)
    with np.errstate(invalid="ignore", divide="ignore"):
        amp = np.where(n_win > 0, np.sqrt(p_sum / np.maximum(n_win, 1)), np.nan)
    speed = np.full(nb, np.nan)
    limit = np.full(nb, np.nan)
    samples = np.zeros(nb, int)
    for i in range(nb):
        sel = ok & (b == i)
        if sel.any():
            speed[i] = float(speeds[sel].mean())
            limit[i] = MEASURABLE_FRACTION * float(nyqs[sel].max())
            samples[i] = int(counts[sel].sum() // 2)  # windows overlap by half
    with np.errstate(all="ignore"):  # a few given frequencies have no "median cell": no noise level
        noise = np.array([np.nanmedian(r) if np.isfinite(r).any() and k >= 16 else np.nan for r in amp])
    order = None if gear is None or gear.output_frequency is None else freq / gear.output_frequency
    order_ref = freq * 2 * math.pi if m.unit == "rad" else None
    notes = [f"velocity from the {m.velocity_source}; samples slower than {m.min_speed:.3g} {m.unit}/s left out"]
    if m.inertia:
        notes.append(f"inertia removed: torque - {m.inertia:g} x thetadd")
    return OrderMap(m.direction, m.unit, np.asarray(freq, float), order, order_ref, edges, speed, amp, n_win, limit,
                    noise, samples, 1.0 / length, window, method, m.min_speed, notes)
