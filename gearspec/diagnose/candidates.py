"""Candidate terms: what a detector proposes, and how each one is fitted.

A candidate is a *procedure*, not a fixed term: given the data it may use (the training groups of
a fold, or all of them), it searches its own nonlinear parameters there -- the frequency of a
line, its amplitude-vs-speed law and decay, a Stribeck velocity, an exponent, a presliding
length -- and returns the blocks to add to the model (and the blocks they replace).  The held-out
test (:mod:`.loop`) runs that procedure inside every fold, so that the data a fold is judged on
never chose the term that predicts it.

Candidate kinds (``CONTRACTS.md`` section 4):

``periodic``     a line at a frequency found in the residual spectrum; amplitude law per
                 direction chosen by the data (const, exp, rational, power; a decaying law only
                 when it beats a constant amplitude by a likelihood-ratio test at 1 %)
``speed_law``    nonlinear viscous ``c|v|^p``; an extra Stribeck term of exponential, Gaussian or
                 rational shape (with a Coulomb + viscous base: the Stribeck law itself); another
                 amplitude-vs-speed law for a line the model has
``load``         Coulomb and viscous friction growing with |load| (Lola law (8)); a line whose
                 amplitude grows with load^2 (SILO4 eq. 14)
``temperature``  friction linear in temperature
``drift``        friction linear in time (on the recording's clock)
``asymmetry``    a base-law parameter that differs between directions (symmetric models)
``inertia``      a missing inertia: torque ``J thetadd``
``hysteresis``   presliding after reversals (``-s exp(-travel/L)``) or backlash (friction
                 missing over a gap after reversals)
``lag``          the torque channel logged behind position: the lag estimated from the phases of
                 the model's lines across the training plateaus, every line fitted at
                 ``theta - v lag`` (:class:`LagCandidate`)

Declared sidebands (``periodic``): a line of the model amplitude-modulated by a slower shaft, at
the frequencies the gear declares, pooled per direction over the plateaus long enough to resolve
them (:class:`SidebandCandidate`); they compete with another amplitude law of the carrier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..gears import integer_hint
from ..model import LAWS
from ..spectrum import LombScargle
from ..terms import amplitude_law
from .design import (LINEAR, BaseBlock, Block, Grams, HarmonicBlock, TermBlock, measurable, solve_normal,
                     travel_range)

__all__ = ["Candidate", "Proposal", "PeriodicCandidate", "GridCandidate", "FixedCandidate", "AsymmetryBlock",
           "LagCandidate", "LaggedHarmonicBlock", "SidebandCandidate", "SidebandBlock", "segment_phases",
           "lag_candidates", "sideband_candidates", "SIDEBAND_CYCLES"]

_TWO_PI = 2.0 * math.pi
_DNAME = {1: "positive", -1: "negative", 0: "both"}


@dataclass
class Proposal:
    """Blocks to add (and to drop) with their per-group cross products (for the fits)."""

    add: list
    drop: list = field(default_factory=list)
    xtc: np.ndarray | None = None
    ctc: np.ndarray | None = None
    cty: np.ndarray | None = None
    describe: str = ""

    def columns(self, dd) -> np.ndarray:
        return np.column_stack([b.columns(dd) for b in self.add])

    def n_params(self, rnd) -> int:
        return sum(len(b.names) for b in self.add) - sum(len(b.names) for b in self.drop)


def cross_grams(rnd, C: np.ndarray):
    """Per-group X^T C, C^T C and C^T y of new columns ``C`` against the round's design."""
    dd = rnd.dd
    xtc = Grams.cross(rnd.X, C, dd)
    ng, q = dd.n_groups, C.shape[1]
    ctc = np.empty((ng, q, q))
    cty = np.empty((ng, q))
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        ctc[g] = C[a:z].T @ C[a:z]
        cty[g] = C[a:z].T @ dd.y[a:z]
    return xtc, ctc, cty


def train_fit(rnd, keep: np.ndarray, prop: Proposal, train: np.ndarray):
    """Coefficients (kept columns, then new ones) fitted on the training groups, and the
    training residual sum of squares."""
    Gx, bx, yy = rnd.train_sums(train)
    k = np.flatnonzero(keep)
    xtc = prop.xtc[train].sum(0)[k]
    ctc = prop.ctc[train].sum(0)
    cty = prop.cty[train].sum(0)
    G = np.block([[Gx[np.ix_(k, k)], xtc], [xtc.T, ctc]])
    b = np.concatenate([bx[k], cty])
    ref = np.concatenate([rnd.ref_diag[k], np.einsum("gii->i", prop.ctc)])
    beta = solve_normal(G, b, reference=ref)
    rss = float(yy - 2 * beta @ b + beta @ G @ beta)
    return beta, rss


class Candidate:
    """Base class: ``kind``, ``name`` (unique within a round), ``evidence`` (one readable
    sentence), ``detail`` (what the figure of the report shows) and :meth:`propose`."""

    kind = "other"

    def __init__(self, name: str, evidence: str = "", detail: dict | None = None, gate_p: float | None = None):
        self.name = name
        self.evidence = evidence
        self.detail = detail or {}
        self.gate_p = gate_p
        self.frequency = None
        self.label = None
        self.hint = None

    def propose(self, rnd, train: np.ndarray) -> Proposal | None:
        raise NotImplementedError


class FixedCandidate(Candidate):
    """Blocks as they are (nonlinear parameters fixed): to check that a term accepted earlier
    still earns its place once later terms are in (backward elimination)."""

    def __init__(self, kind: str, name: str, blocks, drop=()):
        super().__init__(name)
        self.kind = kind
        self.blocks = list(blocks)
        self.drop = list(drop)
        self._cache = {}

    def propose(self, rnd, train):
        if self._cache.get("round") is not rnd:
            C = np.column_stack([b.columns(rnd.dd) for b in self.blocks])
            xtc, ctc, cty = cross_grams(rnd, C)
            self._cache = {"round": rnd, "prop": Proposal(self.blocks, self.drop, xtc, ctc, cty, "")}
        return self._cache["prop"]


# ---------------------------------------------------------------------- grid candidates
class GridCandidate(Candidate):
    """A term family with a grid of nonlinear values; ``make(value) -> (add blocks, drop blocks)``.
    In each fold the grid value with the smallest training error is used."""

    def __init__(self, kind: str, name: str, make, grid, *, evidence: str = "", detail=None, gate_p=None,
                 describe_value=None):
        super().__init__(name, evidence, detail, gate_p)
        self.kind = kind
        self.make = make
        self.grid = list(grid)
        self.describe_value = describe_value or (lambda v: "" if v is None else f"{v:.4g}")
        self._cache = {}

    def _prop(self, rnd, i) -> Proposal | None:
        if self._cache.get("round") is not rnd:
            self._cache = {"round": rnd}
        if i not in self._cache:
            made = self.make(self.grid[i])
            if made is None:
                self._cache[i] = None
            else:
                add, drop = made
                C = np.column_stack([b.columns(rnd.dd) for b in add])
                if np.linalg.norm(C) <= 1e-6 * np.linalg.norm(rnd.dd.y):  # nothing the data can see
                    self._cache[i] = None
                else:
                    xtc, ctc, cty = cross_grams(rnd, C)
                    self._cache[i] = Proposal(add, drop, xtc, ctc, cty, self.describe_value(self.grid[i]))
        return self._cache[i]

    def propose(self, rnd, train):
        best = None
        for i in range(len(self.grid)):
            p = self._prop(rnd, i)
            if p is None:
                continue
            keep = rnd.keep_mask(p.drop)
            _, rss = train_fit(rnd, keep, p, train)
            if best is None or rss < best[0]:
                best = (rss, p)
        return None if best is None else best[1]


@dataclass(frozen=True, eq=False)
class AsymmetryBlock(Block):
    """The difference of one base-law parameter in the negative direction from the shared value
    of a symmetric model: column ``sign(v) [v < 0] m_param(|v|)``."""

    law: str = "coulomb_viscous"
    param: str = "tau_c"
    nonlin: tuple = ()

    @property
    def names(self):
        return [f"{self.param}[neg - pos]"]

    def _raw(self, dd):
        f = dd.fit
        law = LAWS[self.law]
        speed = np.abs(f.v)
        params = {k: 0.0 for k in law.params}
        params.update({k: None for k in law.optional})
        params.update(dict(self.nonlin))
        if all(v is not None for v in dict(self.nonlin).values()):
            params.update({k: 0.0 for k in LINEAR[self.law][0]})
        params[self.param] = 1.0
        load = f.load if f.load is not None else (np.zeros(len(f)) if law.needs_load else None)
        mag = np.broadcast_to(np.asarray(law.magnitude(speed, load, *[params[k] for k in law.params]), float),
                              speed.shape)
        return np.where(f.direction < 0, np.sign(f.v) * mag, 0.0)[:, None]

    def write(self, model, coef, se):
        p = model.directions["negative"]
        if p.get(self.param) is not None:
            p[self.param] = float(p[self.param]) + float(coef[0])
            p[self.param + "_se"] = float(se[0])
        model.notes.append(f"asymmetry: {self.param} differs in the negative direction by {coef[0]:.4g} "
                           f"(+- {se[0]:.2g})")

    def describe(self):
        return f"{self.param} different in the negative direction"


# ---------------------------------------------------------------------- periodic
_EXP_GRID = (-1.0, -0.5, 0.25, 0.5, 1.0, 2.0, 3.0, 5.0)      # decay x top speed
_RAT_GRID = (0.25, 0.5, 1.0, 2.0, 4.0)                          # decay x top speed
_POW_GRID = (0.25, 0.5, 1.0, 2.0, 3.0)                          # exponent


def choose_amplitude_law(theta, speed, seg, r, frequency, *, alpha: float = 0.01) -> tuple[str, float, dict]:
    """The amplitude-vs-speed law of a line at ``frequency`` that the residual ``r`` supports:
    least squares of ``g(|v|) (a sin + c cos)`` (each segment's mean removed) for a constant
    amplitude and each decaying law over a grid of its constant; a decaying law is chosen only when
    it beats the constant amplitude by a likelihood-ratio test at ``alpha`` (and the line is seen
    at two speeds or more).  Returns ``(law, decay, rss_by_law)``."""
    x = _TWO_PI * frequency * theta
    sn, cs = np.sin(x), np.cos(x)
    sids = np.unique(seg)
    inv = np.searchsorted(sids, seg)
    cnt = np.bincount(inv).astype(float)

    def dm(a):
        return a - (np.bincount(inv, weights=a) / cnt)[inv]

    rr = dm(r)
    yy = float(rr @ rr)

    def rss(g):
        A = np.column_stack([dm(g * sn), dm(g * cs)])
        G = A.T @ A
        b = A.T @ rr
        beta = solve_normal(G, b)
        return yy - float(beta @ b)

    top = float(np.max(speed)) if len(speed) else 1.0
    out = {"const": (rss(np.ones_like(speed)), 0.0)}
    speeds = np.unique(np.round(speed, 9))
    if len(speeds) >= 2 and top > 0:
        for law, grid in (("exp", _EXP_GRID), ("rational", _RAT_GRID), ("power", _POW_GRID)):
            best = None
            for gval in grid:
                b = gval if law == "power" else gval / top
                val = rss(amplitude_law(law, speed, b))
                if best is None or val < best[0]:
                    best = (val, b)
            out[law] = best
    law, (val, dec) = min(out.items(), key=lambda kv: kv[1][0])
    n = len(r)
    s2 = val / max(n - 3 - len(sids), 1)
    from scipy import stats
    if law != "const" and (out["const"][0] - val) < stats.chi2.isf(alpha, 1) * s2:
        law, dec = "const", 0.0
    return law, float(dec), {k: v[0] for k, v in out.items()}


class PeriodicCandidate(Candidate):
    """A line at a frequency near ``f0`` found in the residual spectrum.  In each fold: the
    frequency is searched again on the training residual (Lomb-Scargle over +-2 resolution steps,
    the directions' powers added in units of their residual variance, parabolic refinement), the
    amplitude law chosen per direction (:func:`choose_amplitude_law`), and the line fitted jointly
    with the model."""

    kind = "periodic"

    def __init__(self, f0: float, resolution: float, *, gear=None, evidence: str = "", detail=None, gate_p=None,
                 unit: str = "rad"):
        super().__init__(f"line at {f0:.6g} cycles/{unit}", evidence, detail, gate_p)
        self.f0 = float(f0)
        self.resolution = float(resolution)
        self.gear = gear
        self.unit = unit
        self.frequency = self.f0
        self.relabel(self.f0)

    def relabel(self, f: float, se: float | None = None) -> None:
        """Label (or integer hint) of frequency ``f``: within three standard errors of it (or a
        tenth of a resolution step before it is fitted), and at least 0.2 % of it (0.5 % for an
        integer hint)."""
        self.frequency = float(f)
        tol = max(3 * se if se is not None and np.isfinite(se) else 0.1 * self.resolution, 2e-3 * f)
        ln = self.gear.label(f, tol) if self.gear is not None else None
        self.label = None if ln is None else ln.label
        # an integer relation to a shaft is looser: a filtered or delayed signal shifts a fitted
        # frequency by a few tenths of a percent, and neighbouring multiples (6x, 8x) are far apart;
        # a high multiple (72x) needs the line's own precision instead, where the loose tolerance
        # would match a multiple by chance (integer_hint refuses such a tolerance)
        self.hint = None
        if self.gear is not None and ln is None:
            self.hint = integer_hint(self.gear, f, max(tol, 5e-3 * f))
            if self.hint is None and se is not None and np.isfinite(se) and se > 0:
                self.hint = integer_hint(self.gear, f, 3 * se)

    def propose(self, rnd, train):
        dd = rnd.dd
        rows = rnd.rows(train)
        beta0 = rnd.beta(train)
        r0 = dd.y[rows] - rnd.X[rows] @ beta0
        theta = dd.at("theta")[rows]
        d = dd.at("direction")[rows]
        speed = np.abs(dd.at("v")[rows])
        seg = dd.at("segment")[rows]
        top = float(np.max(np.abs(dd.at("v")))) if len(dd) else 0.0
        moving = speed > (0.05 * top if dd.kind == "trajectory" else 0.0)
        w = 2.0 * self.resolution
        freqs = np.linspace(max(self.f0 - w, 0.5 * self.f0), self.f0 + w, 81)
        total = np.zeros(len(freqs))
        dirs = [x for x in (1, -1) if np.sum((d == x) & moving) >= 16]
        if not dirs:
            return None
        for x in dirs:
            sel = (d == x) & moving
            y = x * r0[sel]
            sids = np.unique(seg[sel])
            inv = np.searchsorted(sids, seg[sel])
            y = y - (np.bincount(inv, weights=y) / np.bincount(inv))[inv]
            var = float(np.var(y))
            if var <= 0:
                continue
            total += LombScargle(theta[sel], y, method="astropy").power(freqs) / var
        i = int(np.argmax(total))
        f = float(freqs[i])
        if 0 < i < len(freqs) - 1:
            a, b, c = total[i - 1:i + 2]
            den = a - 2 * b + c
            if den < 0:
                f += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5) * (freqs[1] - freqs[0]))
        symmetric = rnd.state.symmetric
        laws, decays = [], []
        # the amplitude law from the segments that measure the line only (below their position
        # Nyquist limit, a whole cycle): aliased segments would pass for a decay
        meas = measurable(dd, f)[dd.index][rows] if dd.reduce is None else np.ones(len(d), bool)
        groups = [(0, moving & meas)] if symmetric else [(x, (d == x) & moving & meas) for x in dirs]
        for x, sel in groups:
            if not sel.any():
                laws.append((x, "const"))
                decays.append((x, 0.0))
                continue
            yv = (d[sel] if x == 0 else x) * r0[sel]
            law, dec, _ = choose_amplitude_law(theta[sel], speed[sel], seg[sel], yv, f)
            laws.append((x, law))
            decays.append((x, dec))
        blk = HarmonicBlock(key=f"found {f:.6g}", frequency=f, label=self.label, dirs=tuple(dirs),
                            symmetric=symmetric, law=tuple(laws), decay=tuple(decays), found=True)
        C = blk.columns(dd)
        xtc, ctc, cty = cross_grams(rnd, C)
        return Proposal([blk], [], xtc, ctc, cty,
                        f"{f:.6g} cycles/{self.unit}; " + ", ".join(f"{_DNAME[x]}: {lw}" + (f" (decay {dc:.3g})" if lw != 'const' else '')
                                                               for (x, lw), (_, dc) in zip(laws, decays)))


# ---------------------------------------------------------------------- builders of the other kinds
def term_candidates(rnd, analyses: dict, *, gate: float) -> list[Candidate]:
    """The non-periodic candidates of a round (see the module docstring).  ``analyses`` is what
    :func:`.loop.analyse` computed on the round's residual; its statistics become each
    candidate's evidence.  Families with many members are proposed only when their detector
    sees structure at p < ``gate`` (the speed-law family: residual means against speed; other
    amplitude laws of a line: the line standing out in the residual spectrum); the others (one or
    two candidates each: load, eq. 14 per line, temperature, drift, asymmetry of a symmetric
    model, inertia, presliding and backlash) whenever the data can show them (a load or a
    temperature that varies, reversals within a run, ...) -- the held-out test decides."""
    dd = rnd.dd
    state = rnd.state
    out: list[Candidate] = []
    present = dd.directions()
    sym = state.symmetric
    speeds = np.abs(dd.at("v"))
    has = {b.key for b in state.blocks}
    top = float(np.max(speeds)) if len(speeds) else 0.0
    moving = speeds[speeds > (0.05 * top if dd.kind == "trajectory" else 0.0)]
    dirs_blocks = [0] if sym else present

    def per_dir(kind, fixed, key, effect_kind, label=None):
        return [TermBlock(key=f"{key}{'' if x == 0 else ('+' if x > 0 else '-')}", kind=kind, fixed=tuple(fixed),
                          direction=x, label=label, effect_kind=effect_kind) for x in dirs_blocks]

    sp = analyses.get("speed")
    if sp is not None:
        table, st = sp
        ps = [v["p"] for k, v in st.items() if k in (1, -1)]
        p_speed = min(1.0, min(ps) * len(ps)) if ps else 1.0
        n_speeds = len(np.unique(np.round(moving, 6))) if dd.kind == "plateaus" else 12
        if n_speeds >= 3 and p_speed < gate:
            ev = "residual means against speed: " + "; ".join(
                f"{_DNAME[k]}: chi2 {v['chi2']:.1f} on {v['dof']} dof (p {v['p']:.2g})" for k, v in st.items() if k in (1, -1))
            lo, hi = float(np.min(moving)), float(np.max(moving))
            def family(blocks_of):
                def make(p):
                    return blocks_of(p), []
                return make

            if "viscous_power" not in has and "viscous_power+" not in has:
                out.append(GridCandidate(
                    "speed_law", "nonlinear viscous |v|^p",
                    family(lambda p: per_dir("viscous_power", [("exponent", p)], "viscous_power", "speed_law")),
                    (0.25, 0.5, 0.75, 1.5, 2.0, 3.0), evidence=ev,
                    detail={"analysis": "speed"}, gate_p=p_speed, describe_value=lambda v: f"exponent {v:g}"))
            vs_grid = np.geomspace(max(lo / 3, 1e-9), hi / 2, 10)
            for shape in ("exp", "gauss", "rational"):
                key = f"stribeck_extra {shape}"
                if any(k.startswith(key) for k in has):
                    continue
                out.append(GridCandidate(
                    "speed_law", f"Stribeck term ({shape})",
                    family(lambda vs, shape=shape, key=key: per_dir("stribeck_extra", [("v_s", float(vs)),
                                                                                     ("shape", shape)], key, "speed_law")),
                    vs_grid, evidence=ev, detail={"analysis": "speed"}, gate_p=p_speed,
                    describe_value=lambda v: f"v_s {v:.4g}"))
        # another amplitude law for a line of the model: when its frequency stands out in the residual
        spectra = analyses.get("spectra", {}).get("pooled", [])
        for blk in [b for b in state.blocks if isinstance(b, HarmonicBlock)]:
            zs = [s.power_z(blk.frequency) for s in spectra if s.frequency[0] <= blk.frequency <= s.frequency[-1]]
            if not zs:
                continue
            zmax = max(zs)
            m_groups = len(zs)
            p_line = min(1.0, m_groups * math.exp(-zmax))
            if p_line >= gate or n_speeds < 3:
                continue
            for x in ((0,) if blk.symmetric else blk.dirs):
                cur = dict(blk.law).get(x, "exp")

                def make(val, blk=blk, x=x):
                    law, g = val
                    b = g if law == "power" else (g / top if top > 0 else 0.0)
                    law_t = tuple((k, law if k == x else v) for k, v in blk.law)
                    dec_t = tuple((k, (b if law != "const" else 0.0) if k == x else v) for k, v in blk.decay)
                    return [blk.with_(law=law_t, decay=dec_t)], [blk]

                grid = [("const", 0.0)] + [("exp", g) for g in _EXP_GRID] + [("rational", g) for g in _RAT_GRID] + \
                       [("power", g) for g in _POW_GRID]
                grid = [g for g in grid if g[0] != cur or cur != "const"]
                lab = blk.label or f"{blk.frequency:.6g}"
                out.append(GridCandidate(
                    "speed_law", f"amplitude law of {lab}" + ("" if x == 0 else f" ({_DNAME[x]})"), make, grid,
                    evidence=(f"the residual still holds the line {lab} (power {zmax:.1f} x local noise, p {p_line:.2g}): "
                              f"its amplitude does not follow the model's {cur} law at every speed"),
                    detail={"analysis": "spectrum", "frequency": blk.frequency}, gate_p=p_line,
                    describe_value=lambda v: f"{v[0]}" + ("" if v[0] == "const" else f" ({v[1]:g})")))
    # load
    ld = analyses.get("load")
    if ld is not None:
        table, st = ld
        ev = "residual means against |load|: " + "; ".join(
            f"{_DNAME[k]}: slope {v['slope']:.3g} per Nm (p {v['p']:.2g})" for k, v in st.items() if k in (1, -1))
        if True:  # one candidate each, whenever the load varies: the held-out test decides
            if not any(k.startswith("load_coulomb") for k in has):
                out.append(GridCandidate("load", "load-dependent Coulomb mu|load|",
                                         lambda _: (per_dir("load_coulomb", [], "load_coulomb", "load"), []), [None],
                                         evidence=ev, detail={"analysis": "load"}, gate_p=st["p"]))
            if not any(k.startswith("load_viscous") for k in has):
                out.append(GridCandidate("load", "load-speed coupling gamma|load||v|",
                                         lambda _: (per_dir("load_viscous", [], "load_viscous", "load"), []), [None],
                                         evidence=ev, detail={"analysis": "load"}, gate_p=st["p"]))
    lm = analyses.get("load_lines", {})
    for blk in [b for b in state.blocks if isinstance(b, HarmonicBlock) and not b.load_phase]:
        res = lm.get(blk.key)
        if res is None:
            continue
        phases = rnd.line_phases(blk)
        lab = blk.label or f"{blk.frequency:.6g}"
        out.append(GridCandidate(
            "load", f"amplitude of {lab} growing with load^2 (SILO4 eq. 14)",
            lambda _, blk=blk, phases=phases: ([blk.with_(load_phase=phases)], [blk]), [None],
            evidence=(f"the in-phase residual at {lab} grows with load^2 across segments (t {res['t']:.1f}, "
                      f"p {res['p']:.2g})"), detail={"analysis": "load_line", "key": blk.key}, gate_p=res["p"]))
    # temperature, drift
    for ch, kind, name in (("temperature", "temperature", "temperature"), ("t", "drift", "drift")):
        res = analyses.get(ch)
        if res is None or kind in has:
            continue
        table, st = res
        ref = float(np.mean(dd.at(ch)))
        ev = (f"residual means against {'temperature' if ch == 'temperature' else 'time'}: slope "
              f"{st.get('both', {}).get('slope', float('nan')):.3g} per {'degC' if ch == 'temperature' else 's'} "
              f"(p {st['p']:.2g})")
        out.append(GridCandidate(kind, name, lambda _, kind=kind, ref=ref: (
            [TermBlock(key=kind, kind=kind, fixed=(("reference", ref),), effect_kind=kind)], []), [None],
            evidence=ev, detail={"analysis": ch}, gate_p=st["p"]))
    # asymmetry of a symmetric model
    sp = analyses.get("speed")
    base = next((b for b in state.blocks if isinstance(b, BaseBlock)), None)
    if sym and base is not None and len(present) == 2 and sp is not None:
        asy = sp[1].get("asymmetry")
        if asy is not None:
            nl = dict(base.nonlin).get(0, {})
            for p in dict(base.lin)[0]:
                if f"asym {p}" in has:
                    continue
                out.append(GridCandidate(
                    "asymmetry", f"{p} different by direction",
                    lambda _, p=p: ([AsymmetryBlock(key=f"asym {p}", law=base.law, param=p,
                                                    nonlin=tuple(nl.items()))], []), [None],
                    evidence=(f"mean residual differs between directions by {asy['difference']:.3g} "
                              f"(Welch t {asy['t']:.1f}, p {asy['p']:.2g})"),
                    detail={"analysis": "speed"}, gate_p=asy["p"]))
    # inertia
    ac = analyses.get("acc")
    if ac is not None and "inertia" not in has:
        st = ac[1]
        out.append(GridCandidate("inertia", "inertia J thetadd",
                                 lambda _: ([TermBlock(key="inertia", kind="inertia", effect_kind="inertia")], []), [None],
                                 evidence=(f"residual against acceleration: slope {st['slope']:.3g} "
                                           f"(t {st['t']:.1f}, p {st['p']:.2g}): an inertia the model misses"),
                                 detail={"analysis": "acc"}, gate_p=st["p"]))
    # hysteresis near reversals
    rv = analyses.get("reversal")
    if rv is not None:
        st = rv[1]
        t_lo, t_hi = travel_range(dd)
        tr = dd.at("travel")
        fin = tr[np.isfinite(tr) & (tr > 0)]
        hi = float(np.quantile(fin, 0.9))
        grid = np.geomspace(t_lo, max(hi, 2 * t_lo), 10)
        ev = (f"residual against travel since the last reversal: presliding profile of length {st['length']:.3g} "
              f"(t {st['t']:.1f}, p {st['p']:.2g})")
        if "hysteresis" not in has:
            out.append(GridCandidate("hysteresis", "presliding hysteresis",
                                     lambda L: ([TermBlock(key="hysteresis", kind="hysteresis",
                                                           fixed=(("length", float(L)),), effect_kind="hysteresis")], []),
                                     grid, evidence=ev, detail={"analysis": "reversal"}, gate_p=st["p"],
                                     describe_value=lambda L: f"length {L:.4g}"))
        if "backlash" not in has:
            out.append(GridCandidate("hysteresis", "backlash",
                                     lambda g: ([TermBlock(key="backlash", kind="backlash",
                                                           fixed=(("gap", float(g)),), effect_kind="hysteresis")], []),
                                     grid, evidence=ev, detail={"analysis": "reversal"}, gate_p=st["p"],
                                     describe_value=lambda g: f"gap {g:.4g}"))
    # a channel lag; sidebands the gear declares (they compete with the amplitude laws above)
    if "lag" not in has:
        out += lag_candidates(rnd, gate=gate)
    out += sideband_candidates(rnd, analyses, gate=gate)
    return out




# ---------------------------------------------------------------------- lag
@dataclass(frozen=True, eq=False)
class LaggedHarmonicBlock(HarmonicBlock):
    """A line of the model seen through a torque channel logged ``lag`` seconds behind position
    (:mod:`gearspec.lag`): its columns at ``theta - v lag`` (exact on a plateau, where the
    velocity is constant).  The harmonic it writes is the friction's own (phase at the true
    position); the model records the lag in ``meta["lag"]``."""

    lag: float = 0.0

    def _raw(self, dd):
        if self.lag == 0.0:
            return super()._raw(dd)
        store = dd.cache.setdefault("lagged", {})
        view = store.get(self.lag)
        if view is None:
            import dataclasses
            import types
            f = dd.fit
            view = types.SimpleNamespace(fit=dataclasses.replace(f, theta=f.theta - f.v * self.lag, cache={}),
                                         cache={}, reduce=dd.reduce)
            while len(store) >= 8:
                store.pop(next(iter(store)))
            store[self.lag] = view
        return super()._raw(view)

    def write(self, model, coef, se, ranges: dict | None = None):
        super().write(model, coef, se, ranges=ranges)
        model.meta = {**model.meta, "lag": float(self.lag)}
        note = f"lag: torque channel {1e3 * self.lag:.4g} ms behind position (lines fitted at theta - v lag)"
        if note not in model.notes:
            model.notes.append(note)

    def describe(self):
        return super().describe() + f"; torque lag {1e3 * self.lag:.4g} ms"


def _lagged(blk: HarmonicBlock, lag: float) -> LaggedHarmonicBlock:
    """The lagged form of a line of the model (a sideband stays a sideband: same columns
    rule)."""
    import dataclasses
    cls = LaggedSidebandBlock if isinstance(blk, SidebandBlock) else LaggedHarmonicBlock
    kw = {f.name: getattr(blk, f.name) for f in dataclasses.fields(blk) if f.name not in ("uid", "coef", "lag")}
    return cls(**kw, coef=blk.coef, lag=float(lag))


def segment_phases(dd, frequencies, *, min_snr: float = 5.0) -> dict:
    """Per held-out group (a plateau) and line of ``frequencies``: the phase of the line in the
    friction magnitude (``sin(2 pi f theta + phase)``, all lines and a straight line fitted
    jointly, :func:`gearspec.spectrum.harmonic.harmonic_fit`) with its standard error, where
    the line is resolved and stands ``min_snr`` standard errors above the noise.  Cached on the
    data.  Returns arrays ``group, frequency, velocity, phase, phase_se, series``."""
    from ..spectrum.harmonic import harmonic_fit
    from .design import resolved

    key = ("segment_phases", tuple(np.round(frequencies, 12)), float(min_snr))
    hit = dd.cache.get(key)
    if hit is not None:
        return hit
    th = dd.at("theta")
    d = dd.at("direction")
    v = dd.at("v")
    rows = []
    for g, (a, z) in enumerate(zip(dd.starts, dd.stops)):
        x = int(d[a])
        fr = [f for f in frequencies if resolved(dd, f)[dd.index[a]] and f * np.ptp(th[a:z]) >= 1.0]
        if not fr or z - a < 4 * len(fr) + 16:
            continue
        hf = harmonic_fit(th[a:z], x * dd.y[a:z], fr, degree=1)
        for f, A, Ase, ph, phse in zip(fr, hf.amplitude, hf.amplitude_se, hf.phase, hf.phase_se):
            if Ase > 0 and A >= min_snr * Ase:
                rows.append((g, f, float(np.mean(v[a:z])), ph, phse, f"{f:.6g} ({'+' if x > 0 else '-'})"))
    cols = list(zip(*rows)) if rows else [[]] * 6
    out = {k: np.asarray(c) for k, c in zip(("group", "frequency", "velocity", "phase", "phase_se", "series"), cols)}
    dd.cache[key] = out
    return out


class LagCandidate(Candidate):
    """The torque channel behind position by a lag (``CONTRACTS.md`` kind ``lag``): in every
    fold the lag is estimated from the phases of the model's lines across the training plateaus
    (:func:`gearspec.lag.lag_from_phases`) and every line of the model is replaced by its lagged
    form (:class:`LaggedHarmonicBlock`).  ``value``: the lag estimated on all data (s)."""

    kind = "lag"

    def __init__(self, table: dict, estimate, max_lag: float, evidence: str = ""):
        super().__init__("torque channel lag", evidence, {"analysis": "lag", "estimate": estimate.to_dict()},
                         gate_p=estimate.p)
        self.table = table
        self.max_lag = float(max_lag)
        self.value = float(estimate.lag)
        self.value_se = float(estimate.se)
        self._cache = {}

    def estimate(self, train: np.ndarray):
        from ..lag import lag_from_phases
        t = self.table
        sel = train[t["group"].astype(int)]
        return lag_from_phases(t["frequency"][sel], t["velocity"][sel], t["phase"][sel], t["phase_se"][sel],
                               t["series"][sel], max_lag=self.max_lag)

    def propose(self, rnd, train):
        est = self.estimate(train)
        if est is None:
            return None
        lines = [b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)]
        if not lines:
            return None
        ck = (id(rnd), round(est.lag, 15))
        if self._cache.get("round") is not rnd:
            self._cache = {"round": rnd}
        if ck not in self._cache:
            add = [_lagged(b, est.lag) for b in lines]
            prop = _TaylorProposal(add, lines, describe=f"lag {1e3 * est.lag:.4g} ms")
            prop.xtc, prop.ctc, prop.cty = cross_grams(rnd, prop.columns(rnd.dd))
            self._cache[ck] = prop
        return self._cache[ck]


class _TaylorProposal(Proposal):
    """Blocks that replace blocks of the model with the same nonlinear parameters (the lines,
    lagged): they keep their Taylor columns, as the blocks they replace have them in the fits
    without the candidate, so that the held-out comparison differs by the candidate alone."""

    def columns(self, dd) -> np.ndarray:
        return np.column_stack([b.columns(dd, taylor=True) for b in self.add])


def lag_candidates(rnd, *, gate: float = 0.01) -> list[Candidate]:
    """The lag candidate, when the data can show a lag: plateau data (not reduced), no lag in
    the model yet, a line of the model seen strongly at :data:`gearspec.lag.MIN_SPEEDS` speeds
    or more of one direction, and a lag estimated on all data that differs from zero at
    p < ``gate`` (its phases are otherwise consistent with no lag)."""
    from ..lag import lag_from_phases
    dd = rnd.dd
    if dd.kind != "plateaus" or dd.reduce is not None or dd.at("theta") is None or dd.at("t") is None:
        return []
    blocks = [b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)]
    if not blocks or any(isinstance(b, LaggedHarmonicBlock) for b in blocks):
        return []
    table = segment_phases(dd, sorted({b.frequency for b in blocks}))
    if not len(table["group"]):
        return []
    t = dd.at("t")
    dt = np.diff(t)
    dt = dt[dt > 0]
    max_lag = max(20 * float(np.median(dt)), 0.05) if len(dt) else 0.05
    est = lag_from_phases(table["frequency"], table["velocity"], table["phase"], table["phase_se"], table["series"],
                          max_lag=max_lag)
    if est is None or not est.p < gate:   # phases consistent with no lag: nothing to test
        return []
    ev = (f"the phases of the model's lines drift with speed across plateaus: {est.describe()}, z {est.z:.1f} "
          f"(p {est.p:.2g})")
    return [LagCandidate(table, est, max_lag, evidence=ev)]


# ---------------------------------------------------------------------- sidebands
#: a sideband pair f_c +- f_m is fitted only on plateaus whose travel covers this many periods
#: of the modulating line (1/f_m): shorter ones cannot tell the sidebands from the carrier
SIDEBAND_CYCLES = 2.0


@dataclass(frozen=True, eq=False)
class SidebandBlock(HarmonicBlock):
    """A sideband line (declared by the gear: carrier +- modulating shaft), pooled per direction
    over the plateaus whose travel is at least ``min_travel`` (its columns are zero on the
    others: the loop fits and scores it only there).  The model it writes carries the line as a
    harmonic at every speed: the modulation is physical, only its estimate needs long plateaus."""

    min_travel: float = 0.0

    def _raw(self, dd):
        cols = super()._raw(dd)
        if self.min_travel > 0:
            ok = _travel_ok(dd, self.min_travel)
            cols = np.where(ok[:, None], cols, 0.0)
        return cols


@dataclass(frozen=True, eq=False)
class LaggedSidebandBlock(SidebandBlock, LaggedHarmonicBlock):
    """A sideband line seen through a lagged torque channel."""


def _travel_ok(dd, min_travel: float) -> np.ndarray:
    """Samples (of ``dd.fit``) in a segment whose travel is at least ``min_travel``."""
    key = ("travel_ok", float(min_travel))
    hit = dd.cache.get(key)
    if hit is not None:
        return hit
    f = dd.fit
    seg = f.segment
    ids, inv = np.unique(seg, return_inverse=True)
    lo = np.full(len(ids), np.inf)
    hi = np.full(len(ids), -np.inf)
    np.minimum.at(lo, inv, f.theta)
    np.maximum.at(hi, inv, f.theta)
    out = (hi - lo)[inv] >= min_travel
    dd.cache[key] = out
    return out


class SidebandCandidate(Candidate):
    """Both sidebands ``f_c +- f_m`` of a line of the model (the carrier) modulated by a slower
    shaft, at the frequencies the gear declares (:meth:`GearTrain.candidate_lines`), pooled per
    direction over the plateaus that resolve them; their amplitude law is the carrier's (an
    amplitude modulation of depth m gives sidebands of m/2 of the carrier at every speed)."""

    kind = "periodic"

    def __init__(self, carrier: HarmonicBlock, lines: list, min_travel: float, *, evidence: str = "", gate_p=None,
                 unit: str = "rad", detail=None):
        lab = " and ".join(ln.label for ln in lines)
        super().__init__(f"sidebands {lab}", evidence, detail, gate_p)
        self.carrier = carrier
        self.lines = lines
        self.min_travel = float(min_travel)
        self.frequency = float(lines[0].frequency)
        self.label = lines[0].label
        self.f0 = self.frequency
        self.resolution = 0.0
        self._cache = {}

    def propose(self, rnd, train):
        if self._cache.get("round") is not rnd:
            c = next((b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)
                      and math.isclose(b.frequency, self.carrier.frequency, rel_tol=1e-9)), self.carrier)
            add = [SidebandBlock(key=f"sideband {ln.frequency:.6g}", frequency=float(ln.frequency), label=ln.label,
                                 dirs=c.dirs, symmetric=c.symmetric, law=c.law, decay=c.decay, found=False,
                                 min_travel=self.min_travel) for ln in self.lines]
            if isinstance(c, LaggedHarmonicBlock):   # a lag accepted before: the sidebands see it too
                add = [_lagged(b, c.lag) for b in add]
            C = np.column_stack([b.columns(rnd.dd) for b in add])
            xtc, ctc, cty = cross_grams(rnd, C)
            self._cache = {"round": rnd, "prop": Proposal(add, [], xtc, ctc, cty, self.name)}
        return self._cache["prop"]


def sideband_candidates(rnd, analyses: dict, *, gate: float) -> list[Candidate]:
    """Sidebands the gear declares around a line of the model (the carrier: the higher of the two
    parents) modulated by a slower shaft (the lower, a shaft line), proposed when at least three
    plateaus resolve them (travel of :data:`SIDEBAND_CYCLES` modulation periods or more) and one
    of them stands out in the pooled residual spectrum at p < ``gate``.  They compete, in the
    same round, with another amplitude law of the carrier; the held-out test prefers one."""
    dd = rnd.dd
    gear = dd.gear
    if gear is None or dd.reduce is not None or dd.at("theta") is None:
        return []
    lines = [b for b in rnd.state.blocks if isinstance(b, HarmonicBlock)]
    have = [b.frequency for b in lines]
    shafts = {ln.label: ln for ln in gear.declared_lines(1) if ln.kind == "shaft"}
    pairs: dict = {}
    for ln in gear.candidate_lines(sidebands=True):
        if ln.kind != "sideband" or len(ln.parents) != 2 or ln.parents[1] not in shafts:
            continue
        pairs.setdefault(ln.parents, []).append(ln)
    spectra = analyses.get("spectra", {}).get("pooled", [])
    out = []
    for (hi_lab, lo_lab), sb in pairs.items():
        carrier = next((b for b in lines if b.label and (b.label == hi_lab or hi_lab in b.label.split(" = "))), None)
        if carrier is None:
            continue
        # not where the model has a line already (declared, or found in the residual: within 0.2 %)
        sb = [x for x in sb if not any(math.isclose(x.frequency, f, rel_tol=2e-3) for f in have)]
        if not sb:
            continue
        f_m = shafts[lo_lab].frequency
        min_travel = SIDEBAND_CYCLES / f_m
        ok = _travel_ok(dd, min_travel)[dd.index]
        n_groups = len(np.unique(dd.group[ok]))
        if n_groups < 3:
            continue
        zs = [(s.power_z(x.frequency), x) for s in spectra for x in sb
              if len(s.frequency) and s.frequency[0] <= x.frequency <= s.frequency[-1]]
        if not zs:
            continue
        zmax = max(z for z, _ in zs)
        p_line = min(1.0, len(zs) * math.exp(-zmax))
        if not p_line < gate:
            continue
        out.append(SidebandCandidate(
            carrier, sb, min_travel, unit=dd.unit, gate_p=p_line,
            evidence=(f"declared sidebands of {hi_lab} modulated by the {lo_lab} stand out in the residual spectrum "
                      f"(power {zmax:.1f} x local noise, p {p_line:.2g}); fitted on the {n_groups} plateaus that "
                      f"travel {SIDEBAND_CYCLES:g} modulation periods or more"),
            detail={"analysis": "spectrum", "frequency": sb[0].frequency, "min_travel": min_travel,
                    "groups": n_groups}))
    return out
