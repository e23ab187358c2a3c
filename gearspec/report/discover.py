"""The report of ``gearspec discover``: the laws found, their held-out errors against complexity,
the selected law with standard errors, inclusion probabilities, and the papers' laws beside."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..plots.discover import plot_inclusion, plot_levels, plot_pareto
from . import bullets, header, markdown_table, report_dir, write_report

__all__ = ["write_discover_report"]


def write_discover_report(result, rec, out, command: str = "") -> Path:
    """Write ``report.md``, ``pareto.png``, ``levels.png``, ``inclusion.png``, ``candidates.csv`` and
    ``comparison.csv`` into ``out``."""
    out = report_dir(out)
    M = result.moments
    tu = result.torque_unit
    unit = result.unit
    figs = {"pareto": plot_pareto(result, out / "pareto.png"), "levels": plot_levels(result, out / "levels.png"),
            "inclusion": plot_inclusion(result, out / "inclusion.png")}
    cand = pd.DataFrame([{"selected": "->" if i == result.selected else "", "complexity": c.complexity,
                          f"held-out RMSE ({tu})": c.rmse_holdout, f"RMSE ({tu})": c.rmse, "AIC": c.aic,
                          "BIC": c.bic, "law": c.equation} for i, c in zip(result.front, result.front_candidates())])
    cand.to_csv(out / "candidates.csv", index=False)
    comp = result.comparison()
    comp.to_csv(out / "comparison.csv", index=False)

    md = header("gearspec discover report", command) + ["## Data", ""]
    if rec is not None:
        md += ["```", rec.summary(), "```", ""]
    md += [f"{M.N} samples in {M.S} constant-speed segments ({', '.join(_dirs(M))}); speeds "
           f"{M.speed.min():.4g} to {M.speed.max():.4g} {unit}/s. Held-out errors: {result.settings['folds']}-fold "
           f"cross-validation over whole {result.settings['by']}s (never interleaved samples).", ""]
    if len(M.frequencies):
        md += ["Ripple lines in the library (cycles per " + unit + " of theta):", ""]
        md += [markdown_table(pd.DataFrame({"frequency": M.frequencies,
                                            "label": [lab or "" for lab in M.labels],
                                            "most cycles in a segment": M.cycles.max(axis=0)}), ".6g"), ""]
    else:
        md += ["No ripple line in the library (none declared, none found, or no positions).", ""]
    md += ["Library: " + result.library.describe() + ".", ""]

    sel = result.best
    md += ["## Selected law", "", "```", sel.equation, "```", "",
           f"Held-out RMSE {sel.rmse_holdout:.5g} {tu}, in-sample RMSE {sel.rmse:.5g} {tu}, complexity "
           f"{sel.complexity}. `(a | b)`: value for positive | negative motion; friction has the sign of v; "
           f"`a` is the acceleration. Rule: the search proposes the simplest law whose held-out error exceeds the "
           f"best one's by at most {result.settings['se_rule']:g} standard errors of the noise in that difference; "
           f"every term of it must then pass the closed loop's held-out test (Z against the law without it, "
           f"level {result.settings.get('test_alpha', 0.01):g} over {result.settings.get('acceptance_candidates', 1)} "
           f"candidates, Bonferroni; rmse gain at least the minimum) or it is simplified away." + _rounds(result), ""]
    md += _acceptance_section(result)
    coef = _coefficients(sel, M.frequencies)
    md += [markdown_table(coef), "", f"Standard errors: {sel.fit.se_method or 'n/a'}.", ""]
    if coef["at bound"].astype(bool).any():
        md += ["Parameters marked *at bound* ended at the edge of the range the plateau speeds can identify "
               "(Stribeck velocities from a fifth of the lowest to half the highest speed; decays from a 5 % to "
               "an e^-20 fall over the speeds): the data say the effect lies beyond the measured speeds, not "
               "where.", ""]
    md += ["## Pareto front: held-out error against complexity", "", f"![pareto]({figs['pareto'].name})", "",
           markdown_table(cand, ".5g"), ""]
    # the laws on either side of the selection, with their coefficients
    k = result.front.index(result.selected)
    near = [i for i in result.front[max(k - 2, 0):k + 3] if i != result.selected]
    if near:
        md += ["### Neighbours of the selected law on the front", ""]
        for i in near:
            c = result.candidates[i]
            md += [f"Complexity {c.complexity}, held-out RMSE {c.rmse_holdout:.5g} {tu}:", "", "```", c.equation,
                   "```", "", markdown_table(_coefficients(c, M.frequencies)), "",
                   f"Standard errors: {c.fit.se_method or 'n/a'}.", ""]
    md += ["## Compared with the papers' laws and published models", "",
           "Papers' laws fitted by `gearspec.identify.fit` (ordinary least squares, per direction) on the same "
           "folds as the candidates; published models scored as they are. `delta_mse`: held-out mean squared "
           "error minus the selected law's, with its standard error over held-out groups.", "",
           markdown_table(comp, ".5g"), "", f"![levels]({figs['levels'].name})", ""]
    md += ["## Inclusion probabilities", ""]
    if figs["inclusion"] is not None:
        md += [f"For each term of the selected law: the fraction of {result.settings['n_models']} bootstrap "
               f"replicates (whole {result.settings['by']}s resampled) in which the sparse regression selects a "
               "term of its slot (any of its shapes, either direction variant), at the largest threshold of each "
               "stage's path that selects as many terms as the law has there. Terms the law does not hold are not "
               "shown: the held-out test rejected them.", "",
               f"![inclusion]({figs['inclusion'].name})", "",
               markdown_table(result.inclusion.head(25)[["term", "family", "variant", "probability", "stage"]]), ""]
    else:
        md += ["_Not computed (--bootstrap 0)._", ""]
    md += ["## Method", "",
           "1. **Exact reduction.** Within a segment the speed is constant, so every library column is a "
           "per-segment multiplier times one of a few sample bases (1, |load|, temperature, acceleration, "
           "sin/cos of each ripple line). One pass over the samples stores each segment's Gram matrix of those "
           "bases as pseudo rows; every regression, cross-validation and bootstrap below works on them and is "
           "exactly what it would be on the samples.",
           "2. **Sparse regression.** pysindy's " + result.settings["optimizer"].upper() + " on standardised "
           "columns over a path of thresholds: first the friction level (every segment's ripple profiled out by "
           "its own sin/cos fit), then the ripple terms with the level law held in, then the level again with "
           "the ripple held in. Each support becomes a law with one term per slot (one Stribeck shape, one "
           "amplitude law per line), direction-dependent where an asym column was selected.",
           "3. **Refinement and search.** Stribeck velocities and decay constants are refined by nonlinear "
           "least squares (variable projection); a hill climb on held-out error adds, drops, splits by "
           "direction or reshapes terms around the best law.",
           "4. **Selection.** Held-out errors from refits on the other folds; the simplest law within the "
           "standard-error margin of the best is proposed; AIC and BIC are shown beside (they assume independent "
           "samples).",
           "5. **Acceptance.** The closed loop's rule (`gearspec diagnose`): every term of the proposed law must "
           "pass the held-out Z test against the law without it (or without its direction dependence, or with a "
           "constant ripple amplitude), Bonferroni over the candidates a search round tries, with a minimum rmse "
           "gain; the weakest failing term is simplified first. With `--validate`, the same check on the "
           "independent recording.", ""]
    md += bullets(result.notes, "Notes:")
    return write_report(out, md + ["Timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in result.timings.items()), ""])


def _rounds(result) -> str:
    """How the search's selection ended (rounds of refitting the selected law's simplifications)."""
    n = result.settings.get("selection_rounds")
    if not n:
        return ""
    if result.settings.get("selection_settled"):
        return (f" The search's selection settled after {n} round(s): every simplification of the law it proposes "
                "was refitted on the held-out folds and the rule selects that law again.")
    return f" The search's selection did not settle within {n} rounds; the last law it selected was proposed."


def _acceptance_section(result) -> list:
    """The acceptance test's verdict on every term, and the line screen's on every line."""
    md: list = []
    if result.acceptance:
        md += ["### The acceptance test of each term", "",
               markdown_table(pd.DataFrame([{"term": a["term"], "tested against": "without " + a["move"],
                                             "data": a["data"], "Z": a["z"], "Z needed": a["z_crit"],
                                             "rmse gain (%)": 100 * a["gain"],
                                             "decision": "accepted" if a["passed"] else "rejected"}
                                            for a in result.acceptance]), ".3g"), ""]
    if result.lines:
        md += ["### Ripple lines screened", "",
               "Each line offered (declared by the gear, found by the spectrum, given) is tested on its own by "
               "the held-out Z (each segment's level profiled out), then beside the stronger lines; only those "
               "that pass enter the library.", "",
               markdown_table(pd.DataFrame([{"frequency": ln["frequency"], "source": ln.get("source"),
                                             "label": ln.get("label") or "", "Z": ln["z"], "Z needed": ln["z_crit"],
                                             "kept": "yes" if ln["passed"] else "no"}
                                            for ln in result.lines]), ".4g"), ""]
    return md


def _dirs(M) -> list[str]:
    return [f"{int((M.direction == d).sum())} {'positive' if d > 0 else 'negative'}" for d in (1, -1)
            if (M.direction == d).any()]


def _coefficients(c, freqs) -> pd.DataFrame:
    return pd.DataFrame([{"term": c.parts[v["part"]].label(freqs),
                          "direction": {0: "both", 1: "positive", -1: "negative"}[v["slot"]],
                          "parameter": v["name"] if v["kind"] == "nonlinear" else _lin_name(v["name"]),
                          "value": v["value"], "s.e.": v["se"], "at bound": "at bound" if v["at_bound"] else ""}
                         for v in c.fit.values()])


def _lin_name(basis: str) -> str:
    return next((f"coefficient of {k}" for k in ("sin", "cos") if basis.startswith(k)), "coefficient")
