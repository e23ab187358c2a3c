"""The exclusion ledger (NaN or inf, backward and repeated time stamps, saturation; each row counted
under its reason: ``n_read == len(data) + sum(excluded.values())``) and unwrapping of positions."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pandas as pd

from ..errors import InputError, warn
from .record import _run_rows

__all__ = ["CLOCK_BURST_FRACTION"]

#: rows repeating a time stamp (and not copies of their predecessor) in at least this fraction of a
#: run's rows are read as a coarse logger clock and spread; rarer ones are isolated and excluded
CLOCK_BURST_FRACTION = 0.01


def _clean_rows(path, frame: pd.DataFrame, sig: str, unit: str, excluded: Counter, notes: list[str],
                max_bad_fraction: float) -> pd.DataFrame:
    """The rows of one file that can be analysed (exclusions counted in ``excluded``), theta unwrapped."""
    frame = _exclude_nonfinite(path, frame, sig, excluded, max_bad_fraction)
    frame = _clean_times(path, frame, sig, excluded, notes, max_bad_fraction)
    frame, n_sat = _exclude_saturation(path, frame, sig)
    if n_sat:
        excluded["saturation"] += n_sat
    return _unwrap_theta(path, frame, unit, notes)


def _exclude_nonfinite(path, frame: pd.DataFrame, sig: str, excluded: Counter,
                       max_bad_fraction: float) -> pd.DataFrame:
    """Rows with NaN or inf in the columns the analysis needs (``t``, ``theta``, ``sig``) excluded;
    a column with more than ``max_bad_fraction`` of them is refused."""
    need = ["t", "theta", sig]
    finite = np.ones(len(frame), bool)
    for col in need:
        v = frame[col].to_numpy()
        fin = np.isfinite(v)
        if not fin.any():
            raise InputError(f"{path}: column '{col}' holds no finite number")
        frac = 1 - fin.mean()
        if frac > max_bad_fraction:
            raise InputError(f"{path}: column '{col}' is NaN or inf in {frac:.0%} of rows "
                             f"(first at data row {int(np.flatnonzero(~fin)[0]) + 1}); too many to exclude")
        finite &= fin
    n_bad = int((~finite).sum())
    if n_bad:
        excluded["nan_or_inf"] += n_bad
        warn(f"{path}: {n_bad} rows with NaN or inf in {', '.join(need)} excluded")
        frame = frame.loc[finite]
    return frame


def _clean_times(path, frame: pd.DataFrame, sig: str, excluded: Counter, notes: list[str],
                 max_bad_fraction: float) -> pd.DataFrame:
    """Backward and repeated time stamps, per run.  A row stamped below the running maximum is
    excluded (``non_increasing_time``; more than ``max_bad_fraction`` of them, likely several
    experiments without a ``run`` column, is refused); a copy of the previous row (stamp, position
    and signal) is excluded (``duplicate_time``).  Other repeats come from a logger clock coarser than
    its rate: if systematic (at least ``CLOCK_BURST_FRACTION`` of the rows), each burst is spread
    evenly towards the next stamp (at most the typical period), with a note; if isolated, excluded
    (``duplicate_time``).  Whole-second times of a fast log are refused as the unit mistake they are.
    """
    t = frame["t"].to_numpy()
    runs = frame["run"].to_numpy()
    cols = [frame[c].to_numpy() for c in ("theta", sig)]
    keep = np.ones(len(frame), bool)
    new_t = t.astype(float, copy=True)
    n_spread = 0
    n_copy = n_isolated = n_back = 0
    for rid, idx in _run_rows(runs):
        tr = t[idx]
        prev_max = np.concatenate(([-np.inf], np.maximum.accumulate(tr)[:-1]))
        back = tr < prev_max
        if back.mean() > max_bad_fraction:
            first = idx[np.flatnonzero(back)[0]]
            raise InputError(
                f"{path}: column 't' goes backwards in {int(back.sum())} of {len(tr)} rows (first at data "
                f"row {frame.index[first] + 1}: t = {t[first]:g} after {prev_max[np.flatnonzero(back)[0]]:g}); if the file holds "
                "several experiments, give each its own file or a 'run' column")
        if back.any():
            keep[idx[back]] = False
            n_back += int(back.sum())
            ok = idx[~back]  # non-decreasing stamps from here on
            to = t[ok]
        else:  # the usual run: every stamp in order, its rows and stamps as they are (no copies)
            ok, to = idx, tr
        rep = np.concatenate(([False], to[1:] == to[:-1]))
        if not rep.any():
            continue
        same = np.concatenate(([False], np.all([c[ok][1:] == c[ok][:-1] for c in cols], axis=0)))
        copy = rep & same
        keep[ok[copy]] = False
        n_copy += int(copy.sum())
        ok, to, rep = ok[~copy], to[~copy], rep[~copy]
        n_rep = int(rep.sum())
        if not n_rep:
            continue
        distinct = np.unique(to)
        med_step = float(np.median(np.diff(distinct))) if len(distinct) > 1 else math.inf
        if med_step >= 1.0 and n_rep > max_bad_fraction * len(idx):
            raise InputError(f"{path}: column 't' repeats the previous time in {n_rep} of {len(idx)} rows; "
                             "is the time column in the right unit (not rounded to whole seconds)?")
        if n_rep < CLOCK_BURST_FRACTION * len(idx) or len(distinct) < 2:
            keep[ok[rep]] = False
            n_isolated += n_rep
            continue
        # bursts: rows [s, e) share the stamp to[s]; spread them towards the next distinct stamp
        starts = np.flatnonzero(~rep)
        ends = np.concatenate((starts[1:], [len(to)]))
        size = ends - starts
        nxt = np.concatenate((to[starts[1:]], [np.nan]))
        span = nxt - to[starts]
        period = float(np.median(span[:-1] / size[:-1]))  # the typical sample period of the run
        even = span / size
        # a burst before a gap (or the last one) takes the typical period, not the gap
        step = np.where(np.isfinite(even) & (even <= 2 * period), even, period)
        offset = np.arange(len(to)) - np.repeat(starts, size)
        new_t[ok] = to + offset * np.repeat(step, size)
        n_spread += n_rep
    n_drop = n_copy + n_isolated
    if n_drop:
        excluded["duplicate_time"] += n_drop
    if n_back:
        excluded["non_increasing_time"] += n_back
    if n_drop or n_back:
        warn(f"{path}: {n_drop + n_back} rows with duplicate or backward time excluded")
    if n_spread:
        notes.append(f"{path}: {n_spread} rows repeat the time stamp of the row before (a logger clock coarser than "
                     "its sample rate); each burst of equal stamps is spread evenly up to the next stamp, no row lost")
    if n_spread or not keep.all():
        frame = frame.copy() if keep.all() else frame.loc[keep].copy()
        frame["t"] = new_t[keep]
    return frame


def _exclude_saturation(path, frame: pd.DataFrame, col: str):
    v = frame[col].to_numpy()
    n = len(v)
    if n < 100:
        return frame, 0
    # Saturation shows as a signal that varies from sample to sample but sticks at its extreme.  A
    # signal that often holds its value anyway (noise-free simulation, coarse quantisation) sits at
    # its extremes by nature: that is no evidence of saturation, and nothing is excluded.
    # each extreme's rows found once (a pass each), the repeats counted without a difference array:
    # the same counts, hence the same decisions, as (v == max) | (v == min) and mean(diff(v)[inner] == 0)
    ats = [v == extreme for extreme in (v.max(), v.min())]
    at_end = ats[0] | ats[1]
    inner = ~at_end[:-1] & ~at_end[1:]
    n_inner = int(np.count_nonzero(inner))
    if n_inner < 20 or np.count_nonzero(inner & (v[1:] == v[:-1])) / n_inner > 0.2:
        return frame, 0
    mask = np.zeros(n, bool)
    for at in ats:
        count = int(np.count_nonzero(at))
        if count < max(5, 0.002 * n):
            continue
        # longest run of consecutive samples at the extreme
        edges = np.diff(np.concatenate(([0], at.astype(np.int8), [0])))
        longest = int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max())
        if longest >= 5:
            mask |= at
    n_sat = int(mask.sum())
    if n_sat:
        warn(f"{path}: column '{col}' sits at its extreme value in {n_sat} rows; they look saturated and are excluded")
        frame = frame.loc[~mask]
    return frame, n_sat


def _unwrap_theta(path, frame: pd.DataFrame, unit: str, notes: list[str]) -> pd.DataFrame:
    if unit != "rad":
        return frame
    theta = frame["theta"].to_numpy(dtype=float)
    runs = frame["run"].to_numpy()
    out = theta.copy()
    changed = False
    for rid, idx in _run_rows(runs):
        th = theta[idx]
        if len(th) < 3:
            continue
        ad = np.abs(np.diff(th))
        if not (ad > np.pi).any():  # no step of half a turn (of either period): nothing wraps (most runs)
            continue
        lo, hi = th.min(), th.max()
        for period, what in ((2 * np.pi, "2*pi"), (360.0, "360")):
            big = ad > 0.5 * period
            if not big.any() or hi - lo > period * 1.02:
                continue
            if not np.all(np.abs(ad[big] - period) < 0.25 * period):
                continue
            # typical step far below the jumps: it is a wrap, not fast motion
            typical = np.median(ad[~big]) if (~big).any() else 0.0
            if typical > 0.05 * period:
                continue
            out[idx] = np.unwrap(th, period=period)
            changed = True
            msg = f"{path}: theta wraps into a range of {what} ({int(big.sum())} wraps in run {rid}); unwrapped"
            if what == "360":
                warn(f"{path}: theta wraps at 360: it looks like degrees, not radians; unwrapped with period 360, "
                     "but frequencies will be per degree: convert with --scale theta=0.0174533")
            notes.append(msg)
            break
    if changed:
        frame = frame.copy()
        frame["theta"] = out
    return frame
