"""What the candidates of one round of the closed loop read: the round's context (:class:`Round`),
read-only; the training sums and coefficients of a fold are cached (a round asks for them often).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.crossval import held_out
from . import budget
from .data import DiagnoseData
from ..core.reduction import GroupNormals, group_normal_equations, normal_equations
from . import gram
from .chunked import Design, design_of
from .design import FittedState, HarmonicBlock, State, fit_state, solve_normal
from .nonlinear import nonlinear_standard_errors

__all__ = ["Round", "group_normals"]

#: groups of at least this many observations on average are reduced one by one (BLAS): the
#: batched outer products of :func:`~gearspec.core.reduction.group_normal_equations` cost
#: rows x p^2 element operations, several times a BLAS product of plateau-sized groups
BLAS_GROUP_ROWS = 256
#: a group of a :class:`~.chunked.Design` with more rows than this many chunks
#: (:data:`~.gram.CHUNK_ROWS`) is reduced a chunk of rows at a time, shorter ones whole
STACK_GROUP_CHUNKS = 4


def group_normals(X, y: np.ndarray, starts, stops) -> GroupNormals:
    """:class:`~gearspec.core.reduction.GroupNormals` of the columns ``X`` (n, p; an array or a
    :class:`~.chunked.Design`) and ``y`` (n,) over the contiguous groups ``[starts[g], stops[g])``:
    by one BLAS product per group (:func:`~gearspec.core.reduction.normal_equations`) when the groups
    hold :data:`BLAS_GROUP_ROWS` rows or more on average (plateaus, runs), else
    :meth:`GroupNormals.of` (thousands of short free-motion blocks; of a Design, on its rows stacked
    for runs of whole groups of at most :data:`~.gram.CHUNK_ROWS` rows).  The same numbers up to
    round-off either way."""
    starts, stops = np.asarray(starts), np.asarray(stops)
    n = stops - starts
    if not len(n) or float(np.mean(n)) < BLAS_GROUP_ROWS:
        if not isinstance(X, Design):
            return GroupNormals.of(X, y, starts, stops)
        p = X.shape[1]
        G, b, yy = np.zeros((len(n), p, p)), np.zeros((len(n), p)), np.zeros(len(n))
        g = 0
        while g < len(n):
            # a run of whole groups of at most CHUNK_ROWS rows (at least one group)
            h = g + max(int(np.searchsorted(np.cumsum(n[g:]), gram.CHUNK_ROWS, side="right")), 1)
            a, z = int(starts[g]), int(stops[h - 1])
            G[g:h], b[g:h], yy[g:h] = group_normal_equations(np.asarray(X[a:z]), y[a:z], starts[g:h] - a,
                                                             stops[g:h] - a)
            g = h
        return GroupNormals(G, b, yy, n)
    p = X.shape[1]
    G, b, yy = np.empty((len(n), p, p)), np.empty((len(n), p)), np.empty(len(n))
    for g, (a, z) in enumerate(zip(starts, stops)):
        if isinstance(X, Design) and z - a > STACK_GROUP_CHUNKS * gram.CHUNK_ROWS:
            # a long group (a run held out whole) of a Design: summed a chunk of rows at a time
            G[g], b[g], yy[g] = 0.0, 0.0, 0.0
            for c, e in gram.spans([a], [z]):
                Gc, bc, yc = normal_equations(np.asarray(X[c:e]), y[c:e])
                G[g] += Gc
                b[g] += bc
                yy[g] += yc
            continue
        G[g], b[g], yy[g] = normal_equations(np.asarray(X[a:z]), y[a:z])
    return GroupNormals(G, b, yy, n)


@dataclass(frozen=True, eq=False)
class Round:
    """The model as it stands (``state``: its blocks, kept refreshed with the coefficients fitted
    on all data) on the observations ``dd`` (torque in Nm), with the fold of every held-out group
    (``fold``).  Derived: ``fitted`` (the fit on all data), ``X`` (the design with the Taylor
    columns of every nonlinear parameter), ``grams`` (its per-group normal equations), ``ref_diag``
    (the diagonal of those of all data: :func:`solve_normal`'s reference), ``K`` (folds) and
    ``keys`` (of the model's blocks: ``"hysteresis"``, ``"viscous_power+"``, ...)."""

    dd: DiagnoseData = field(repr=False)
    state: State = field(repr=False)
    fold: np.ndarray = field(repr=False)
    #: the standard errors of the nonlinear parameters (``fitted.nonlinear_se``); False for a round
    #: only a candidate's held-out folds read (the extended model of :func:`~.loop._run_folds`)
    standard_errors: bool = field(default=True, repr=False)
    fitted: FittedState = field(init=False, repr=False)
    grams: GroupNormals = field(init=False, repr=False)
    ref_diag: np.ndarray = field(init=False, repr=False)
    K: int = field(init=False)
    keys: frozenset = field(init=False, repr=False)
    _sums: dict = field(init=False, repr=False, default_factory=dict)
    _beta: dict = field(init=False, repr=False, default_factory=dict)
    #: what every candidate of the round reads alike: channels at the observations, the held-out
    #: prediction of the model as it stands, the training residual of a fold (:meth:`train_residual`)
    _memo: dict = field(init=False, repr=False, default_factory=dict)
    #: ``[X or None, columns of X]`` (:attr:`X`, :meth:`release_design`)
    _design: list = field(init=False, repr=False, default_factory=lambda: [None, 0])

    def __post_init__(self):
        dd = self.dd
        # the designs as their blocks' columns, never stacked (:class:`~.chunked.Design`)
        fitted = fit_state(self.state, dd, X=design_of(self.state, dd))
        state = fitted.state = self.state.refreshed(fitted.coef)
        # the held-out fits use the Taylor columns of every nonlinear parameter as well
        X = design_of(state, dd, taylor=True)
        grams = group_normals(X, dd.y, dd.starts, dd.stops)
        G_all, b_all, _ = grams.sum()
        if self.standard_errors:
            fitted.nonlinear_se = nonlinear_standard_errors(state, dd, X.blocks, G_all, b_all)
        self._design[:] = [X, X.shape[1]]
        for name, value in (("state", state), ("fitted", fitted), ("grams", grams),
                            ("ref_diag", np.diag(G_all).copy()), ("K", int(self.fold.max()) + 1),
                            ("keys", frozenset(b.key for b in state.blocks))):
            object.__setattr__(self, name, value)

    @property
    def X(self) -> Design:
        """The design with the Taylor columns of every nonlinear parameter (rows x columns), as its
        blocks' columns (:class:`~.chunked.Design`: rows read by ranges, products a chunk of rows at
        a time, never stacked), built again (the same arrays) when :meth:`release_design` let it go."""
        if self._design[0] is None:
            self._design[0] = design_of(self.state, self.dd, taylor=True)
        return self._design[0]

    def design_bytes(self) -> int:
        """Bytes the arrays of :attr:`X` hold (lazy columns, :mod:`.rowcols`, hold none; a design let
        go counts as the rows x columns it had)."""
        X = self._design[0]
        return int(X.nbytes) if X is not None else 8 * len(self.dd) * self.width

    @property
    def width(self) -> int:
        """Columns of :attr:`X` (without building it)."""
        return self._design[1]

    def release_design(self) -> bool:
        """Let :attr:`X` go when it holds more than :data:`~.budget.DESIGN_BYTES` (a long recording:
        a candidate's extended round then holds its own design, not both at once); it is built
        again when asked for.  What the held-out tests read from it is kept (:meth:`held_out_residual`).
        Whether it was let go."""
        X = self._design[0]
        if X is None or X.nbytes <= budget.DESIGN_BYTES:
            return False
        self.held_out_residual()
        self._design[0] = None
        return True

    def key(self, train: np.ndarray) -> bytes:
        """A hashable key of a boolean mask over the groups."""
        return np.packbits(train).tobytes()

    def train_sums(self, train: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """``(X^T X, X^T y, y^T y)`` summed over the groups where ``train`` is true."""
        k = self.key(train)
        if k not in self._sums:
            self._sums[k] = self.grams.sum(train)
        return self._sums[k]

    def beta(self, train: np.ndarray) -> np.ndarray:
        """Coefficients of ``X`` fitted on the groups where ``train`` is true."""
        k = self.key(train)
        if k not in self._beta:
            G, b, _ = self.train_sums(train)
            self._beta[k] = solve_normal(G, b, reference=self.ref_diag)
        return self._beta[k]

    def channel(self, name: str) -> np.ndarray | None:
        """A channel at the observations (:meth:`DiagnoseData.at`), read once per round (every
        candidate reads the same); ``"speed"``: ``|v|``.  Read-only: do not write into it."""
        key = ("channel", name)
        if key not in self._memo:
            a = np.abs(self.dd.at("v")) if name == "speed" else self.dd.at(name)
            if a is not None:
                a.flags.writeable = False
            self._memo[key] = a
        return self._memo[key]

    def held_out_prediction(self) -> np.ndarray:
        """The prediction of the model as it stands at every observation, fitted on the folds
        without it (Nm): :meth:`baseline_holdout`'s, the same for every candidate of the round
        (do not write into it)."""
        return self.baseline_holdout()["prediction"]

    def held_out_residual(self) -> np.ndarray:
        """``y -`` :meth:`held_out_prediction` (Nm): one array shared by every candidate's test of
        the round (rows x candidates on a long recording otherwise; read-only)."""
        if "holdout_residual" not in self._memo:
            r0 = self.dd.y - self.held_out_prediction()
            r0.flags.writeable = False
            self._memo["holdout_residual"] = r0
        return self._memo["holdout_residual"]

    def train_residual(self, train: np.ndarray) -> np.ndarray:
        """``y - X beta(train)`` at the observations of the groups ``train`` (Nm, in their order),
        group by group on views of ``X`` (no copy of its rows); the last few kept (read-only)."""
        key = ("r0", self.key(train))
        hit = self._memo.get(key)
        if hit is None:
            beta = self.beta(train)
            dd = self.dd
            parts = [dd.y[a:z] - self.X[a:z] @ beta for a, z in zip(dd.starts[train], dd.stops[train])]
            hit = np.concatenate(parts) if parts else np.zeros(0)
            hit.flags.writeable = False
            old = [k for k in self._memo if k[0] == "r0"]
            if len(old) >= self.K + 1:          # the folds' and all data's: a round asks for no others
                del self._memo[old[0]]
            self._memo[key] = hit
        return hit

    def rows(self, train_groups: np.ndarray) -> np.ndarray:
        """Observations (boolean) of the groups where ``train_groups`` is true (the folds' and all
        data's kept for the round; read-only)."""
        key = ("rows", self.key(train_groups))
        hit = self._memo.get(key)
        if hit is None:
            hit = train_groups[self.dd.group]
            hit.flags.writeable = False
            if sum(1 for k in self._memo if k[0] == "rows") < 2 * self.K + 2:   # a fold's, its complement, all
                self._memo[key] = hit
        return hit

    def taylor_spans(self) -> list[tuple[int, int]]:
        """Columns ``[a, z)`` of every block in ``X`` (its plain and Taylor columns), computed once."""
        if "spans" not in self._memo:
            self._memo["spans"] = self.state.spans(self.dd, taylor=True)
        return self._memo["spans"]

    def all_groups(self) -> np.ndarray:
        """Every group (boolean mask)."""
        return np.ones(self.dd.n_groups, bool)

    def keep_mask(self, drop) -> np.ndarray:
        """Columns of ``X`` that stay when the blocks ``drop`` (blocks or uids) go."""
        keep = np.ones(self.width, bool)
        uids = {getattr(d, "uid", d) for d in drop}
        for blk, (a, z) in zip(self.state.blocks, self.taylor_spans()):
            if blk.uid in uids:
                keep[a:z] = False
        return keep

    def line_phases(self, blk: HarmonicBlock) -> tuple:
        """``((direction, phase in rad), ...)`` of a line of the model, fitted on all data."""
        i = next(i for i, b in enumerate(self.state.blocks) if b.uid == blk.uid)
        a, _ = self.state.spans()[i]
        coef = self.fitted.coef
        out, j = [], a
        for d in ((0,) if blk.symmetric else blk.dirs):
            out.append((d, float(math.atan2(coef[j + 1], coef[j]))))
            j += 2 + (1 if d in dict(blk.load_phase) else 0)
        return tuple(out)

    def lines(self) -> list[HarmonicBlock]:
        """The lines of the model."""
        return [b for b in self.state.blocks if isinstance(b, HarmonicBlock)]

    def baseline_holdout(self) -> dict:
        """Held-out sums of squares of the model as it stands, per group (Nm^2), its held-out
        prediction at every observation (Nm) and its held-out rmse (Nm), folds as
        :func:`gearspec.core.crossval.held_out` runs them: ``{"sse", "prediction", "rmse"}``."""
        hit = self._memo.get("holdout")
        if hit is None:
            dd = self.dd
            pred = np.zeros(len(dd))

            def score(beta, test):
                # group by group on views of X (no copy of its rows)
                out = []
                for a, z in zip(dd.starts[test], dd.stops[test]):
                    pred[a:z] = self.X[a:z] @ beta
                    r = dd.y[a:z] - pred[a:z]
                    out.append(float(r @ r))
                return out

            ho = held_out(self.fold, self.beta, score, weight=dd.stops - dd.starts, catch=())
            hit = self._memo["holdout"] = {"sse": ho.sse, "prediction": pred, "rmse": ho.rmse}
        # the round's model does not change: the same numbers every time it is asked (a step's
        # guard, the next round's "before", the final model)
        return dict(hit)
