"""Position-locked lines evaluated together, and a model's base law with its lines compiled for fast
evaluation (what :meth:`FrictionModel.evaluate <gearspec.model.FrictionModel.evaluate>` and the
registry's ``periodic`` term compute).

A line (SILO4 eqs. 6, 8 and 14) is ``(A + k load^2) g(|v|) sin(2 pi f theta + phi)`` with ``g`` an
amplitude law of :mod:`.shapes` evaluated at ``|v|`` held within the line's ``speed_range``.
:class:`Lines` holds K lines as parameter arrays and evaluates them in a few array operations,
whatever K; :class:`CompiledFriction` holds both directions of a model and evaluates the signed
friction ``sign(v) [base(|v|, load) + sum_k line_k]`` in blocks of samples, each direction on its own
samples.  Units: SI (rad, rad/s, Nm; frequencies in cycles per unit of theta, decays in s/rad).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .shapes import AMPLITUDE_LAWS, amplitude_law, clamp_speed, load_amplitude, sinusoid

__all__ = ["Lines", "CompiledDirection", "CompiledFriction"]

#: samples per block times lines: arrays of a block stay in the processor's cache, and the Python
#: work per block (some 40 numpy calls) is spread over enough samples to cost < 5 % of the numpy work
_BLOCK = 65536
#: group name of the lines with the exp law and decay 0 (SILO4 eq. 6 written as eq. 8, Table 2's first line)
_EXP0 = "exp, decay 0"


class Lines:
    """K position-locked lines, each given in the ``periodic`` term's form: ``frequency``,
    ``amplitude``, ``decay`` (default 0), ``phase`` (default 0), ``law`` (default ``"exp"``),
    ``load_coefficient`` (default 0), ``speed_range`` (default None: not clamped).

    The lines are stored grouped by (law, speed range, load coefficient or not), so that each group
    is one slice of the parameter arrays; :meth:`__call__` returns them in the order given.
    """

    def __init__(self, lines: Sequence[Mapping]):
        keyed = []
        for i, h in enumerate(lines):
            for name in ("frequency", "amplitude", "decay", "phase"):
                if name in h and h[name] is None:
                    raise InputError(f"a position-locked line has no value for its {name} (null in the model)")
            law = h.get("law") or "exp"
            if law not in AMPLITUDE_LAWS:
                raise InputError(f"unknown amplitude law '{law}' ({', '.join(AMPLITUDE_LAWS)})")
            rng = h.get("speed_range")
            rng = None if not rng else tuple(rng)
            k = h.get("load_coefficient", 0.0) or 0.0
            if law == "exp" and h.get("decay", 0.0) == 0.0:
                law = _EXP0
            keyed.append(((law, rng, bool(k)), i, h, k))
        keyed.sort(key=lambda x: (x[0][0], repr(x[0][1]), x[0][2], x[1]))
        self.n = len(keyed)
        col = lambda vals: np.array(vals, dtype=float)[:, None]  # noqa: E731
        self.frequency = col([h["frequency"] for _, _, h, _ in keyed])
        self.amplitude = col([h["amplitude"] for _, _, h, _ in keyed])
        self.decay = col([h.get("decay", 0.0) for _, _, h, _ in keyed])
        self.phase = col([h.get("phase", 0.0) for _, _, h, _ in keyed])
        self.load_coefficient = col([k for _, _, _, k in keyed])
        #: row of each line in the order given
        self.order = [row for row, _ in sorted(enumerate(x[1] for x in keyed), key=lambda r: r[1])]
        #: (start, stop, law, speed range, with load) of each group of rows
        self.groups = []
        for row, (key, *_rest) in enumerate(keyed):
            if self.groups and tuple(self.groups[-1][2:]) == key:
                self.groups[-1][1] = row + 1
            else:
                self.groups.append([row, row + 1, *key])
        self.needs_load = any(g[4] for g in self.groups)

    def __call__(self, theta, speed, load=None) -> np.ndarray:
        """The lines at samples: ``theta`` (rad or m) and ``speed = |v|`` (rad/s or m/s), 1-D arrays of
        one length n, ``load`` (Nm) as well when a line has a load coefficient.  Returns (K, n) in
        the internal row order (rows of the lines as given: :attr:`order`)."""
        out = sinusoid(theta[None, :], self.frequency, self.phase)
        clamped = {}
        for a, b, law, rng, with_load in self.groups:
            if with_load:
                if load is None:
                    raise InputError("a periodic term with a load coefficient (SILO4 eq. 14) needs the 'load' channel")
                amp = load_amplitude(load[None, :], self.amplitude[a:b], self.load_coefficient[a:b])
            else:
                amp = self.amplitude[a:b]
            if law == "const":    # g = 1, and A * 1 * s is A * s exactly
                out[a:b] *= amp
                continue
            if rng not in clamped:
                clamped[rng] = clamp_speed(speed, rng)[None, :]
            s = clamped[rng]
            if law == _EXP0 and (s.size == 0 or math.isfinite(s.max())):
                out[a:b] *= amp   # exp(-0 |v|) = 1 exactly at every finite speed (NaN or inf: as exp gives)
                continue
            amp = amp * amplitude_law("exp" if law == _EXP0 else law, s, self.decay[a:b])
            out[a:b] *= amp
        return out


class CompiledDirection:
    """One direction of a model ready to evaluate: its base law with the parameter values ``params``
    (in the law's order) and its lines (:class:`Lines`, or None).  ``error``: why the direction cannot
    be evaluated (a parameter not identified, an unknown amplitude law), raised when samples move
    that way."""

    def __init__(self, law, params: Sequence, lines: Sequence[Mapping], error: str | None = None):
        self.law, self.params, self.error, self.lines = law, list(params), error, None
        if lines and error is None:
            try:
                self.lines = Lines(lines)
            except InputError as exc:
                self.error = str(exc)

    def magnitude(self, theta, speed, load) -> np.ndarray:
        """Friction magnitude ``base(|v|, load) + sum_k line_k`` at the samples (1-D arrays), the lines
        added one after the other in their order; may be a scalar or one of the inputs (read only)."""
        mag = self.law.magnitude(speed, load, *self.params)
        if self.lines is not None:
            rows = self.lines(theta, speed, load)
            order = self.lines.order
            mag = np.add(mag, rows[order[0]])     # a new array, summed into
            for r in order[1:]:
                mag += rows[r]
        return mag


class CompiledFriction:
    """Both directions of a model (:class:`CompiledDirection` ``positive`` and ``negative``):
    :meth:`__call__` gives the signed friction of the base law and lines."""

    def __init__(self, positive: CompiledDirection, negative: CompiledDirection):
        self.directions = ((1.0, positive), (-1.0, negative))
        self.block = _BLOCK // max(1, positive.lines.n if positive.lines else 1,
                                   negative.lines.n if negative.lines else 1)

    def check(self, theta, v, load) -> None:
        """InputError when samples move in a direction that cannot be evaluated with these inputs."""
        for d, c in self.directions:
            needs_theta = c.lines is not None and theta is None
            needs_load = c.lines is not None and c.lines.needs_load and load is None
            if (c.error or needs_theta or needs_load) and np.any(v * d > 0):
                if c.error:
                    raise InputError(c.error)
                if needs_theta:
                    raise InputError("the model has position-locked harmonics and needs theta")
                raise InputError("a periodic term with a load coefficient (SILO4 eq. 14) needs the 'load' channel")

    def __call__(self, theta, v, load=None) -> np.ndarray:
        """``sign(v) * magnitude`` at 1-D samples ``theta`` (None when no line needs it), ``v``, ``load``
        (None when not needed); 0 where v is 0 or NaN.  Blocks of samples; in each, the samples of
        each direction gathered (all of them without a copy when the block moves one way)."""
        self.check(theta, v, load)
        n = len(v)
        out = np.zeros(n)
        for i in range(0, n, self.block):
            j = min(n, i + self.block)
            vb, tb, lb = v[i:j], None if theta is None else theta[i:j], None if load is None else load[i:j]
            ob = out[i:j]
            for d, c in self.directions:
                sel = vb > 0 if d > 0 else vb < 0
                cnt = int(np.count_nonzero(sel))
                if cnt == j - i:
                    mag = c.magnitude(tb, np.abs(vb), lb)
                    ob[...] = mag if d > 0 else np.negative(mag)
                elif cnt:
                    idx = np.flatnonzero(sel)
                    mag = c.magnitude(None if tb is None else tb.take(idx), np.abs(vb.take(idx)),
                                      None if lb is None else lb.take(idx))
                    ob[idx] = mag if d > 0 else np.negative(mag)
        return out
