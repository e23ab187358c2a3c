"""A FrictionModel as the closed loop's blocks (:func:`state_from_model`) and its prediction on
any data (:func:`predict_model`), coefficients read from the model."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..model import LAWS, FrictionModel
from ..terms import TERM_LINEAR
from .data import DiagnoseData
from .design import LINEAR, BaseBlock, Block, HarmonicBlock, State, TermBlock

__all__ = ["state_from_model", "predict_model"]


def state_from_model(model: FrictionModel, dd: DiagnoseData, *, symmetric: bool | None = None,
                     keep_ranges: bool = False) -> State:
    """The blocks of a FrictionModel: its base law (per direction, or shared when the model is
    symmetric), every harmonic (paired across directions by frequency) and every term of a kind
    the loop fits (:data:`TERM_LINEAR`); nonlinear parameters as the model has them.
    ``keep_ranges``: the lines keep the model's speed ranges (evaluating a fitted model); by
    default a refit takes the speeds at which ``dd`` measures each line."""
    law = model.law
    if law not in LINEAR:
        raise InputError(f"the closed loop cannot refit law '{law}'")
    present = dd.directions()
    if symmetric is None:
        symmetric = model.symmetric and len(present) == 2
    blocks: list[Block] = []
    lin_names, nonlin_names = LINEAR[law]

    degraded = LAWS[law].degraded_for("v_s")

    def lin_of(p):
        if any(p.values.get(k) is None for k in nonlin_names) and degraded is not None:
            return degraded.linear
        return lin_names

    if law != "none":
        # one parameter set (key 0) for both directions, or one per direction with its base law identified
        P = {0: model.directions["positive"]} if symmetric else {d: model.params(d) for d in present}
        keys = (0,) if symmetric else tuple(d for d in present if all(P[d].values.get(k) is not None
                                                                     for k in lin_names if k in lin_of(P[d])))
        blocks.append(BaseBlock(key="base", law=law, dirs=tuple(present) if symmetric else keys, symmetric=symmetric,
                                lin=tuple((d, lin_of(P[d])) for d in keys),
                                nonlin=tuple((d, {k: P[d].values.get(k) for k in nonlin_names}) for d in keys)))
    lines: list = []     # (frequency, {direction: harmonic}): the harmonics paired by frequency
    for d in present:
        for h in model.harmonics(d):
            if h.amplitude is not None:
                per = next((x for f, x in lines if math.isclose(h.frequency, f, rel_tol=1e-9)), None)
                if per is None:
                    lines.append((float(h.frequency), {d: h}))
                else:
                    per[d] = h
    for f, per in lines:
        dirs = tuple(sorted(per, reverse=True))
        load_phase = tuple((d, float(per[d].phase or 0.0)) for d in dirs if per[d].load_coefficient)
        if symmetric:
            per = {0: next(iter(per.values()))}
            load_phase = ((0, load_phase[0][1]),) if load_phase else ()
        keys = tuple(per) if symmetric else dirs
        rng = tuple((d, tuple(per[d].speed_range)) for d in keys if per[d].speed_range) if keep_ranges else ()
        blocks.append(HarmonicBlock(key=f"line {f:.6g}", frequency=f, label=per[keys[0]].label, dirs=dirs,
                                    symmetric=symmetric, law=tuple((d, per[d].amplitude_law) for d in keys),
                                    decay=tuple((d, float(per[d].decay or 0.0)) for d in keys),
                                    load_phase=load_phase, speed_range=rng))
    for t in model.terms:
        kind = t["kind"]
        if kind not in TERM_LINEAR:
            raise InputError(f"the closed loop cannot refit a '{kind}' term")
        lin = TERM_LINEAR[kind]
        drop = {"kind", "direction", "label", "effect_kind"} | ({"amplitude", "phase"} if lin == "trig" else {lin})
        fixed = tuple((k, v) for k, v in t.items() if k not in drop and not k.endswith("_se"))
        blocks.append(TermBlock(key=f"term {kind}", kind=kind, fixed=fixed, direction=int(t.get("direction", 0) or 0),
                                label=t.get("label"), effect_kind=t.get("effect_kind")))
    return State(blocks, model, symmetric)


def predict_model(model: FrictionModel, dd: DiagnoseData) -> np.ndarray:
    """A model's drive torque at the observations of ``dd`` (evaluated per sample, reduced like
    the data; presliding and backlash from the travel since the last reversal)."""
    st = state_from_model(model, dd, symmetric=False, keep_ranges=True)
    if not st.blocks:
        return np.zeros(len(dd))
    # coefficients as the model has them: fit nothing, read them back
    return np.column_stack([b.columns(dd) for b in st.blocks]) @ np.concatenate([_model_coefs(b, model)
                                                                                for b in st.blocks])


def _model_coefs(blk: Block, model: FrictionModel) -> np.ndarray:
    if isinstance(blk, BaseBlock):
        return np.array([float(model.params(d).values[k]) for d in blk.dirs for k in blk._lin(d)])
    if isinstance(blk, HarmonicBlock):
        out = []
        for d in blk.dirs:
            h = next(h for h in model.harmonics(d) if math.isclose(h.frequency, blk.frequency, rel_tol=1e-9))
            A, ph = float(h.amplitude), float(h.phase)
            out += [A * math.cos(ph), A * math.sin(ph)]
            if d in dict(blk.load_phase):
                out.append(float(h.load_coefficient or 0.0))
        return np.array(out)
    t = next(t for t in model.terms if blk.matches(t))
    lin = TERM_LINEAR[blk.kind]
    if lin == "trig":
        A, ph = float(t["amplitude"]), float(t.get("phase", 0.0))
        return np.array([A * math.cos(ph), A * math.sin(ph)])
    return np.array([float(t[lin])])
