"""Velocity reference profiles: whole motions for the twins and synthetic recordings.

Plain functions of ``(top_speed, duration, fs, **options)`` returning ``(t, v)``: ``t`` in s from 0
on a uniform grid of ``fs`` Hz (``round(duration * fs) + 1`` samples, the last at ``duration``),
``v`` in rad/s (or m/s) of the reference shaft.  Every profile starts and ends at rest and reaches
``+top_speed`` and ``-top_speed`` (sampled, within 1 % when a move spans 20 samples or more), passing
through every speed in between, so that a friction law over speed and a speed-decaying mesh line
can be identified from it in both directions:

``plateaus``
    Trapezoids from rest: held speeds ``top_speed * geomspace(1/30, 1, levels)``, each forwards then
    backwards.  (The twins' own plateau schedule is a different code path, selected by this name.)
``ramp``
    Slow linear ramps: rest -> +top -> rest -> -top -> rest, four equal legs.
``chirp``
    ``top_speed * sin(phi(t))``, the frequency sweeping linearly or logarithmically from ``f0`` to
    ``f1`` Hz; through zero speed twice a cycle.
``bell``
    Minimum-jerk point-to-point moves, velocity ``A / T * 30 s^2 (1 - s)^2`` (s = t / T, peak
    ``1.875 A / T``), of several peak speeds and durations, each there and back, with rests between
    (an industrial robot's moves).
``sine``
    A sum of sines (Fourier excitation trajectory) windowed to start and end at rest over the first
    half, then the same motion reversed in time and sign, so that the shaft returns to its start
    and both directions reach the top speed.

:func:`velocity_profile` dispatches by name; :data:`PROFILES` lists the names, :data:`SHAPES` says
each shape in one line (the command line's help), :func:`position` integrates a profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal.windows import tukey

from ..errors import InputError

__all__ = ["PROFILES", "SHAPES", "velocity_profile", "position", "plateaus", "ramp", "chirp", "bell", "sine",
           "Reference", "reference", "tracking"]

#: names of the profiles, in the order the command line lists them
PROFILES = ("plateaus", "ramp", "chirp", "bell", "sine")

#: one line per profile: its shape
SHAPES = {
    "plateaus": "held speeds from top/30 to top, each forwards then backwards (in a twin: its own plateau grid)",
    "ramp": "slow linear ramps rest -> +top -> rest -> -top -> rest",
    "chirp": "top x sin of a phase whose frequency sweeps linearly from 1/duration to 10/duration Hz",
    "bell": "minimum-jerk point-to-point moves peaking at 1, 0.5, 0.25, 0.1 and 0.04 x top, each there and back, "
            "rests between",
    "sine": "5 harmonics of 4/duration Hz (Schroeder phases) windowed to rest, then the same motion reversed",
}

#: fewest samples of a move (a ramp leg, a bell move, a plateau slot): a sampled peak within 1 % of the top
MIN_SAMPLES = 20


def _grid(top_speed: float, duration: float, fs: float) -> np.ndarray:
    """The uniform time grid (s), after checking the three common arguments."""
    for name, value in (("top_speed", top_speed), ("duration", duration), ("fs", fs)):
        if not (isinstance(value, (int, float, np.number)) and math.isfinite(value) and value > 0):
            raise InputError(f"velocity profile: {name} must be a positive finite number, got {value!r}")
    n = int(round(duration * fs)) + 1
    if n < 4 * MIN_SAMPLES:
        raise InputError(f"velocity profile: {duration:g} s at {fs:g} Hz is {n} samples; give at least "
                         f"{4 * MIN_SAMPLES} (a longer duration or a higher rate)")
    return np.arange(n) / fs


def _check_move(kind: str, seconds: float, fs: float, what: str) -> None:
    if seconds * fs < MIN_SAMPLES:
        raise InputError(f"{kind} profile: {what} lasts {seconds:.3g} s, fewer than {MIN_SAMPLES} samples at "
                         f"{fs:g} Hz; give a longer duration")


def position(v: np.ndarray, fs: float, theta0: float = 0.0) -> np.ndarray:
    """Position (rad or m) of a velocity sampled at ``fs`` Hz: ``theta0`` plus the cumulative
    trapezoid integral of ``v``, exact for a velocity linear between samples."""
    v = np.asarray(v, dtype=float)
    return float(theta0) + np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) / fs))


# ---------------------------------------------------------------------- the profiles
def plateaus(top_speed: float, duration: float, fs: float, *, levels: int = 5, ramp: float = 0.2
             ) -> tuple[np.ndarray, np.ndarray]:
    """Held speeds: ``levels`` speeds ``top_speed * geomspace(1/30, 1, levels)`` in increasing
    order, each as a trapezoid from rest forwards, then backwards; ``2 levels`` equal slots, each
    ramping up over the fraction ``ramp`` of the slot, holding, ramping down over ``ramp``.

    Returns ``(t, v)``: s, rad/s.
    """
    t = _grid(top_speed, duration, fs)
    levels = int(levels)
    if levels < 1 or not 0 < ramp < 0.5:
        raise InputError(f"plateaus profile: levels must be >= 1 and ramp in (0, 0.5), got {levels}, {ramp}")
    slot = duration / (2 * levels)
    _check_move("plateaus", ramp * slot, fs, "a ramp")
    speeds = [d * s for s in top_speed * np.geomspace(1 / 30, 1, levels) for d in (1.0, -1.0)]
    k = np.minimum((t / slot).astype(int), len(speeds) - 1)
    x = t / slot - k  # position within the slot, 0..1
    shape = np.clip(np.minimum(x, 1 - x) / ramp, 0.0, 1.0)
    return t, np.asarray(speeds)[k] * shape


def ramp(top_speed: float, duration: float, fs: float, *, rest: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Linear ramps: ``rest`` s at rest, then rest -> +top -> rest -> -top -> rest in four equal legs
    (constant acceleration ``4 top / (duration - 2 rest)``), then ``rest`` s at rest.

    Returns ``(t, v)``: s, rad/s.
    """
    t = _grid(top_speed, duration, fs)
    if not 0 <= rest < duration / 2:
        raise InputError(f"ramp profile: rest must be from 0 to half the duration (s), got {rest}")
    leg = (duration - 2 * rest) / 4
    _check_move("ramp", leg, fs, "a leg")
    knots = rest + leg * np.arange(5)
    v = np.interp(t, np.concatenate(([0.0], knots, [duration])), top_speed * np.array([0, 0, 1, 0, -1, 0, 0.0]))
    return t, v


def chirp(top_speed: float, duration: float, fs: float, *, f0: float | None = None, f1: float | None = None,
          method: str = "linear") -> tuple[np.ndarray, np.ndarray]:
    """A velocity chirp ``top_speed * sin(phi(t))``: the frequency ``phi' / 2 pi`` sweeps from ``f0``
    to ``f1`` Hz (default ``1 / duration`` to ``10 / duration``) linearly or, ``method="log"``,
    exponentially.  Both frequencies are scaled by one common factor (by less than half a cycle over
    the sweep) so that the sweep ends at a zero crossing: at rest.  At least one whole cycle.

    Returns ``(t, v)``: s, rad/s.
    """
    t = _grid(top_speed, duration, fs)
    f0 = 1.0 / duration if f0 is None else f0
    f1 = 10.0 / duration if f1 is None else f1
    if method not in ("linear", "log"):
        raise InputError(f"chirp profile: method must be 'linear' or 'log', got '{method}'")
    if not (0 < f0 < fs / 20 and 0 < f1 < fs / 20):
        raise InputError(f"chirp profile: f0 and f1 must be positive and below fs / 20 = {fs / 20:g} Hz, "
                         f"got {f0}, {f1}")
    T = duration
    if method == "linear" or math.isclose(f0, f1):
        phi = 2 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t * t / T)
    else:
        k = math.log(f1 / f0)
        phi = 2 * math.pi * f0 * T / k * np.expm1(k * t / T)
    half_cycles = round(phi[-1] / math.pi)
    if half_cycles < 2:
        raise InputError(f"chirp profile: {phi[-1] / (2 * math.pi):.2f} cycles from f0 = {f0:g} to f1 = {f1:g} Hz "
                         f"in {T:g} s; give at least one whole cycle (both directions)")
    v = top_speed * np.sin(phi * (half_cycles * math.pi / phi[-1]))
    v[-1] = 0.0  # sin(m pi) exactly
    return t, v


def bell(top_speed: float, duration: float, fs: float, *, peaks=(1.0, 0.5, 0.25, 0.1, 0.04),
         shares=(1.0, 0.7, 1.0, 0.7, 1.0), rest: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-jerk point-to-point moves, each there and back: move k peaks at
    ``peaks[k] * top_speed`` (fractions, the largest 1) and lasts ``T_k`` proportional to
    ``shares[k]``; its travel is ``A_k = peak_k T_k / 1.875`` and its velocity
    ``A_k / T_k * 30 s^2 (1 - s)^2``, ``s = (t - start) / T_k``.  ``rest`` s at rest before, between and
    after the moves (default: 10 % of the duration shared among them).

    Returns ``(t, v)``: s, rad/s.
    """
    t = _grid(top_speed, duration, fs)
    peaks, shares = np.atleast_1d(np.asarray(peaks, float)), np.atleast_1d(np.asarray(shares, float))
    if len(peaks) != len(shares) or not len(peaks) or np.any(peaks <= 0) or np.any(shares <= 0):
        raise InputError("bell profile: peaks and shares must be positive and as many as each other")
    if not math.isclose(peaks.max(), 1.0):
        raise InputError(f"bell profile: the largest peak must be 1 (the top speed), got {peaks.max():g}")
    n_rest = 2 * len(peaks) + 1
    rest = 0.1 * duration / n_rest if rest is None else float(rest)
    if not 0 <= rest * n_rest < duration:
        raise InputError(f"bell profile: {n_rest} rests of {rest:g} s leave no time for the moves")
    T = shares * (duration - n_rest * rest) / (2 * shares.sum())
    _check_move("bell", T.min(), fs, "the shortest move")
    v = np.zeros(len(t))
    start = rest
    for p, Tk in zip(peaks, T):
        for d in (1.0, -1.0):
            s = np.clip((t - start) / Tk, 0.0, 1.0)
            v += d * p * top_speed / 1.875 * 30 * s * s * (1 - s) ** 2
            start += Tk + rest
    return t, v


def sine(top_speed: float, duration: float, fs: float, *, harmonics: int = 5, base: float | None = None,
         taper: float = 0.2, seed=None) -> tuple[np.ndarray, np.ndarray]:
    """A Fourier excitation trajectory: over the first half, ``sum_k sin(2 pi k base t + phi_k) / k``
    for ``k = 1..harmonics`` (``base`` Hz, default ``4 / duration``: two cycles of the fundamental
    per half) times a Tukey window (``taper``: its tapered fraction) that starts and ends at rest;
    the second half is the same motion reversed in time and sign (the shaft returns to its start,
    both directions reach the top).  Scaled so that the largest sampled speed is ``top_speed``.
    Phases: Schroeder's ``pi k^2 / harmonics`` (low crest factor), or uniform random from ``seed``.

    Returns ``(t, v)``: s, rad/s.
    """
    t = _grid(top_speed, duration, fs)
    harmonics = int(harmonics)
    base = 4.0 / duration if base is None else base
    if harmonics < 1 or not 0 < base * harmonics < fs / 20 or not 0 < taper <= 1:
        raise InputError(f"sine profile: harmonics >= 1, 0 < base x harmonics < fs / 20 = {fs / 20:g} Hz and "
                         f"taper in (0, 1] needed, got {harmonics}, {base}, {taper}")
    n = len(t)
    h = (n + 1) // 2  # samples of the first half, the midpoint shared when n is odd
    th = t[:h]
    k = np.arange(1, harmonics + 1)
    phases = (np.pi * k * k / harmonics if seed is None else
              np.random.default_rng(seed).uniform(0, 2 * np.pi, harmonics))
    u = tukey(h, taper) * (np.sin(2 * np.pi * base * th[:, None] * k + phases) / k).sum(axis=1)
    v = np.concatenate((u, -u[::-1][n % 2:]))
    peak = np.abs(v).max()
    if not peak > 0:
        raise InputError("sine profile: the sines cancel over the duration; give another seed or base")
    return t, v * (top_speed / peak)


_FUNCTIONS = {"plateaus": plateaus, "ramp": ramp, "chirp": chirp, "bell": bell, "sine": sine}
_OPTIONS = {"plateaus": ("levels", "ramp"), "ramp": ("rest",), "chirp": ("f0", "f1", "method"),
            "bell": ("peaks", "shares", "rest"), "sine": ("harmonics", "base", "taper")}


def velocity_profile(kind: str, *, top_speed: float, duration: float, fs: float, seed=None, **options
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The velocity profile ``kind`` (one of :data:`PROFILES`), see the module docstring.

    Parameters
    ----------
    kind : str
        ``plateaus``, ``ramp``, ``chirp``, ``bell`` or ``sine``.
    top_speed : float
        Largest speed reached, in both directions (rad/s or m/s of the reference shaft).
    duration : float
        Seconds from the first sample (at rest) to the last (at rest).
    fs : float
        Sample rate of the grid (Hz).
    seed : int, optional
        Random phases of ``sine`` (other profiles are deterministic and ignore it).
    **options
        The profile's own keywords (:func:`plateaus`, :func:`ramp`, :func:`chirp`, :func:`bell`,
        :func:`sine`).

    Returns
    -------
    t : ndarray
        Times (s), ``arange(round(duration * fs) + 1) / fs``.
    v : ndarray
        Velocity (rad/s), ``v[0] == v[-1] == 0``.
    """
    if kind not in _FUNCTIONS:
        raise InputError(f"unknown velocity profile '{kind}' (one of {', '.join(PROFILES)})")
    unknown = sorted(set(options) - set(_OPTIONS[kind]))
    if unknown:
        raise InputError(f"{kind} profile: no option {', '.join(unknown)} (options: {', '.join(_OPTIONS[kind])})")
    for key, value in options.items():
        try:
            ok = key == "method" or bool(np.all(np.isfinite(np.asarray(value, dtype=float))))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise InputError(f"{kind} profile: option {key} must be a finite number (or numbers), got {value!r}")
    if kind == "sine":
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
            raise InputError(f"sine profile: the seed of its phases must be an integer >= 0, got {seed!r}")
        options["seed"] = seed
    return _FUNCTIONS[kind](top_speed, duration, fs, **options)


# ---------------------------------------------------------------------- a profile for a twin
@dataclass
class Reference:
    """A velocity profile resolved for a twin: ``kind``, ``top_speed`` (rad/s), ``duration`` (s),
    the grid's ``fs`` (Hz), the profile's ``options`` and ``seed``, and ``v`` (rad/s, on the grid)."""

    kind: str
    top_speed: float
    duration: float
    fs: float
    options: dict
    seed: object
    v: np.ndarray

    def position(self, theta0: float = 0.0) -> np.ndarray:
        """The reference position (rad) on the grid, from ``theta0``."""
        return position(self.v, self.fs, theta0)

    def record(self) -> dict:
        """What a twin's truth records of its profile (JSON-ready; ``fs`` is the twin's grid)."""
        return {"kind": self.kind, "top_speed": self.top_speed, "duration": self.duration, "fs": self.fs,
                "options": {k: (list(v) if isinstance(v, (tuple, np.ndarray)) else v) for k, v in self.options.items()},
                "seed": self.seed}


def reference(kind: str, *, top_speed: float, duration, fs: float, options: dict | None = None,
              who: str = "twin") -> Reference:
    """The profile ``kind`` for a twin (``who`` names it in messages): ``duration`` one number of
    seconds, ``options`` the profile's keywords plus an optional ``seed`` (see :func:`velocity_profile`)."""
    if isinstance(duration, bool) or not isinstance(duration, (int, float, np.number)):
        raise InputError(f"{who}: with the {kind} profile, duration is one number of seconds, got {duration!r}")
    if options is not None and not isinstance(options, dict):
        raise InputError(f"{who}: profile_options must be a dict of the {kind} profile's options")
    options = dict(options or {})
    seed = options.pop("seed", None)
    _, v = velocity_profile(kind, top_speed=float(top_speed), duration=float(duration), fs=fs, seed=seed, **options)
    return Reference(kind, float(top_speed), (len(v) - 1) / fs, float(fs), options, seed, v)


def tracking(v: np.ndarray, v_ref: np.ndarray) -> dict:
    """How a measured or simulated velocity ``v`` followed ``v_ref`` (same samples, rad/s):
    ``velocity_max`` (largest |v|), ``tracking_rms`` and ``tracking_max`` of ``v - v_ref``."""
    e = np.asarray(v, float) - np.asarray(v_ref, float)
    return {"velocity_max": float(np.max(np.abs(v))), "tracking_rms": float(np.sqrt(np.mean(e * e))),
            "tracking_max": float(np.max(np.abs(e)))}
