"""A fitted model's errors on plateaus from the segments' normal equations, not from its predictions
at every sample.

On a plateau (a segment at one velocity) a model of :mod:`gearspec.identify` predicts its level at
that speed plus its lines, ``A_k g_k(|v|) sin(2 pi f_k theta + phi_k)``: a linear combination
``X_s beta_s`` of the columns ``[1, sin_k, cos_k]`` whose normal equations the fit has already
reduced (:class:`~.stats.SegmentStats`, cached on the data).  So the segment's residual sum of
squares is ``y'y - 2 beta'X'y + beta'X'X beta`` (:func:`gearspec.core.reduction.normal_equations`)
and the sum of its predictions ``X'1 . beta``: a few numbers per segment instead of an evaluation
of the model at every sample (10^7 rows: about 1 s of CPU per model and use).  The numbers are the
same to rounding (the sums are taken in another order: about 1e-13 relative), and each segment
whose sum would lose digits to cancellation (a residual below :data:`CANCEL` of the torque's sum of
squares), or where a line lies above the position-Nyquist limit (its columns are not in the
statistics), or whose model has terms the statistics do not hold (inertia, load, terms) is
evaluated sample by sample as before.

:func:`layout` says whether data can be scored so (plateaus in segment order, one velocity and one
direction per segment, finite torque); :func:`segment_sums` scores a model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import LAWS
from ..terms.shapes import amplitude_law, clamp_speed

__all__ = ["Layout", "layout", "Sums", "segment_sums", "predict_rows", "check_finite", "Fallback", "CANCEL"]

#: a segment whose residual sum of squares (or, for its mean error, whose sum of squared deviations
#: about that mean) is below this fraction of the torque's sum of squares, the sum it is the
#: difference of, is evaluated sample by sample: the difference's rounding is about 1e-15 of that
#: sum (measured: 11 x 1.1e-16), so it keeps 1e-10 relative or better above it
CANCEL = 1e-5


@dataclass
class Layout:
    """The segments of plateau data as the scores read them: ``starts``/``stops`` (S,) their rows
    (the data are in segment order), ``n`` (S,), ``v`` and ``direction`` (S,) each segment's velocity
    and direction, ``ids`` (S,) its segment id; ``row_segment`` (N,) the segment index of every row
    (made when first asked)."""

    ids: np.ndarray
    starts: np.ndarray
    stops: np.ndarray
    v: np.ndarray
    direction: np.ndarray

    @property
    def n(self) -> np.ndarray:
        return self.stops - self.starts

    def row_segment(self) -> np.ndarray:
        r = self.__dict__.get("_row_segment")
        if r is None:
            r = self._row_segment = np.repeat(np.arange(len(self.ids)), self.n)
        return r


def layout(data) -> Layout | None:
    """The :class:`Layout` of ``data`` when its models can be scored from the segments' normal
    equations, else None: data without free motion, rows in ascending segment order (as
    :meth:`FitData.from_recording` writes them), one velocity and one direction in every segment,
    every torque finite.  Computed once per data (one pass over the rows)."""
    d = data.__dict__
    if "_score_layout" not in d:
        d["_score_layout"] = _make_layout(data)
    return d["_score_layout"]


def _make_layout(data) -> Layout | None:
    if len(data) == 0 or data.free_motion:
        return None
    order, ids, bounds = data.segment_groups()      # (FitData's layout: order None when in segment order)
    if order is not None:
        return None
    starts, stops = bounds[:-1], bounds[1:]
    dirs = data._layout()[2]
    v = data.v
    if not (dirs is not None and np.array_equal(np.minimum.reduceat(v, starts), np.maximum.reduceat(v, starts))
            and bool(np.all(np.isfinite(data.y))) and bool(np.all(np.isfinite(v[starts])))):
        return None
    return Layout(ids, starts, stops, v[starts].astype(float), dirs.astype(int))


class Fallback(Exception):
    """The per-segment scores cannot stand for the samples' (a non-finite sum): score by samples."""


@dataclass
class Sums:
    """Per segment (of the selection): ``sse`` the residual sum of squares, ``pred`` the sum of the
    predicted friction magnitudes, ``y`` the sum of the measured ones (``direction x y``), ``yy``
    the sum of their squares, ``ok`` whether the model predicts the segment's direction (NaN in the
    others where not)."""

    sse: np.ndarray
    pred: np.ndarray
    y: np.ndarray
    yy: np.ndarray
    ok: np.ndarray


def segment_sums(model, data, select=None, *, check: bool = True) -> Sums | None:
    """The :class:`Sums` of ``model`` on the segments ``select`` of ``data`` (indices or a mask over
    :func:`layout`'s segments; default all): the residual sum of squares of
    ``data.y - model.evaluate(**data.inputs())`` over each segment's rows and the sums of the
    predicted and measured friction magnitudes, from the segments' normal equations (module
    docstring).  A segment of a direction the model cannot predict is NaN, or with ``check`` the
    :class:`InputError` that :meth:`FrictionModel.evaluate` raises on those rows is raised.  None
    when the data or the model cannot be scored so (free motion, a model with terms or with a law
    or line that reads the load): score by samples then."""
    lay = layout(data)
    if lay is None or model.terms or LAWS[model.law].needs_load:
        return None
    comp = model._compiled()
    if any(c.lines is not None and c.lines.needs_load for _, c in comp.directions):
        return None
    if data.theta is None and any(c.lines is not None for _, c in comp.directions):
        return None
    sel = np.arange(len(lay.ids)) if select is None else np.asarray(select)
    if sel.dtype == bool:
        sel = np.flatnonzero(sel)
    if check:
        comp.check(np.zeros(1) if data.theta is not None else None, lay.v[sel], None)
    freqs = []      # in the order the model gives its lines (the fit's: its statistics are cached so)
    for _, c in comp.directions:
        if c.lines is not None and c.error is None:
            freqs += [f for f in (float(h["frequency"]) for h in c.lines.given) if f not in freqs]
    from .stats import segment_stats

    stats = _stats(data, freqs, segment_stats)
    if not np.array_equal(stats.segment, lay.ids):
        return None
    out = Sums(*(np.full(len(sel), np.nan) for _ in range(4)), np.zeros(len(sel), bool))
    by_rows = []
    for d, c in comp.directions:
        at = np.flatnonzero(lay.direction[sel] == d)
        if not len(at) or c.error is not None:
            continue
        js = sel[at]
        beta, unsampled = _coefficients(c, np.abs(lay.v[js]), stats, js)
        G, g, yy = stats.G[js], stats.b[js], stats.yy[js]
        sse = yy - 2.0 * np.einsum("sp,sp->s", beta, g) + np.einsum("sp,spq,sq->s", beta, G, beta)
        out.sse[at], out.pred[at], out.y[at], out.yy[at] = sse, np.einsum("sp,sp->s", G[:, 0, :], beta), g[:, 0], yy
        out.ok[at] = True
        by_rows += at[unsampled | ~(sse > CANCEL * yy)].tolist()
    for i in by_rows:
        out.sse[i], out.pred[i], out.y[i] = _by_rows(model, data, lay, sel[i])
    return out


def _stats(data, freqs, segment_stats):
    """The segments' statistics at ``freqs`` (the model's lines): :func:`~.stats.segment_stats`,
    whose per-segment numbers are cached on ``data`` (and checked against the segment's rows), so
    that after the fits this reads them."""
    return segment_stats(data, freqs)


def _coefficients(c, speed, stats, js):
    """``beta`` (len(js), P): the coefficients of the statistics' columns ``[1, sin_k, cos_k]`` that
    give direction ``c``'s friction magnitude at the segments ``js`` (speeds ``speed``), as
    :class:`~gearspec.terms.lines.Lines` computes it; ``unsampled`` (len(js),) bool: a line of
    nonzero amplitude lies where the statistics hold no columns for it (score by samples)."""
    P = stats.G.shape[1]
    beta = np.zeros((len(js), P))
    beta[:, 0] = c.law.magnitude(speed, None, *c.params)
    unsampled = np.zeros(len(js), bool)
    lines = c.lines
    if lines is None:
        return beta, unsampled
    col = {f: k for k, f in enumerate(stats.frequencies.tolist())}
    for rows, law, rng, _with_load, amp, decay, _coef in lines.groups:
        fac = amp * amplitude_law(law, clamp_speed(speed, rng)[None, :], decay) if law != "const" else \
            np.broadcast_to(amp, (len(amp), len(speed)))
        for r, f in zip(range(rows.start, rows.stop), fac):
            k = col[float(lines.frequency[r, 0])]
            phase = float(lines.phase[r, 0])
            beta[:, 1 + 2 * k] += f * np.cos(phase)
            beta[:, 2 + 2 * k] += f * np.sin(phase)
            unsampled |= ~stats.sampled[js, k] & (f != 0)
    return beta, unsampled


def _by_rows(model, data, lay, j):
    """``(sse, pred, y)`` of segment ``j`` (:class:`Sums`) from the model's predictions at its samples."""
    a, b = int(lay.starts[j]), int(lay.stops[j])
    pred = predict_rows(model, data, a, b)
    y = data.y[a:b]
    r = y - pred
    d = lay.direction[j]
    return float(r @ r), float(d * pred.sum()), float(d * y.sum())


def predict_rows(model, data, a: int, b: int) -> np.ndarray:
    """``model.evaluate`` at the rows ``a:b`` of ``data`` (their inputs sliced, not gathered)."""
    return model.evaluate(**{k: (None if x is None else x[a:b]) for k, x in data.inputs().items()})


def check_finite(sse) -> np.ndarray:
    """``sse`` when every value is finite, else :class:`Fallback`."""
    if not np.all(np.isfinite(sse)):
        raise Fallback
    return sse

