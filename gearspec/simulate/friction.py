"""The friction inside the SILO4 twin's closed loop: :meth:`FrictionModel.evaluate
<gearspec.model.FrictionModel.evaluate>` for every run at one instant (thousands of calls per
simulated second; the model keeps its law and lines compiled between calls), history terms carried
along the motion.
"""

from __future__ import annotations

import numpy as np

from ..model import FrictionModel
from ..terms import TERMS, evaluate_term


_HISTORY = ("hysteresis", "backlash")


class _LoopFriction:
    """A truth model split for step-by-step use in a closed loop: pointwise friction (base law,
    harmonics, magnitude terms: the model without its other terms, evaluated), signed terms
    (cogging, offset) as external torques, inertia terms added to the rotor inertia, and history
    terms (hysteresis, backlash) evaluated on two-sample sequences ``[turning point, now]`` per
    run, the turning point kept as state -- the same numbers as evaluating the whole trajectory at
    once."""

    def __init__(self, model: FrictionModel):
        self.model = model
        pointwise = model.copy()
        pointwise.terms = [t for t in model.terms if not TERMS[t["kind"]].signed and t["kind"] not in _HISTORY]
        self.pointwise = pointwise.evaluator()    # a private copy, never changed: compiled once
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
