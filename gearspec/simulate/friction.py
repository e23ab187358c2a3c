"""The friction inside the SILO4 twin's closed loop: the same numbers as
:meth:`FrictionModel.evaluate <gearspec.model.FrictionModel.evaluate>`, for every run at one
instant (thousands of calls per simulated second), history terms carried along the motion.
"""

from __future__ import annotations

import numpy as np

from .. import laws
from ..errors import InputError
from ..model import FrictionModel
from ..terms import TERMS, evaluate_term


_HISTORY = ("hysteresis", "backlash")


class _Pointwise:
    """Evaluation of a model without signed or history terms, fast for small vectors: the base law
    of both directions on every sample then a select, and the exponential-decay harmonics in one
    broadcast :func:`gearspec.laws.meshing_ripple` call (other harmonics through the ``periodic`` term)."""

    def __init__(self, model: FrictionModel):
        self.law = model.law_spec
        params, fast, self.slow = [], [], []
        for name in ("positive", "negative"):
            p = model.directions[name]
            missing = [k for k in self.law.params if p.values.get(k) is None]
            if missing:
                raise InputError(f"the truth model has no {name}-direction value for {', '.join(missing)}")
            params.append([float(p.values[k]) for k in self.law.params])
            hs = [h for h in p.harmonics if h.amplitude is not None]
            fast.append([h for h in hs if h.amplitude_law == "exp" and not h.load_coefficient])
            self.slow.append([h for h in hs if not (h.amplitude_law == "exp" and not h.load_coefficient)])
        # parameters of both directions stacked along a first axis of length 2
        self.params = [np.array(col)[:, None] for col in zip(*params)] if params[0] else []
        n_h = max(len(f) for f in fast)
        self.harm = None
        if n_h:
            # (direction, harmonic, 1) arrays; padding harmonics have zero amplitude
            self.harm = tuple(np.array([[[getattr(h, key)] for h in f] + [[0.0]] * (n_h - len(f)) for f in fast],
                                       dtype=float) for key in ("amplitude", "decay", "frequency", "phase"))
        self.terms = list(model.terms)

    def __call__(self, theta, v, *, load=None, temperature=None, t=None, run=None):
        speed = np.abs(v)
        sign = np.sign(v)
        ld = None if load is None else load[None, :]
        m = np.asarray(self.law.magnitude(speed[None, :], ld, *self.params), dtype=float)
        if self.harm is not None:
            m = m + laws.meshing_ripple(theta[None, None, :], v[None, None, :], *self.harm).sum(axis=1)
        mag = np.where(sign > 0, m[0], m[-1]) if m.ndim == 2 else np.broadcast_to(m, speed.shape)
        for d, hs in ((1.0, self.slow[0]), (-1.0, self.slow[1])):
            for h in hs:
                mag = mag + (sign == d) * evaluate_term(h.term(), theta=theta, v=v, load=load)[0]
        for term in self.terms:
            mag = mag + evaluate_term(term, theta=theta, v=v, load=load, temperature=temperature, t=t, acc=None,
                                      run=run)[0]
        return sign * mag


class _LoopFriction:
    """A truth model split for step-by-step use in a closed loop: pointwise friction (base law,
    harmonics, magnitude terms, :class:`_Pointwise`), signed terms (cogging, offset) as external
    torques, inertia terms added to the rotor inertia, and history terms (hysteresis, backlash)
    evaluated on two-sample sequences ``[turning point, now]`` per run, the turning point kept as
    state -- the same numbers as evaluating the whole trajectory at once."""

    def __init__(self, model: FrictionModel):
        self.model = model
        pointwise = model.copy()
        pointwise.terms = [t for t in model.terms if not TERMS[t["kind"]].signed and t["kind"] not in _HISTORY]
        self.pointwise = _Pointwise(pointwise)
        self.signed = [t for t in model.terms if TERMS[t["kind"]].signed and t["kind"] != "inertia"]
        self.history = [t for t in model.terms if t["kind"] in _HISTORY]
        self.extra_inertia = float(sum(t["inertia"] for t in model.terms if t["kind"] == "inertia"))

    def external(self, theta, v, **kw):
        return sum((evaluate_term(term, theta=theta, v=v, **kw)[0] for term in self.signed), 0.0)

    def friction(self, theta, v, turn_theta, last_sign, prev_theta=None, **kw):
        """Signed friction at (theta, v); ``turn_theta``/``last_sign`` per run: the turning point of
        the last reversal (NaN: none yet) and the last nonzero direction of motion; ``prev_theta``:
        the position one step before (the turning point if the motion reverses now; default
        theta, as in the twin, where a reversing motor always stops for a step first)."""
        f = self.pointwise(theta, v, **kw)
        if self.history:
            s = np.sign(v)
            now_rev = (s != 0) & (last_sign != 0) & (s != last_sign)
            have = now_rev | np.isfinite(turn_theta)
            if have.any():
                idx = np.flatnonzero(have)
                tt = np.where(now_rev, theta if prev_theta is None else prev_theta, turn_theta)[idx]
                # sample 0: the turning point, moving the old way; sample 1: now
                old = np.where(now_rev, last_sign, -s)[idx]
                th2 = np.column_stack((tt, theta[idx])).ravel()
                v2 = np.column_stack((old, s[idx])).ravel()
                run2 = np.repeat(np.arange(len(idx)), 2)
                extra = np.zeros(len(idx))
                for term in self.history:
                    extra += evaluate_term(term, theta=th2, v=v2, run=run2)[0][1::2]
                f = f.copy()
                f[idx] += s[idx] * extra
        return f
