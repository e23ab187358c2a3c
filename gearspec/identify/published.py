"""The SILO4 identification procedure as published (SILO4 section 3-4), kept as published so that
its bias beside the joint fit (:mod:`.joint`) can be shown.

:func:`silo4_published`: Coulomb and viscous friction from a straight line through the plateau
averages above ``high_speed`` (100 rpm), static friction and Stribeck velocity from the log-linear
fit of eqs. 4-5 on the plateaus below it (viscous term neglected), and per stage and direction the
amplitude and decay constant from the log-linear fit of eq. 10 to the amplitudes of the spectra
(``constant`` stages, the paper's F1, keep a constant amplitude, eq. 6), phases from the spectra
(circular mean).  The amplitudes of the lines per segment: :func:`line_amplitudes` (least squares
on the segment's samples) or :func:`amplitudes_from_spectrum`.

Units: speeds rad/s (m/s), friction and amplitudes Nm (N), phases rad, decays s/rad (s/m).
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np
import pandas as pd

from ..fitdata import FitData
from ..model import LAWS, RPM, Direction, FrictionModel, Harmonic
from . import validate
from .stats import harmonic_specs, pair_se, segment_stats
from .validate import _safe_rmse

__all__ = ["silo4_published", "line_amplitudes", "amplitudes_from_spectrum"]

#: the columns of a table of per-segment line amplitudes
_AMP_COLUMNS = ["segment", "direction", "speed", "label", "frequency", "amplitude", "amplitude_se", "phase"]


def line_amplitudes(data: FitData, harmonics, *, min_cycles: float = 1.0) -> pd.DataFrame:
    """Amplitude, phase and standard error of each line in each segment where it completes
    ``min_cycles`` cycles: the joint least-squares fit of the lines and a constant on the segment's
    own samples (what the spectra of :mod:`gearspec.spectrum` measure at declared lines, with white-
    noise errors).  One row per (segment, line)."""
    specs = harmonic_specs(harmonics)
    rows = []
    for d in (1, -1):
        sub = data.direction_subset(d)
        if len(sub) == 0 or not specs:
            continue
        st = segment_stats(sub, [h["frequency"] for h in specs], min_cycles=min_cycles)
        for i, sid in enumerate(st.segment):
            try:
                cov = np.linalg.pinv(st.G[i], rcond=1e-12, hermitian=True) * (st.sigma2[i] if np.isfinite(st.sigma2[i])
                                                                               else np.nan)
            except np.linalg.LinAlgError:
                cov = np.full(st.G[i].shape, np.nan)
            for k, h in enumerate(specs):
                if not st.active[i, k]:
                    continue
                ia, ic = 1 + 2 * k, 2 + 2 * k
                a_, c_ = st.beta_hat[i, ia], st.beta_hat[i, ic]
                rows.append({"segment": int(sid), "direction": d, "speed": float(st.speed[i]),
                             "label": h.get("label"), "frequency": h["frequency"], "amplitude": math.hypot(a_, c_),
                             "amplitude_se": pair_se(a_, c_, cov[np.ix_([ia, ic], [ia, ic])])[0],
                             "phase": math.atan2(c_, a_)})
    return pd.DataFrame(rows, columns=_AMP_COLUMNS)


def amplitudes_from_spectrum(spectrum, data: FitData, harmonics=None) -> pd.DataFrame:
    """The declared-line peaks of a :class:`~gearspec.spectrum.SpectrumResult` in the form of
    :func:`line_amplitudes`, matched to ``data``'s segments (same segmentation)."""
    specs = harmonic_specs(harmonics, spectrum.gear) if harmonics is None else harmonic_specs(harmonics)
    rows = []
    for s in spectrum.segments:
        sid = _segment_id(data.segments, s)
        if sid is None:
            continue
        for h in specs:
            p = s.peak(h["label"]) if h.get("label") else None
            if p is not None and p.amplitude > 0:
                rows.append({"segment": sid, "direction": s.direction, "speed": s.speed, "label": h["label"],
                             "frequency": h["frequency"], "amplitude": p.amplitude, "amplitude_se": p.amplitude_se,
                             "phase": p.phase})
    return pd.DataFrame(rows, columns=_AMP_COLUMNS)


def silo4_published(data: FitData, amplitudes=None, *, harmonics=None, gear=None, high_speed: float = 100 * RPM,
                    constant: Iterable[str] = ("output shaft",), min_cycles: float = 1.0,
                    holdout: str | None = "segment", folds: int = 5) -> FrictionModel:
    """The SILO4 identification procedure as published (section 3-4; see the module docstring).

    ``data``: samples in segments (the plateau averages come from it).  ``amplitudes``: per-segment
    amplitudes and phases of the lines (:func:`line_amplitudes`, or the spectra of
    :func:`gearspec.spectrum.analyze` on the same segmentation; default: measured from ``data`` at
    the lines of ``harmonics``/``gear``, :func:`harmonic_specs`; none: eq. 3 only).  ``high_speed``:
    plateaus above it give Coulomb and viscous friction (the paper: 100 rpm; rad/s here), the others
    static friction and Stribeck velocity.  ``constant``: labels of lines with a constant amplitude
    (eq. 6): the paper's F1, one joint turn.
    """
    specs = harmonic_specs(harmonics, gear)
    if amplitudes is None:
        amplitudes = line_amplitudes(data, specs, min_cycles=min_cycles)
    elif not isinstance(amplitudes, pd.DataFrame):
        if not specs and amplitudes.gear is not None:
            specs = harmonic_specs(None, amplitudes.gear)
        amplitudes = amplitudes_from_spectrum(amplitudes, data, specs)
    model = _published(data, amplitudes, specs, high_speed, set(constant))
    if holdout:
        def fit_fold(train):  # the plateaus and line amplitudes of the training segments only
            amp = amplitudes[amplitudes["segment"].isin(train.segment_groups()[1])]
            return _published(train, amp, specs, high_speed, set(constant), rmse=False)

        model.rmse_holdout, model.rmse_holdout_reason = validate.holdout(fit_fold, data, by=holdout, folds=folds)
    return model


def _published(data: FitData, amplitudes: pd.DataFrame, specs, high_speed, constant,
               rmse: bool = True) -> FrictionModel:
    """The published procedure on ``data``; ``rmse``: compute its in-sample rmse (a held-out
    fold's model is only asked for predictions)."""
    plate = data.plateaus()
    directions, ni, notes = {}, {}, []
    for d, dname in ((1, "positive"), (-1, "negative")):
        pl = plate[plate["direction"] == d]
        P = Direction.of(LAWS["silo4"], {})
        if pl.empty:
            for k in ("tau_c", "tau_s", "v_s", "viscous"):
                ni[f"{dname}.{k}"] = f"no segment in the {dname} direction"
            directions[dname] = P
            continue
        hi = pl[pl["speed"] > high_speed]
        lo = pl[pl["speed"] <= high_speed]
        if len(hi) >= 2:
            coef, se = _line(hi["speed"], hi["level"].to_numpy())
            P.set("tau_c", float(coef[0]), float(se[0]))
            P.set("viscous", float(coef[1]), float(se[1]))
        else:
            where = (f"above {high_speed:.4g} {data.unit}/s" if data.unit == "rad" else
                     f"above {high_speed:.4g} {data.unit}/s (the paper's split at 100 rpm is a speed of a rotary "
                     f"shaft, read here as {data.unit}/s: the procedure does not carry over to a linear axis)")
            ni[f"{dname}.tau_c"] = ni[f"{dname}.viscous"] = (f"needs two plateaus {where} in the {dname} direction, "
                                                               f"has {len(hi)}")
        if P.values["tau_c"] is not None:
            excess = lo["level"].to_numpy() - P.values["tau_c"]
            ok = excess > 0
            if ok.sum() >= 2:
                coef, se = _line(lo["speed"].to_numpy()[ok], np.log(excess[ok]))
                m_, n_ = coef[1], coef[0]
                if m_ < 0:
                    P.set("v_s", float(-1.0 / m_), float(se[1] / m_ ** 2))
                    P.set("tau_s", float(P.values["tau_c"] + math.exp(n_)), float(math.exp(n_) * se[0]))
                    if ok.sum() < len(lo):
                        notes.append(f"{dname}: {len(lo) - ok.sum()} low-speed plateau(s) below the Coulomb level "
                                     f"left out of the log-linear fit (eq. 4 cannot take their log)")
                else:
                    ni[f"{dname}.v_s"] = ni[f"{dname}.tau_s"] = "the low-speed plateaus do not fall with speed"
            else:
                ni[f"{dname}.v_s"] = ni[f"{dname}.tau_s"] = (f"needs two plateaus below {high_speed:.4g} "
                                                             f"{data.unit}/s above the Coulomb level, has {ok.sum()}")
        # amplitudes and decays from the per-segment line fits (eq. 10), phases by circular mean
        for h in specs:
            lab = h.get("label")
            rows = amplitudes[(amplitudes["direction"] == d) & np.isclose(amplitudes["frequency"], h["frequency"])]
            rows = rows[rows["amplitude"] > 0]
            key = f"{dname}.{lab or h['frequency']}"
            if rows.empty:
                ni[key] = "not fitted in any segment (too few cycles)"
                continue
            sp, amp, ph = rows["speed"].to_numpy(), rows["amplitude"].to_numpy(), rows["phase"].to_numpy()
            phase = float(np.angle(np.sum(amp * np.exp(1j * ph))))
            # the amplitude law holds over the speeds of the segments that measured the line
            entry = {"frequency": h["frequency"], "phase": phase,
                     "speed_range": [float(np.min(sp)), float(np.max(sp))]}
            if lab:
                entry["label"] = lab
            if lab in constant or len(np.unique(np.round(sp, 9))) < 2:
                entry.update(amplitude=float(np.mean(amp)), decay=0.0, decay_se=0.0, law="const",
                             amplitude_se=float(np.std(amp, ddof=1) / math.sqrt(len(amp))) if len(amp) > 1
                             else float("nan"))
                if lab not in constant:
                    ni[key + ".decay"] = "the line is measured at one speed only"
            else:
                coef, se = _line(sp, np.log(amp))
                entry.update(amplitude=float(math.exp(coef[0])), amplitude_se=float(math.exp(coef[0]) * se[0]),
                             decay=float(-coef[1]), decay_se=float(se[1]))
            P.harmonics.append(Harmonic.of(entry))
        directions[dname] = P
    model = FrictionModel("silo4", directions["positive"], directions["negative"], unit=data.unit,
                          not_identified=ni, notes=notes, name="SILO4 published procedure",
                          meta={"procedure": "published", "high_speed": high_speed})
    if rmse:
        model.rmse = _safe_rmse(model, data)
    return model


def _segment_id(segments: pd.DataFrame, seg_spectrum) -> int | None:
    s = seg_spectrum.segment
    m = segments[(segments["run"] == s.run) & (segments["direction"] == s.direction)
                 & (np.isclose(segments["speed"], s.speed))]
    return int(m["segment"].iloc[0]) if len(m) else None


def _line(x, y):
    """Least-squares line ``y = coef[0] + coef[1] x``: ``(coef, se)``, se NaN without degrees of freedom."""
    X = np.column_stack([np.ones(len(y)), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    if len(y) <= 2:
        return coef, np.full(2, np.nan)
    r = y - X @ coef
    try:
        cov = np.linalg.inv(X.T @ X) * (float(r @ r) / (len(y) - 2))
    except np.linalg.LinAlgError:
        return coef, np.full(2, np.nan)
    return coef, np.sqrt(np.clip(np.diag(cov), 0, None))
