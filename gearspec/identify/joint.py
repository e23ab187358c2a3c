"""The joint fit: weighted nonlinear least squares of all parameters of a direction together, on
the samples themselves (amplitudes fitted in the position domain, not through logs of noisy
amplitudes), with standard errors cluster-robust over runs (:mod:`.covariance`; or a bootstrap
over segments); as an estimator (:class:`JointFit`) and as a function (:func:`fit`).

How it works.  Within a constant-speed segment ``s`` the model is *linear* in a few local
coefficients ``beta_s = [level, a_1, c_1, ..., a_K, c_K]`` (the level, and ``A_k g_k(|v_s|)``
times ``cos phi_k``, ``sin phi_k`` of every harmonic), so the segment's residual sum of squares is
exactly ``(beta_s - beta_hat_s)^T G_s (beta_s - beta_hat_s) + const`` with ``G_s = X_s^T X_s`` and
``beta_hat_s`` its own least-squares coefficients (:class:`~.stats.SegmentStats`): the fit works on
a few numbers per segment, exact and independent of the number of samples.  Each segment is
weighted by the inverse of its pure-error variance.  The law's linear parameters are solved in
closed form for given nonlinear ones (variable projection), the nonlinear ones (Stribeck velocity,
decays) by ``scipy.optimize.least_squares`` from the registry's grid start, and a last joint pass
over all parameters gives the covariance.  The laws are evaluated at each segment's mean velocity
(``FitData`` with ``velocity="segment"``) and mean load.  Lola/CROPS laws (``lola8``/``lola11``)
fit friction points (:meth:`FitData.from_points` or load-holding segments).
"""

from __future__ import annotations

import copy
import inspect
import math
import sys
import warnings
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np
from scipy import optimize

from ..core.reduction import on_one_blas_thread
from ..errors import GearspecWarning, InputError
from ..fitdata import FitData
from ..model import LAWS, Direction, FrictionModel, Harmonic
from ..terms.registry import Basis as _Basis
from ..terms.registry import basis as _basis
from ..terms.shapes import amplitude_law, clamp_speed
from .stats import MIN_CYCLES, SIGNIFICANT, ConvergenceError, SegmentStats, harmonic_specs, pair_se, segment_stats
from .stats import speed_ranges
from .covariance import SE_METHODS, _carry_se, _common_inertia, jacobian
from .jointlines import covariance, faint_lines, few_speeds, grid_starts, hold_constant, not_converged
from .validate import _safe_rmse, holdout, inverted_sign, negative_viscous

__all__ = ["JointFit", "clone", "fit", "refit", "fold_fit", "negative_viscous", "inverted_sign"]


# ---------------------------------------------------------------------- the joint fit of one direction
@dataclass
class _Problem:
    stats: SegmentStats
    basis: _Basis
    harmonics: list[dict]
    decay_free: np.ndarray     # (K,) bool: decay fitted (else fixed 0)
    amp_law: list[str]
    weights: np.ndarray        # (S,)
    Lt: np.ndarray             # (S, P, P): sqrt(w) diag(sqrt(lambda)) U^T
    ranges: np.ndarray         # (K, 2): speed range of each amplitude law (:func:`speed_ranges`)
    se: str = "independent"    # covariance method (:func:`~.covariance.fit_covariance`)
    segments: object = None    # the FitData's segment table (run of each segment), for the clusters

    @property
    def K(self):
        return len(self.harmonics)

    def factors(self, decays):
        """(S, K) amplitude factor of each harmonic at each segment's speed, the speed held within
        the harmonic's ``speed_range`` (as :meth:`FrictionModel.evaluate` does)."""
        sp = self.stats.speed
        return np.column_stack([amplitude_law(law, clamp_speed(sp, tuple(self.ranges[k])), decays[k])
                                for k, law in enumerate(self.amp_law)]) if self.K else np.ones((len(sp), 0))

    def design(self, nonlin_base, decays):
        """M (S, P, L): local coefficients = M @ lin, lin = [base lin..., a_1, c_1, ..., (J)]: the
        inertia J, when identified, is the coefficient of the last local column in every segment."""
        st = self.stats
        S, P = st.g.shape
        nb = len(self.basis.lin)
        L = nb + 2 * self.K + int(st.acc)
        M = np.zeros((S, P, L))
        if st.acc:
            M[:, P - 1, L - 1] = 1.0
        if nb:
            M[:, 0, :nb] = self.basis.columns(st.speed, st.load if st.load is not None else np.zeros(S), *nonlin_base)
        fac = self.factors(decays) * st.sampled
        k = np.arange(self.K)
        M[:, 1 + 2 * k, nb + 2 * k] = fac
        M[:, 2 + 2 * k, nb + 2 * k + 1] = fac
        return M

    def weighted_design(self, nonlin_base, decays):
        """``Lt @ design`` per segment, ``(S * P, L)``, from the few local columns each linear
        parameter enters (the level, the line's two, the inertia's): the same products as the full
        contraction over ``design``'s zeros, each entry one product, bit for bit."""
        st, Lt = self.stats, self.Lt
        S, P = st.g.shape
        nb, K = len(self.basis.lin), self.K
        L = nb + 2 * K + int(st.acc)
        A = np.zeros((S, P, L))
        if st.acc:
            A[:, :, L - 1] = Lt[:, :, P - 1]
        if nb:
            cols = self.basis.columns(st.speed, st.load if st.load is not None else np.zeros(S), *nonlin_base)
            A[:, :, :nb] = Lt[:, :, :1] * cols[:, None, :]
        if K:
            fac = (self.factors(decays) * st.sampled)[:, None, :]
            A[:, :, nb:nb + 2 * K:2] = Lt[:, :, 1:1 + 2 * K:2] * fac
            A[:, :, nb + 1:nb + 2 * K:2] = Lt[:, :, 2:2 + 2 * K:2] * fac
        return A.reshape(-1, L)

    def solve_linear(self, nonlin_base, decays):
        A = self.weighted_design(nonlin_base, decays)
        rhs = self.__dict__.get("_rhs")
        if rhs is None:      # the weighted local coefficients: the same for every nonlinear value
            rhs = self._rhs = np.einsum("spq,sq->sp", self.Lt, self.stats.beta_hat).ravel()
        nonneg = [j for j, nm in enumerate(self.basis.lin) if nm in self.basis.nonneg]
        if nonneg:
            lo = np.full(A.shape[1], -np.inf)
            lo[nonneg] = 0.0
            sol = optimize.lsq_linear(A, rhs, bounds=(lo, np.inf), method="bvls").x
        else:
            sol = np.linalg.lstsq(A, rhs, rcond=None)[0]
        return sol, A @ sol - rhs

    def residual_full(self, lin, nonlin_base, decays):
        M = self.design(nonlin_base, decays)
        beta = np.einsum("spl,l->sp", M, lin)
        return np.einsum("spq,sq->sp", self.Lt, beta - self.stats.beta_hat).ravel()


def _make_problem(stats: SegmentStats, law: str, harmonics: list[dict], weights: str, *, se: str = "independent",
                  segments=None) -> _Problem:
    """The problem of one direction; ``se``: the covariance method (``bootstrap``: the covariance's
    errors are replaced later; its base covariance is cluster-robust too), ``segments``: the data's
    segment table (the run of each segment: the clusters)."""
    S = len(stats.g)
    if weights == "segment" and np.all(np.isfinite(stats.sigma2)) and np.all(stats.sigma2 > 0):
        w = 1.0 / stats.sigma2
        w = w / np.median(w)
    elif weights in ("segment", "uniform"):
        w = np.ones(S)
    else:
        raise InputError(f"weights must be 'segment' or 'uniform', got '{weights}'")
    Lt = np.zeros(stats.G.shape)
    if S:   # one batched eigen-decomposition (the same LAPACK call on each segment's matrix)
        lam, U = np.linalg.eigh(stats.G)
        for i in range(S):
            Lt[i] = math.sqrt(w[i]) * (np.sqrt(np.clip(lam[i], 0.0, None))[:, None] * U[i].T)
    amp_law = [("const" if h.get("decay", True) is False else h.get("law", "exp")) for h in harmonics]
    decay_free = np.array([a != "const" for a in amp_law], bool)
    method = "independent" if se == "independent" else "covariance"
    return _Problem(stats, _basis(law), harmonics, decay_free, amp_law, w, Lt, speed_ranges(stats), method, segments)


def _fit_direction(prob: _Problem, *, init: Mapping | None = None, at=None) -> dict:
    """Variable projection from a grid start (``at``: from these nonlinear base values instead), then
    one joint least-squares pass for the covariance."""
    st = prob.stats
    nb_nl = len(prob.basis.nonlin)
    free = np.flatnonzero(prob.decay_free)
    starts, dec0, vs_bounds = grid_starts(prob, init, at)
    # outer problem over log(nonlinear base) and free decays (scaled by the speed range)
    sscale = 1.0 / max(float(np.max(st.speed)), 1e-12) if len(st.speed) else 1.0

    def unpack(x):
        nl = list(np.exp(x[:nb_nl])) if nb_nl else []
        dec = dec0.copy()
        dec[free] = x[nb_nl:] * sscale
        return nl, dec

    def proj(x):
        return prob.solve_linear(*unpack(x))[1]

    if nb_nl or len(free):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            lb = np.concatenate([[vs_bounds[0]] * nb_nl, np.full(len(free), -np.inf)])
            ub = np.concatenate([[vs_bounds[1]] * nb_nl, np.full(len(free), np.inf)])
            res = None
            for st_ in starts:
                x0 = np.clip(np.concatenate([np.log(st_) if nb_nl else [], dec0[free] / sscale]), lb + 1e-9, ub - 1e-9)
                r_ = optimize.least_squares(proj, x0, bounds=(lb, ub), method="trf", x_scale="jac", max_nfev=400)
                if res is None or (np.all(np.isfinite(r_.x)) and r_.cost < res.cost):
                    res = r_
        if not np.all(np.isfinite(res.x)):
            raise ConvergenceError("the friction fit did not converge (non-finite parameters)")
        x_opt, status, stop = res.x, res.status, res
    else:
        x_opt, status, stop = np.zeros(0), 1, None
    nl, dec = unpack(x_opt)
    lin, _ = prob.solve_linear(nl, dec)
    # joint pass over all parameters: covariance from the Jacobian at the optimum

    def full(z):
        return prob.residual_full(z[:len(lin)], *unpack(z[len(lin):]))

    z = np.concatenate([lin, x_opt])
    r = full(z)
    J = jacobian(full, z)
    p = len(z)
    cov, se_method = covariance(prob, J, r)
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) if np.all(np.isfinite(cov)) else np.full(p, np.nan)
    on_bound = bool(nb_nl and (x_opt[0] <= vs_bounds[0] + 1e-3 or x_opt[0] >= vs_bounds[1] - 1e-3))
    return {"on_bound": on_bound, "lin": lin, "nonlin": nl, "decays": dec, "cov": cov, "se": se, "status": status,
            "sscale": sscale, "free": free, "se_method": se_method, "stop": stop}


def _direction_params(prob: _Problem, sol: dict) -> Direction:
    """Fitted values and standard errors of one direction."""
    basis = prob.basis
    lin, se, cov = sol["lin"], sol["se"], sol["cov"]
    nb = len(basis.lin)
    L = len(lin)
    P = Direction({})
    P.se_method = sol.get("se_method") or None
    for j, name in enumerate(basis.lin):
        P.set(name, float(lin[j]), float(se[j]))
    # nonlinear base parameters are fitted as logs: delta method
    for j, name in enumerate(basis.nonlin):
        val = float(sol["nonlin"][j])
        P.set(name, val, float(val * se[L + j]))
    free = list(sol["free"])
    for k, h in enumerate(prob.harmonics):
        ia, ic = nb + 2 * k, nb + 2 * k + 1
        a, c = lin[ia], lin[ic]
        a_se, p_se = (pair_se(a, c, cov[np.ix_([ia, ic], [ia, ic])]) if np.all(np.isfinite(cov))
                      else (float("nan"),) * 2)
        if k in free:
            decay_se = float(se[L + len(basis.nonlin) + free.index(k)] * sol["sscale"])
        else:
            decay_se = 0.0 if prob.amp_law[k] == "const" else float("nan")
        rng = [float(x) for x in prob.ranges[k]] if np.all(np.isfinite(prob.ranges[k])) else None
        P.harmonics.append(Harmonic(float(h["frequency"]), float(math.hypot(a, c)), float(sol["decays"][k]),
                                    float(math.atan2(c, a)),
                                    label=h.get("label") or None, law=prob.amp_law[k], speed_range=rng,
                                    segments=int(prob.stats.active[:, k].sum()),
                                    se={"amplitude": a_se, "phase": p_se, "decay": decay_se}))
    return P


def _fit_one_direction(sub: FitData, law: str, specs: list[dict], dname: str, *, weights, min_cycles, init, se,
                       bootstrap, seed, acc: bool = False):
    """One direction's fit: ``(parameters, not_identified, notes, inertia)``; ``acc``: the inertia
    is identified with the friction (``inertia``: its ``(value, se)``, else None)."""
    notes: list[str] = []
    ni: dict[str, str] = {}
    stats = segment_stats(sub, [h["frequency"] for h in specs], min_cycles=min_cycles, acc=acc)
    # harmonics that the segments do not cover by one cycle together cannot be identified: left out
    total = np.where(stats.active, stats.cycles, 0.0).sum(axis=0) if len(specs) else np.zeros(0)
    keep = [k for k in range(len(specs)) if total[k] >= 1.0]
    for k in range(len(specs)):
        if k not in keep:
            lab = specs[k].get("label") or f"{specs[k]['frequency']:.6g}"
            ni[f"{dname}.{lab}"] = (f"the {dname} segments cover {total[k]:.3g} of its cycles together (segments "
                                    f"with at least {min_cycles:g} cycle each); one cycle is "
                                    f"{1 / specs[k]['frequency']:.4g} {sub.unit} of travel")
    if len(keep) < len(specs):
        specs = [specs[k] for k in keep]
        stats = segment_stats(sub, [h["frequency"] for h in specs], min_cycles=min_cycles, acc=acc)
    specs = [dict(h) for h in specs]
    if len(sub.segments) and "kind" in sub.segments and bool((sub.segments["kind"] == "quasi_static").all()):
        return (*_quasi_static_direction(sub, segment_stats(sub, [h["frequency"] for h in specs],
                                                            min_cycles=min_cycles), law, specs, dname, ni, notes,
                                         weights), None)
    # a decay needs the line measured on its own (a whole cycle in a segment) at two speeds or more,
    # and an amplitude distinguishable from zero (below: :func:`_faint_lines_held`); else the line
    # keeps a constant amplitude (SILO4 eq. 6), said in not_identified (:mod:`.jointlines`)
    few_speeds(stats, specs, speed_ranges(stats), dname, ni)
    basis = _basis(law)
    distinct = len(np.unique(np.round(stats.speed, 9)))
    need = len(basis.lin) + len(basis.nonlin)
    if LAWS[law].needs_load:
        distinct_load = len(np.unique(np.round(stats.load, 9))) if stats.load is not None else 0
        if distinct_load < 2:
            raise ConvergenceError(f"law {law} needs points at two loads or more in the {dname} direction")
    if distinct < need - (1 if LAWS[law].needs_load else 0):
        raise ConvergenceError(f"law {law} has {need} parameters per direction but the {dname} direction has "
                               f"plateaus at only {distinct} speed(s); fit a simpler law "
                               f"(e.g. coulomb_viscous) or record more speeds")
    prob = _make_problem(stats, law, specs, weights, se=se, segments=sub.segments)
    try:
        prob = _faint_lines_held(prob, stats, law, specs, weights, se, sub, dname, ni, init)
        sol = _fit_direction(prob, init=init)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ConvergenceError(f"the {law} fit did not converge in the {dname} direction ({exc}); the lines "
                               f"asked for may be too close to each other or to the Nyquist frequency") from exc
    if sol["status"] <= 0:
        raise ConvergenceError(not_converged(law, dname, prob, sol["stop"], sol["nonlin"], sol["decays"],
                                               sub.unit))
    P = _direction_params(prob, sol)
    for h in P.harmonics:
        if np.isfinite(h.se["amplitude"]) and h.amplitude < SIGNIFICANT * h.se["amplitude"]:
            notes.append(f"{dname}: amplitude of {h.label or h.frequency} not significant "
                         f"({h.amplitude:.3g} +- {h.se['amplitude']:.2g})")
    if se == "bootstrap":
        _bootstrap_se(P, stats, law, specs, weights, bootstrap, seed)
    # parameters the data cannot pin down: a Stribeck velocity outside the plateau speeds.  Then
    # the Stribeck part is left out (None) and the rest refitted without it: the law degrades to
    # its Coulomb + viscous part over the measured speeds, and says so
    if basis.nonlin:
        lo, hi = float(np.min(stats.speed)), float(np.max(stats.speed))
        V = P.values
        rel = P.se["v_s"] / V["v_s"] if V["v_s"] > 0 else np.inf
        # the height of the Stribeck term must be there too: static minus Coulomb larger than its
        # error (either sign: Lola's Table IV has T_fS < T_f0, friction rising towards T_f0)
        top, base = ("tau_s", "tau_c") if "tau_s" in V else ("t_fs", "t_f0")
        hump = V[top] - V[base]
        weak = not (np.isfinite(P.se[top]) and P.se[top] < abs(hump))
        if sol["on_bound"] or not np.isfinite(rel) or rel > 1.0 or weak:
            why = (f"not identified by plateaus at {lo:.3g}..{hi:.3g} {sub.unit}/s (the fit went to v_s = "
                   f"{V['v_s']:.3g} {sub.unit}/s, relative standard error {rel:.2g}, hump {top} - {base} = "
                   f"{hump:.3g} +- {P.se[top]:.2g}); record slower plateaus")
            reduced = LAWS[law].degraded_for("v_s")
            prob = _make_problem(stats, reduced.name, specs, weights, se=se, segments=sub.segments)
            sol = _fit_direction(prob, init=init)
            P = _direction_params(prob, sol)
            for k in reduced.dropped:
                P.set(k, None, None)
                ni[f"{dname}.{k}"] = why
            notes.append(f"{dname}: Stribeck part of law {law} not identified; Coulomb + viscous part fitted alone")
    P.n_segments, P.n_samples = int(len(stats.speed)), int(np.sum(stats.n))
    j = len(sol["lin"]) - 1
    inertia = (float(sol["lin"][j]), float(sol["se"][j])) if acc else None
    return P, ni, notes, inertia


def _faint_lines_held(prob: _Problem, stats, law, specs, weights, se, sub, dname, ni, init) -> _Problem:
    """The problem with every line whose amplitude is not distinguishable from zero at fixed shapes
    (:func:`~.jointlines.faint_lines`) held at a constant amplitude, said in ``ni``."""
    faint = faint_lines(prob, _fit_direction, init)
    for k, (amp, a_se) in faint.items():
        hold_constant(specs[k], dname, ni, f"the line is not distinguishable from zero (amplitude {amp:.2g} +- "
                      f"{a_se:.2g} {'Nm' if sub.unit == 'rad' else 'N'} with its shape held, below {SIGNIFICANT:g} "
                      f"standard errors), so its decay is not identified")
    return _make_problem(stats, law, specs, weights, se=se, segments=sub.segments) if faint else prob


def _quasi_static_direction(sub: FitData, stats: SegmentStats, law: str, specs: list[dict], dname: str,
                            ni: dict, notes: list, weights):
    """One direction of a quasi-static map (every segment a sweep taken at rest): the level
    (``tau_c``, the direction offset) and the lines with constant amplitudes.  The speeds of the
    sweeps are nominal (travel over duration, at rest in between), so nothing that depends on
    speed (Stribeck, viscous, decay laws) is identifiable: those are None, with the reason."""
    quasi = LAWS[law].degraded_for("speed")
    if LAWS[law].needs_load or quasi is None:
        raise ConvergenceError(f"law {law} needs plateaus at several speeds and loads; the {dname} direction "
                               f"has quasi-static sweeps only (fit silo4, stribeck or coulomb_viscous)")
    why = (f"the {dname} direction has quasi-static sweeps only (rows taken at rest; their speed is nominal): "
           f"no speed dependence can be identified")
    for h in specs:
        if h.get("decay", True) is not False and h.get("law", "exp") != "const":
            ni[f"{dname}.{h.get('label') or format(h['frequency'], '.6g')}.decay"] = why + "; amplitude held constant"
        h["decay"] = False
    prob = _make_problem(stats, quasi.name, specs, weights)
    P = _direction_params(prob, _fit_direction(prob))
    for k in LAWS[law].params:
        if k not in P.values:
            P.set(k, None, None)
            ni[f"{dname}.{k}"] = why
    notes.append(f"{dname}: quasi-static map: level and lines only")
    P.n_segments, P.n_samples = int(len(stats.speed)), int(np.sum(stats.n))
    return P, ni, notes


def _bootstrap_se(P, stats: SegmentStats, law, specs, weights, B, seed):
    """Replace the standard errors by the spread of refits on segments resampled with replacement."""
    rng = np.random.default_rng(seed)
    S = len(stats.speed)
    base_names = list(_basis(law).lin) + list(_basis(law).nonlin)
    fits = []
    for _ in range(B):
        bs = stats.take(rng.integers(0, S, S))
        if len(np.unique(np.round(bs.speed, 9))) < len(base_names):
            continue
        try:
            prob = _make_problem(bs, law, specs, weights)
            fits.append(_direction_params(prob, _fit_direction(prob)))
        except (InputError, np.linalg.LinAlgError, ValueError):
            continue
    if len(fits) >= 10:
        for k in base_names:
            P.se[k] = float(np.std([Q.values[k] for Q in fits], ddof=1))
        for i, h in enumerate(P.harmonics):
            h.se["amplitude"] = float(np.std([Q.harmonics[i].amplitude for Q in fits], ddof=1))
            h.se["decay"] = float(np.std([Q.harmonics[i].decay for Q in fits], ddof=1))
            ph = np.angle(np.exp(1j * (np.asarray([Q.harmonics[i].phase for Q in fits]) - h.phase)))
            h.se["phase"] = float(np.sqrt(np.mean(ph ** 2)))
    P.se_method = f"bootstrap over segments ({B} resamples)"


# ---------------------------------------------------------------------- the estimator
class JointFit:
    """The joint fit of a friction law, per direction, as an estimator: settings in ``__init__``,
    learned values (trailing underscore) after :meth:`fit`.

    - ``law``: ``silo4`` (eq. 11: eq. 3 + harmonics), ``stribeck`` (eq. 3 alone), ``coulomb_viscous``,
      ``lola8``, ``lola11`` or ``none`` (harmonics only).  ``silo4`` fits the declared lines of
      ``gear`` unless ``harmonics`` says otherwise (:func:`~.stats.harmonic_specs`); the others fit
      ``harmonics`` only if given.
    - ``weights`` ("segment" or "uniform"): each segment weighted by the inverse of its own residual
      variance, or all samples alike.
    - ``se`` ("covariance", "independent" or "bootstrap"): standard errors from the cluster-robust
      covariance of the weighted fit over runs (CR2; over segments when the runs are too few, the
      covariance of independent samples when both are: :mod:`.covariance`, the method in each
      direction's ``se_method``), from the covariance of independent samples (``independent``:
      gearspec 0.5's ``covariance``, too small when runs scatter), or from ``bootstrap`` refits on
      segments resampled with replacement (``seed`` seeds them).
    - ``min_cycles``: a segment counts towards a harmonic where it covers at least this fraction of
      a cycle; the harmonic is identified when those segments cover one cycle together (a line too
      slow for any one segment, e.g. one joint turn, is fitted from many); every segment's level is
      modelled with the partial cycles of slow lines it contains.
    - ``holdout`` ("segment", "run" or None: skip): ``rmse_holdout`` by ``folds``-fold
      cross-validation over whole segments or runs, each fold refitted with :func:`refit`.
    - ``inertia`` ("auto", "fit" or "none"): identify the inertia ``J`` with the friction (the
      torque is modelled as friction + ``J thetadd``; an ``inertia`` term of the model, one value for
      both directions): "auto" when the data hold free motion and no inertia was removed from them.
    - ``init``: a model of starting values; ``name``: the model's (default: the law); ``check``:
      warn (:class:`~gearspec.errors.GearspecWarning`) about a negative viscous coefficient
      (:func:`negative_viscous`; flagged in the model either way).

    ``model_``: the FrictionModel, with ``rmse`` (in-sample, Nm), ``rmse_holdout``,
    ``not_identified`` and in ``meta["fit"]`` the settings :meth:`from_model` rebuilds the estimator
    from; ``harmonics_``: the lines fitted (``frequency`` in cycles per unit of theta, ``label``).
    """

    def __init__(self, law: str = "silo4", *, harmonics=None, gear=None, weights: str = "segment",
                 se: str = "covariance", bootstrap: int = 200, min_cycles: float = MIN_CYCLES,
                 holdout: str | None = "segment", folds: int = 5, init: FrictionModel | None = None, seed: int = 0,
                 name: str | None = None, check: bool = True, inertia: str = "auto"):
        self.law, self.harmonics, self.gear, self.weights, self.se = law, harmonics, gear, weights, se
        self.bootstrap, self.min_cycles, self.holdout, self.folds = bootstrap, min_cycles, holdout, folds
        self.init, self.seed, self.name, self.check, self.inertia = init, seed, name, check, inertia

    def get_params(self, deep: bool = False) -> dict:
        """The settings by name (``deep`` as in scikit-learn; no setting is itself an estimator)."""
        return {k: getattr(self, k) for k in _SETTINGS}

    def set_params(self, **params) -> "JointFit":
        """Change settings by name; returns the estimator."""
        for k in params:
            if k not in _SETTINGS:
                raise InputError(f"JointFit has no setting '{k}' (settings: {', '.join(_SETTINGS)})")
        for k, v in params.items():
            setattr(self, k, v)
        return self

    @classmethod
    def from_model(cls, model: FrictionModel) -> "JointFit":
        """An unfitted estimator with the settings ``model`` was fitted with (its ``meta["fit"]``, as
        :meth:`fit` writes it) and its name; a file without ``min_cycles`` was fitted with 1 cycle."""
        s = model.meta.get("fit") or {}
        if not s or s.get("method"):
            raise InputError("this model carries no fit settings (it was not made by gearspec.identify.fit)")
        # the lines are recorded as fitted: none recorded means none (not the gear's declared lines)
        lines = s.get("harmonics") or ([] if s["law"] == "silo4" else None)
        return cls(s["law"], harmonics=lines, weights=s.get("weights", "segment"), se=s.get("se", "covariance"),
                   bootstrap=s.get("bootstrap", 200), min_cycles=s.get("min_cycles", 1.0), name=model.name,
                   inertia=s.get("inertia", "auto"))

    @on_one_blas_thread
    def fit(self, data: FitData) -> "JointFit":
        """Fit the law to ``data`` (samples in constant-speed segments, ``velocity="segment"``, or
        quasi-static points), each direction on its own (BLAS on one thread); returns the estimator."""
        law = self.law
        if law not in LAWS:
            raise InputError(f"unknown friction law '{law}' (known: {', '.join(LAWS)})")
        if self.se not in SE_METHODS:
            raise InputError(f"se must be one of {', '.join(SE_METHODS)}, got '{self.se}'")
        if LAWS[law].needs_load and data.load is None:
            raise InputError(f"law {law} needs the output load torque: the data has no 'load' channel")
        if law == "silo4" and self.harmonics is None:
            specs = harmonic_specs(None, self.gear)
            if not specs:
                _warn("law silo4 without a gear spec or harmonics: fitting eq. 3 only" if self.gear is None else
                      f"law silo4: the gear spec '{getattr(self.gear, 'name', self.gear)}' declares no line and no "
                      f"harmonics (--lines) were given: fitting eq. 3 only")
        else:
            specs = harmonic_specs(self.harmonics, self.gear) if self.harmonics is not None else []
        acc = self._identifies_inertia(data)
        directions, not_identified, notes, inertias = self._directions(data, law, specs, acc)
        terms = []
        if acc:
            # one inertia for both directions (the mean of the two, weighted by their errors); the
            # friction refitted with it held; its standard errors are those of the fit with the
            # inertia free, so that they carry its uncertainty
            J, J_se, note = _common_inertia(inertias, data.unit)
            held = replace(data, y=data.y - J * np.nan_to_num(data.acc), inertia=J, notes=list(data.notes), cache={})
            free_fit = directions
            directions, not_identified, notes, _ = self._directions(held, law, specs, False)
            for dname, P in directions.items():
                _carry_se(free_fit[dname], P)
            notes.append(note)
            terms = [{"kind": "inertia", "inertia": J, "inertia_se": J_se}]
        settings = {"law": law, "harmonics": specs, "weights": self.weights, "se": self.se,
                    "min_cycles": self.min_cycles, "bootstrap": self.bootstrap, "inertia": self.inertia}
        model = FrictionModel(law, directions["positive"], directions["negative"], unit=data.unit, terms=terms,
                              not_identified=not_identified, notes=notes, name=self.name or law,
                              meta={"fit": settings})
        if getattr(self, "_predict_only", False):
            # a held-out fold's model (:func:`fold_fit`): only its predictions are read
            self.harmonics_, self.model_ = specs, model
            return self
        model.rmse = _safe_rmse(model, data)
        flags = inverted_sign(model, data) + negative_viscous(model, data)
        if self.check:
            for msg in flags:
                _warn(msg)
        if self.holdout:
            model.rmse_holdout, model.rmse_holdout_reason = holdout(
                lambda tr: fold_fit(model, tr), data, by=self.holdout, folds=self.folds)
        self.harmonics_, self.model_ = specs, model
        return self

    def _identifies_inertia(self, data: FitData) -> bool:
        """Whether the inertia is identified with the friction: ``inertia="auto"`` when the data
        hold free motion (blocks whose acceleration varies) and no inertia was removed from them."""
        if self.inertia not in ("auto", "fit", "none"):
            raise InputError(f"inertia must be 'auto', 'fit' or 'none', got '{self.inertia}'")
        if self.inertia == "none" or not data.has("acc"):     # (a fold's accelerations are not copied to ask)
            return False
        if self.inertia == "fit":
            return True
        return data.free_motion and data.inertia is None

    def _directions(self, data: FitData, law: str, specs: list[dict], acc: bool):
        """Both directions fitted: ``(directions, not_identified, notes, inertias)``."""
        directions: dict[str, Direction] = {}
        not_identified: dict[str, str] = {}
        notes: list[str] = []
        inertias: dict[str, tuple] = {}
        # blocks of free motion are too short for their own residual variance to weight them
        weights = "uniform" if data.free_motion and self.weights == "segment" else self.weights
        for d, dname in ((1, "positive"), (-1, "negative")):
            sub = data.direction_subset(d)
            if len(sub) == 0:
                directions[dname] = Direction.of(LAWS[law], {})
                for k in list(LAWS[law].params) + [h.get("label") or h["frequency"] for h in specs]:
                    not_identified[f"{dname}.{k}"] = f"no segment in the {dname} direction"
                continue
            try:
                directions[dname], ni, nt, J = _fit_one_direction(
                    sub, law, specs, dname, weights=weights, min_cycles=self.min_cycles, se=self.se,
                    init=None if self.init is None else self.init.params(dname), bootstrap=self.bootstrap,
                    seed=self.seed, acc=acc)
            except np.linalg.LinAlgError as exc:  # an SVD or eigen-solver that does not converge: one sentence
                raise ConvergenceError(f"the {law} fit did not converge in the {dname} direction ({exc}) with "
                                       f"{len(specs)} lines; fit fewer lines (--lines) or a simpler law") from exc
            not_identified.update(ni)
            notes += nt
            if J is not None:
                inertias[dname] = J
        return directions, not_identified, notes, inertias


#: the settings of :class:`JointFit`, in the order of its ``__init__``
_SETTINGS = tuple(inspect.signature(JointFit.__init__).parameters)[1:]


def clone(estimator: JointFit) -> JointFit:
    """A new, unfitted estimator with copies of the settings of ``estimator``."""
    return type(estimator)(**copy.deepcopy(estimator.get_params()))


def fold_fit(model: FrictionModel, data: FitData) -> FrictionModel:
    """``refit(model, data, holdout=None)`` for a held-out fold (of :meth:`JointFit.fit`, of the
    explorer's reference laws), whose model is only asked for its predictions: the same parameters,
    without the in-sample rmse and the checks' flags (which nobody reads; said once per fold)."""
    est = JointFit.from_model(model).set_params(se="covariance", check=False, holdout=None)
    est._predict_only = True
    return est.fit(data).model_


def _warn(message: str) -> None:
    """A :class:`GearspecWarning` attributed to the first caller outside this module (of :func:`fit`
    or of :meth:`JointFit.fit`)."""
    frame, level = sys._getframe(1), 2
    while frame is not None and frame.f_globals.get("__name__") == __name__:
        frame, level = frame.f_back, level + 1
    warnings.warn(message, GearspecWarning, stacklevel=level)


def fit(data: FitData, law: str = "silo4", **settings) -> FrictionModel:
    """Fit a friction law to samples, jointly per direction: ``JointFit(law, **settings).fit(data).model_``
    (the settings and the model: :class:`JointFit`)."""
    return JointFit(law, **settings).fit(data).model_


def refit(model: FrictionModel, data: FitData, **overrides) -> FrictionModel:
    """Fit ``model``'s law and lines again, to other data, with the settings it was fitted with
    (:meth:`JointFit.from_model`; covariance standard errors, no warnings) changed by ``overrides``
    (settings of :class:`JointFit`).  A model of :func:`~.efficiency.fit_efficiency` is refitted
    to efficiency, with ``holdout`` the only override it takes."""
    s = model.meta.get("fit") or {}
    if s.get("method") == "efficiency":
        from .efficiency import fit_efficiency

        return fit_efficiency(data, s["law"], ratio=s["ratio"], holdout=overrides.get("holdout"), name=model.name)
    return JointFit.from_model(model).set_params(**{"se": "covariance", "check": False, **overrides}).fit(data).model_
