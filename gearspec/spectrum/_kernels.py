"""Compiled kernels (numba) of the order analysis: one pass per sample where numpy needed many.

Each kernel is THE implementation of its step (no numpy twin): the tests check them against a
dense least squares, ``np.histogram``, ``np.interp`` and the package's rules on small cases.
Compiled with ``cache=True`` (the machine code is kept in ``__pycache__`` between processes) and
``nogil=True`` (the two directions of :func:`~gearspec.spectrum.ordertrack.order_analysis` run in
two threads at once).  No ``fastmath``: every sum and product is the IEEE operation numpy does, so
results equal numpy's to rounding of the order of summation only.  Import this module lazily (inside
the functions that use it): importing numba costs a few tenths of a second that a command without an
order analysis should not pay.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: degree of the track's B-splines (cubic), as ``ordertrack._DEGREE``
DEGREE = 3
_TWO_PI = 2 * np.pi


@njit(cache=True, nogil=True)
def grid_cell(x, edges, scale):
    """The cell ``i`` with ``edges[i] <= x < edges[i + 1]`` of equal cells (as ``np.histogram`` counts
    ``x``; the top edge in the last cell): the arithmetic guess ``(x - edges[0]) * scale``, and a
    binary search among the edges when the guess lies within 1e-9 of a cell's border, where rounding
    may have put it on the wrong side; clipped to the cells."""
    n_cells = len(edges) - 1
    pos = (x - edges[0]) * scale
    cell = int(pos)
    frac = pos - cell
    if frac < 1e-9 or frac > 1 - 1e-9:
        cell = np.searchsorted(edges, x, side="right") - 1
    return min(max(cell, 0), n_cells - 1)


@njit(cache=True, nogil=True)
def grid_cells(x, edges):
    """:func:`grid_cell` of every value of ``x``."""
    scale = (len(edges) - 1) / (edges[-1] - edges[0])
    out = np.empty(len(x), np.intp)
    for i in range(len(x)):
        out[i] = grid_cell(x[i], edges, scale)
    return out


#: the sums of the track's moments may be taken in any order and their multiply-adds fused (so that
#: they run four samples at a time): rounding only, 1e-12 of the sums (tested against a dense design)
_SUMS = {"reassoc", "contract"}


@njit(cache=True, nogil=True)
def track_gather(r, theta, speed, y, acc, freqs, tk, edges, X, Y, A, PH, span, counts, travel):
    """The samples ``r`` of a chunk, for :func:`track_sums`: their speed ``X``, friction ``Y`` and
    acceleration ``A`` (0 when ``acc`` is empty) side by side, their knot span ``span`` (``DEGREE``
    + the interior knots of ``tk`` at or below the speed) and the phase of every line ``PH[l, i]``:
    ``2 pi f_l theta`` reduced to one cycle in double precision (``p - floor(p)`` cycles), then
    times 2 pi rounded to single precision (rad).  Each sample's cell of the speed grid with
    ``edges`` (:func:`grid_cell`) gets one count and its speed added to ``travel``."""
    scale = (len(edges) - 1) / (edges[-1] - edges[0])
    has_acc = len(acc) > 0
    top = len(tk) - DEGREE - 1
    for i in range(len(r)):
        k = r[i]
        x = speed[k]
        X[i] = x
        Y[i] = y[k]
        A[i] = acc[k] if has_acc else 0.0
        j = DEGREE
        for t in range(DEGREE + 1, top):
            if x >= tk[t]:
                j += 1
        span[i] = j
        th = theta[k]
        for ln in range(len(freqs)):
            p = th * freqs[ln]
            p -= np.floor(p)
            PH[ln, i] = np.float32(p * _TWO_PI)
        cell = grid_cell(x, edges, scale)
        counts[cell] += 1
        travel[cell] += x


@njit(cache=True, nogil=True)
def track_sums(X, Y, A, span, S, C, tk, P, Q, AJ):
    """Add the moments of a chunk (from :func:`track_gather`; ``S``, ``C`` the single-precision sines
    and cosines, lines x samples) to the sums of their knot spans; return ``sum y^2``.

    In each span j (coordinate ``u = (x - tk[j]) / (tk[j+1] - tk[j])``), with ``g = [1, sin_l,
    cos_l (every line l), sin_l^2, sin_l cos_l (every line)]``: ``P[j - DEGREE, s, c] += u^s g_c``
    (s = 0..6), ``Q[., s, c] += u^s y g_c`` and ``Q[., 4 + s, c] += u^s acc g_c`` (s = 0..3, c < 1 +
    2 lines), ``AJ[.] += (acc^2, acc y)``.  Consecutive samples of one span are summed together."""
    nf = S.shape[0]
    ntrig = 1 + 2 * nf
    n = len(X)
    yy = 0.0
    i = 0
    while i < n:
        j = span[i]
        e = i + 1
        while e < n and span[e] == j:
            e += 1
        lo, h, js = tk[j], tk[j + 1] - tk[j], j - DEGREE
        yy += _run_level(X[i:e], Y[i:e], A[i:e], lo, h, P[js], Q[js], AJ[js])
        for ln in range(nf):
            _run_line(X[i:e], Y[i:e], A[i:e], S[ln, i:e], C[ln, i:e], lo, h, P[js], Q[js],
                      1 + 2 * ln, ntrig + 2 * ln)
        i = e
    return yy


@njit(cache=True, nogil=True, fastmath=_SUMS)
def _run_level(x, y, a, lo, h, P, Q, AJ):
    """The level's moments of samples of one span (see :func:`track_sums`); returns ``sum y^2``."""
    p0 = p1 = p2 = p3 = p4 = p5 = p6 = 0.0
    q0 = q1 = q2 = q3 = r0 = r1 = r2 = r3 = aa = ay = yy = 0.0
    for i in range(len(x)):
        u1 = (x[i] - lo) / h
        u2 = u1 * u1
        u3 = u2 * u1
        u4 = u3 * u1
        u5 = u4 * u1
        u6 = u5 * u1
        p0 += 1.0
        p1 += u1
        p2 += u2
        p3 += u3
        p4 += u4
        p5 += u5
        p6 += u6
        yv, av = y[i], a[i]
        q0 += yv
        q1 += u1 * yv
        q2 += u2 * yv
        q3 += u3 * yv
        r0 += av
        r1 += u1 * av
        r2 += u2 * av
        r3 += u3 * av
        aa += av * av
        ay += av * yv
        yy += yv * yv
    P[0, 0] += p0
    P[1, 0] += p1
    P[2, 0] += p2
    P[3, 0] += p3
    P[4, 0] += p4
    P[5, 0] += p5
    P[6, 0] += p6
    Q[0, 0] += q0
    Q[1, 0] += q1
    Q[2, 0] += q2
    Q[3, 0] += q3
    Q[4, 0] += r0
    Q[5, 0] += r1
    Q[6, 0] += r2
    Q[7, 0] += r3
    AJ[0] += aa
    AJ[1] += ay
    return yy


@njit(cache=True, nogil=True, fastmath=_SUMS)
def _run_line(x, y, a, S, C, lo, h, P, Q, cs, cq):
    """One line's moments of samples of one span (see :func:`track_sums`): ``P[s, cs]``, ``P[s, cs
    + 1]`` (sine, cosine), ``P[s, cq]``, ``P[s, cq + 1]`` (sin^2, sin cos), ``Q[s, cs]``, ``Q[s, cs +
    1]`` (times y, s < 4) and ``Q[4 + s, .]`` (times acc).  Written out sum by sum on purpose: numba
    keeps these scalars in registers, where an array of accumulators would go through memory."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = c0 = c1 = c2 = c3 = c4 = c5 = c6 = 0.0
    t0 = t1 = t2 = t3 = t4 = t5 = t6 = m0 = m1 = m2 = m3 = m4 = m5 = m6 = 0.0
    ys0 = ys1 = ys2 = ys3 = yc0 = yc1 = yc2 = yc3 = 0.0
    as0 = as1 = as2 = as3 = ac0 = ac1 = ac2 = ac3 = 0.0
    for i in range(len(x)):
        u1 = (x[i] - lo) / h
        u2 = u1 * u1
        u3 = u2 * u1
        u4 = u3 * u1
        u5 = u4 * u1
        u6 = u5 * u1
        sv = np.float64(S[i])
        cv = np.float64(C[i])
        ss = sv * sv
        sc = sv * cv
        s0 += sv
        s1 += u1 * sv
        s2 += u2 * sv
        s3 += u3 * sv
        s4 += u4 * sv
        s5 += u5 * sv
        s6 += u6 * sv
        c0 += cv
        c1 += u1 * cv
        c2 += u2 * cv
        c3 += u3 * cv
        c4 += u4 * cv
        c5 += u5 * cv
        c6 += u6 * cv
        t0 += ss
        t1 += u1 * ss
        t2 += u2 * ss
        t3 += u3 * ss
        t4 += u4 * ss
        t5 += u5 * ss
        t6 += u6 * ss
        m0 += sc
        m1 += u1 * sc
        m2 += u2 * sc
        m3 += u3 * sc
        m4 += u4 * sc
        m5 += u5 * sc
        m6 += u6 * sc
        ysv, ycv, asv, acv = y[i] * sv, y[i] * cv, a[i] * sv, a[i] * cv
        ys0 += ysv
        ys1 += u1 * ysv
        ys2 += u2 * ysv
        ys3 += u3 * ysv
        yc0 += ycv
        yc1 += u1 * ycv
        yc2 += u2 * ycv
        yc3 += u3 * ycv
        as0 += asv
        as1 += u1 * asv
        as2 += u2 * asv
        as3 += u3 * asv
        ac0 += acv
        ac1 += u1 * acv
        ac2 += u2 * acv
        ac3 += u3 * acv
    _add7(P, cs, s0, s1, s2, s3, s4, s5, s6)
    _add7(P, cs + 1, c0, c1, c2, c3, c4, c5, c6)
    _add7(P, cq, t0, t1, t2, t3, t4, t5, t6)
    _add7(P, cq + 1, m0, m1, m2, m3, m4, m5, m6)
    _add4(Q, 0, cs, ys0, ys1, ys2, ys3)
    _add4(Q, 0, cs + 1, yc0, yc1, yc2, yc3)
    _add4(Q, 4, cs, as0, as1, as2, as3)
    _add4(Q, 4, cs + 1, ac0, ac1, ac2, ac3)


@njit(cache=True, nogil=True)
def _add7(P, c, v0, v1, v2, v3, v4, v5, v6):
    P[0, c] += v0
    P[1, c] += v1
    P[2, c] += v2
    P[3, c] += v3
    P[4, c] += v4
    P[5, c] += v5
    P[6, c] += v6


@njit(cache=True, nogil=True)
def _add4(Q, r, c, v0, v1, v2, v3):
    Q[r, c] += v0
    Q[r + 1, c] += v1
    Q[r + 2, c] += v2
    Q[r + 3, c] += v3


@njit(cache=True, nogil=True)
def masked_range(x, use):
    """``(count, min, max)`` of ``x[use]`` without forming it (min and max NaN when none)."""
    n = 0
    lo = np.inf
    hi = -np.inf
    for i in range(len(x)):
        if use[i]:
            n += 1
            v = x[i]
            if v < lo:
                lo = v
            if v > hi:
                hi = v
    if n == 0:
        return 0, np.nan, np.nan
    return n, lo, hi


@njit(cache=True, nogil=True)
def direction_runs(v, min_speed, d, acc, check_acc, starts, stops, min_piece, rs, re):
    """The runs of samples moving in direction ``d`` (``d v > min_speed``; NaN never moves; with
    ``check_acc`` the acceleration finite too) within each stretch ``[starts[k], stops[k])``, into
    ``rs`` and ``re`` (room for ``len(v) // min_piece + len(starts)`` runs): ``(runs, moving
    samples)``, runs shorter than ``min_piece`` left out (their samples counted as moving)."""
    n_runs = 0
    n_moving = 0
    for k in range(len(starts)):
        a = -1
        for i in range(starts[k], stops[k] + 1):
            mv = False
            if i < stops[k]:
                x = v[i]
                mv = x > min_speed if d > 0 else x < -min_speed
                if mv and check_acc:
                    mv = np.isfinite(acc[i])
            if mv:
                n_moving += 1
                if a < 0:
                    a = i
            elif a >= 0:
                if i - a >= min_piece:
                    rs[n_runs] = a
                    re[n_runs] = i
                    n_runs += 1
                a = -1
    return n_runs, n_moving


@njit(cache=True, nogil=True)
def gather_runs(rs, re, t, theta, v, tau, acc, inertia, d, need_acc, t_o, th_o, sp_o, y_o, a_o):
    """The samples of the runs ``[rs[k], re[k])`` one after the other into ``t_o, th_o, sp_o, y_o``
    and ``a_o``: time, position, ``|v|``, the friction magnitude ``y = d (tau - inertia acc)``
    (``inertia`` 0: ``d tau``) and, when ``need_acc``, the acceleration."""
    o = 0
    for k in range(len(rs)):
        for i in range(rs[k], re[k]):
            t_o[o] = t[i]
            th_o[o] = theta[i]
            sp_o[o] = abs(v[i])
            y = tau[i] - inertia * acc[i] if inertia != 0 else tau[i]
            y_o[o] = -y if d < 0 else y
            if need_acc:
                a_o[o] = acc[i]
            o += 1


@njit(cache=True, nogil=True)
def _search_with_guess(key, arr, a, n, guess):
    """numpy's ``binary_search_with_guess`` (the search of ``np.interp``) on ``arr[a:a + n]``: the
    index ``j`` with ``arr[j] <= key < arr[j + 1]`` (-1 below, n above), trying ``guess`` first."""
    if key > arr[a + n - 1]:
        return n
    if key < arr[a]:
        return -1
    if n <= 4:
        i = 1
        while i < n and key >= arr[a + i]:
            i += 1
        return i - 1
    imin, imax = 0, n
    guess = max(min(guess, n - 3), 1)
    if key < arr[a + guess]:
        if key < arr[a + guess - 1]:
            imax = guess - 1
            if guess > 8 and key >= arr[a + guess - 8]:
                imin = guess - 8
        else:
            return guess - 1
    else:
        if key < arr[a + guess + 1]:
            return guess
        if key < arr[a + guess + 2]:
            return guess + 1
        imin = guess + 2
        if guess < n - 9 and key < arr[a + guess + 8]:
            imax = guess + 8
    while imin < imax:
        imid = imin + ((imax - imin) >> 1)
        if key >= arr[a + imid]:
            imin = imid + 1
        else:
            imax = imid
    return imin - 1


@njit(cache=True, nogil=True)
def _interp(x, xp, fp, a, n, j):
    """``np.interp(x, xp[a:a + n], fp[a:a + n])`` of one value, its search starting from ``j``:
    ``(value, j)`` (the same arithmetic as numpy's, bit for bit)."""
    if np.isnan(x):
        return x, j
    j = _search_with_guess(x, xp, a, n, j)
    if j == -1:
        return fp[a], 0
    if j == n:
        return fp[a + n - 1], j
    if j == n - 1 or xp[a + j] == x:
        return fp[a + j], j
    k = a + j
    slope = (fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k])
    out = slope * (x - xp[k]) + fp[k]
    if np.isnan(out):
        out = slope * (x - xp[k + 1]) + fp[k + 1]
        if np.isnan(out) and fp[k] == fp[k + 1]:
            out = fp[k]
    return out, j


@njit(cache=True, nogil=True)
def _interp_walk(x, xp, fp, a, n, j):
    """:func:`_interp` where ``xp[a:a + n]`` does not decrease and ``x`` does not fall below the
    previous value: the index walks forward from ``j`` (numpy's search finds the same one: the last
    ``j`` with ``xp[j] <= x``)."""
    if np.isnan(x):
        return x, j
    if x < xp[a]:
        return fp[a], 0
    if x >= xp[a + n - 1]:
        return fp[a + n - 1], j
    while xp[a + j + 1] <= x:
        j += 1
    k = a + j
    if xp[k] == x:
        return fp[k], j
    slope = (fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k])
    out = slope * (x - xp[k]) + fp[k]
    if np.isnan(out):
        out = slope * (x - xp[k + 1]) + fp[k + 1]
        if np.isnan(out) and fp[k] == fp[k + 1]:
            out = fp[k]
    return out, j


@njit(cache=True, nogil=True)
def _grid_walk(xp, fp, a, n, g0, spacing, out):
    """``out[i] = np.interp((g0 + i) * spacing, xp[a:a + n], fp[a:a + n])`` where ``xp`` does not
    decrease (:func:`_interp_walk`, its common case written out: a loop the compiler keeps tight)."""
    j = 0
    first, last = xp[a], xp[a + n - 1]
    for i in range(len(out)):
        x = (g0 + i) * spacing
        if not (first <= x < last):  # outside, at the last point, or NaN
            out[i], j = _interp_walk(x, xp, fp, a, n, j)
            continue
        while xp[a + j + 1] <= x:
            j += 1
        k = a + j
        if xp[k] == x:
            out[i] = fp[k]
            continue
        v = (fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k]) * (x - xp[k]) + fp[k]
        if np.isnan(v):
            v = _interp_walk(x, xp, fp, a, n, j)[0]
        out[i] = v


@njit(cache=True, nogil=True)
def _search(arr, a, n, key, right):
    """``np.searchsorted(arr[a:a + n], key, side)`` (``right``: side="right") by bisection."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if arr[a + mid] < key or (right and arr[a + mid] == key):
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def layout_sizes(th, starts, stops, spacing, window):
    """Per piece ``[starts[k], stops[k])`` of ``th``: its first grid point ``ceil(th0 / spacing)``, its
    grid points (0 when fewer than ``window``) and windows (50 % overlap), for :func:`window_layout`."""
    n_p = len(starts)
    g0s, n_grids, n_wins = np.empty(n_p, np.int64), np.zeros(n_p, np.int64), np.zeros(n_p, np.int64)
    for k in range(n_p):
        s, e = starts[k], stops[k]
        g0 = np.int64(np.ceil(th[s] / spacing))
        g1 = np.int64(np.floor(th[e - 1] / spacing))
        g0s[k] = g0
        if g1 - g0 + 1 >= window:
            n_grids[k] = g1 - g0 + 1
            n_wins[k] = (n_grids[k] - window) // (window // 2) + 1
    return g0s, n_grids, n_wins


@njit(cache=True, nogil=True)
def window_layout(th, y, t, starts, stops, spacing, window, g0s, sizes, outs):
    """The order map's windows over the pieces ``[starts[k], stops[k])`` of the position ``th``
    (increasing along the motion): each piece with a grid of at least ``window`` points at
    ``spacing`` gets ``y`` interpolated linearly on ``ceil(th0 / spacing) .. floor(th1 / spacing)``
    (times spacing, ``np.interp``'s arithmetic) and windows of ``window`` points with 50 % overlap.

    Fills ``outs = (grid, first, a_edge, b_edge, duration, half_idx, b_idx, n_win, p_start, p_stop)``
    (sizes from :func:`layout_sizes`: ``g0s`` and ``sizes = (grid points, windows)`` per piece):
    the grids concatenated; per window its first grid point there, its first and last grid position,
    its duration (s, ``t`` interpolated at them) and ``searchsorted(piece, last, "left")``; per
    piece with windows its number of windows and bounds, and its half-window edges (window starts,
    then the end of the last window's first half) ``searchsorted(piece, edge, "right")``; indices
    within the piece."""
    step = window // 2
    n_grids, n_wins = sizes
    grid, first, a_edge, b_edge, dur, half_idx, b_idx, n_win, p_start, p_stop = outs
    og = ow = oh = op = 0
    for k in range(len(starts)):
        nw = n_wins[k]
        if nw == 0:
            continue
        s, e = starts[k], stops[k]
        n = e - s
        g0 = g0s[k]
        mono = True  # positions that never decrease: the interpolation's index walks forward
        for i in range(s, e - 1):
            if th[i + 1] < th[i]:
                mono = False
                break
        if mono:
            _grid_walk(th, y, s, n, g0, spacing, grid[og:og + n_grids[k]])
        else:
            j = 0
            for i in range(n_grids[k]):
                grid[og + i], j = _interp((g0 + i) * spacing, th, y, s, n, j)
        j = 0
        tb = np.empty(nw)
        for w in range(nw):  # the windows' last points, then their first (np.interp's order)
            x_b = (g0 + window - 1 + w * step) * spacing
            tb[w], j = _interp_walk(x_b, th, t, s, n, j) if mono else _interp(x_b, th, t, s, n, j)
            b_edge[ow + w] = x_b
            b_idx[ow + w] = _search(th, s, n, x_b, False)
        j = 0 if mono else j  # (np.interp carries its search on from the last points)
        for w in range(nw):
            x_a = (g0 + w * step) * spacing
            ta, j = _interp_walk(x_a, th, t, s, n, j) if mono else _interp(x_a, th, t, s, n, j)
            dur[ow + w] = tb[w] - ta
            a_edge[ow + w] = x_a
            first[ow + w] = og + w * step
        for w in range(nw + 1):
            half_idx[oh + w] = _search(th, s, n, (g0 + w * step) * spacing, True)
        n_win[op], p_start[op], p_stop[op] = nw, s, e
        og += n_grids[k]
        ow += nw
        oh += nw + 1
        op += 1



@njit(cache=True, nogil=True)
def mask_chunk(use, start, out):
    """The indices of the ``True`` values of ``use`` from ``start`` on, at most ``len(out)`` of them,
    into ``out``: ``(how many, where the next search starts)``."""
    n = 0
    i = start
    while i < len(use) and n < len(out):
        if use[i]:
            out[n] = i
            n += 1
        i += 1
    return n, i


@njit(cache=True, nogil=True)
def bin_sums(order, bins, power, limit, freq, p_sum, n_win):
    """The order map's cells: for each window ``w`` of ``order`` (in that order), ``p_sum[bins[w],
    k] += power[w, k]`` and ``n_win[bins[w], k] += 1`` where ``freq[k] < limit[w]`` (the frequencies
    the window measures)."""
    for i in range(len(order)):
        w = order[i]
        b = bins[w]
        lim = limit[w]
        for k in range(len(freq)):
            if freq[k] < lim:
                p_sum[b, k] += power[w, k]
                n_win[b, k] += 1
