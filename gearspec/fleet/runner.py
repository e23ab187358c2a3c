"""Many recordings and joints at once: one task per (source, joint), run serially or on Dask.

The per-task code (:func:`analyse_one`) is plain numpy and is the same function whether it runs in
this process (``workers=1``), on a :class:`distributed.LocalCluster` of processes started and closed
here, or on an existing Dask scheduler.  It does what ``gearspec fit`` does on that file alone, with
its defaults (load, ``--lag`` none, the segments of the default segment options, the joint fit with
the published procedure and the simpler laws beside it), plus the spectrum's strongest lines and,
when asked, the closed-loop diagnosis.  A failing task returns an error row with its sentence; it
never stops the batch.
"""

from __future__ import annotations

import sys
import traceback
import warnings
from pathlib import Path
from typing import Iterable

import pandas as pd

from ..core.parallel import can_fork
from ..errors import GearspecWarning, InputError

__all__ = ["batch", "analyse_one", "tasks", "pair_counts", "N_LINES", "BASE_COLUMNS", "DIRECTIONS"]

#: the directions of motion, one row each per (source, joint)
DIRECTIONS = ("positive", "negative")
#: strongest spectral lines kept per (source, joint, direction)
N_LINES = 3
#: the columns every row has, in this order (the law's parameters and the lines follow)
BASE_COLUMNS = ("source", "robot", "joint", "direction", "status", "error", "warnings", "start_time", "law",
                "rmse", "rmse_holdout")
#: the segment options of ``gearspec fit`` and their defaults (window in s or "auto")
SEGMENT_DEFAULTS = {"window": "auto", "rel_tol": 0.15, "min_speed": None, "min_duration": None, "quasi_static": None}
#: how long a Dask scheduler may take to answer
CONNECT_TIMEOUT = "20s"
#: Dask's background sampling in the local cluster, made rare: a worker's statistical profiler (every
#: 10 ms), event-loop tick (20 ms) and memory monitor (100 ms) each take the GIL from the task
#: running beside them; measured on 6 recordings under load, they cost 15-25 % more CPU per task and
#: 1-1.5 s of the scheduler's.  The tasks here are seconds long: sampled each second is enough.
QUIET_CLUSTER = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                 "distributed.worker.memory.monitor-interval": "1s", "distributed.admin.system-monitor.interval": "2s",
                 "distributed.admin.system-monitor.gil.enabled": False}
#: a line counts among the strongest only when its false-alarm probability is below this
LINE_FAP = 0.01


def tasks(recordings: Iterable, joint: str | None = "all",
          topic: str = "/joint_states") -> list[tuple[str, str | None]]:
    """The ``(source, joint)`` pairs of a batch: a ROS bag gives one per joint of ``topic`` when
    ``joint`` is "all" (a bag that cannot be listed gives one task, which then fails with its
    sentence), else the named joint; any other file one task with joint None."""
    from ..recording.bags import bag_joints, is_bag
    from ..recording.load import expand_paths

    out: list[tuple[str, str | None]] = []
    for path in recordings:
        try:
            files = expand_paths([path])
        except InputError:
            out.append((str(path), None))   # e.g. no such file: the task says so
            continue
        for f in files:
            if not is_bag(f):
                out.append((str(f), None))
                continue
            if joint not in (None, "all"):
                out.append((str(f), joint))
                continue
            try:
                names = bag_joints(f, topic)
            except InputError:
                names = [None]
            out += [(str(f), j) for j in names]
    return out


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def analyse_one(source: str, joint: str | None, gear=None, law: str = "silo4", diagnose: bool = False,
                load_options: dict | None = None) -> dict:
    """Analyse one (source, joint) as ``gearspec fit`` (and ``spectrum``, ``diagnose``) would.

    Returns ``{"rows": [...], "fit": dict | None}``: one row per direction (dicts of
    :data:`BASE_COLUMNS`; ``warnings``: the findings the analysis warned of, each once, joined by "; ";
    the law's parameters and standard errors in SI as in the fit's JSON, the
    strongest lines); ``fit``: the ``gearspec fit --json`` form.  Never raises for a bad input: an
    :class:`InputError` becomes the ``error`` sentence, any other exception ``"internal error: ..."``.
    A recording that cannot be read has one error row (``direction`` None: its directions are not
    known); a recording read but not analysed (e.g. the fit refused in one direction, which refuses
    the whole fit as ``gearspec fit`` does) has an error row per direction with the sentence, and a
    direction without any identified parameter of the law (no segment in it) an error row saying so.
    """
    base = {"source": str(source), "robot": Path(source).parent.name or ".", "joint": joint, "direction": None,
            "status": "error", "error": None, "start_time": None, "law": law}
    read: dict = {}   # filled once the recording is read: its start time
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", GearspecWarning)
            warnings.simplefilter("ignore", RuntimeWarning)   # numerical noise of runs that succeed, as in the CLI
            out = _analyse(source, joint, gear, law, diagnose, dict(load_options or {}), base, read)
    except InputError as exc:
        out = {"rows": _error_rows(base, read, _one_line(exc)), "fit": None}
    except Exception as exc:  # not the user's fault: said as such, with the exception's type
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" at {Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else ""
        out = {"rows": _error_rows(base, read, f"internal error: {type(exc).__name__}: {_one_line(exc)}{where}"),
               "fit": None}
    said = list(dict.fromkeys(" ".join(str(w.message).split()) for w in caught
                              if issubclass(w.category, GearspecWarning)))
    for row in out["rows"]:
        row["warnings"] = "; ".join(said) or None
    return out


def _error_rows(base: dict, read: dict, sentence: str) -> list[dict]:
    """The rows of a task that failed: one (direction None) when the recording was not read, else one
    per direction with its start time."""
    if not read:
        return [{**base, "error": sentence}]
    return [{**base, "direction": d, "start_time": read.get("start_time"), "error": sentence} for d in DIRECTIONS]


def _direction_refused(fit: dict, dname: str, law: str) -> str | None:
    """The sentence of a direction in which no parameter of the law was identified (None when some
    was): the fit's own reason (e.g. "no segment in the negative direction")."""
    from ..model import LAWS

    names = LAWS[law].params if law in LAWS else ()
    params = fit["directions"].get(dname) or {}
    if not names or any(params.get(k) is not None for k in names):
        return None
    reason = (fit.get("not_identified") or {}).get(f"{dname}.{names[0]}")
    return reason or f"no parameter of the {law} law was identified in the {dname} direction"


def _analyse(source, joint, gear, law, diagnose, opts, base, read) -> dict:
    from ..identify import identify_recording
    from ..jsonsafe import plain
    from ..lag import lag_option
    from ..recording import load_recording
    from ..segment import find_segments
    from ..spectrum import analyze

    # the segment options with `gearspec fit`'s defaults
    seg_opts = {**SEGMENT_DEFAULTS, **{k: opts.pop(k) for k in SEGMENT_DEFAULTS if k in opts}}
    quasi_static = seg_opts.pop("quasi_static")
    lag = opts.pop("lag", None)
    rec = load_recording([source], gear, joint=joint, **opts)
    rec = lag_option(rec, lag, say=lambda s: None, **seg_opts)
    read["start_time"] = rec.meta.get("start_time")
    seg = find_segments(rec, **seg_opts, quasi_static=quasi_static)
    result = identify_recording(rec, law, segmentation=seg)
    fit = plain(result.to_dict())
    fit.update({k: rec.meta[k] for k in ("lag", "lag_se") if k in rec.meta})
    lines = _strongest_lines(analyze(rec, segmentation=seg, progress=False))
    extra = _diagnosis(rec, seg, law) if diagnose else {}
    base = {**base, "status": "ok", "start_time": rec.meta.get("start_time"), "rmse": fit.get("rmse"),
            "rmse_holdout": fit.get("rmse_holdout"), **extra}
    rows = []
    for dname in DIRECTIONS:
        params = fit["directions"].get(dname) or {}
        row = {**base, "direction": dname, **_parameters(params), **lines.get(dname, {})}
        refused = _direction_refused(fit, dname, law)
        if refused:
            row.update(status="error", error=refused)
        rows.append(row)
    return {"rows": rows, "fit": fit}


def _parameters(params: dict) -> dict:
    """A direction's parameters as flat columns: the law's (``tau_c``, ``tau_c_se``, ...) and each
    line's ``<label> amplitude`` / ``decay`` / ``phase`` with ``_se`` (the names of the model table)."""
    out = {k: v for k, v in params.items() if k != "harmonics" and (v is None or isinstance(v, (int, float)))}
    for i, h in enumerate(params.get("harmonics") or []):
        lab = h.get("label") or f"harmonic {i + 1}"
        for key in ("amplitude", "decay", "phase"):
            out[f"{lab} {key}"] = h.get(key)
            out[f"{lab} {key}_se"] = h.get(key + "_se")
    return out


def _strongest_lines(spec) -> dict:
    """Per direction, the :data:`N_LINES` lines of largest median amplitude over the direction's
    segments (peaks with false-alarm probability below :data:`LINE_FAP`; grouped by label, or by
    frequency for unlabelled ones): ``line1_frequency`` (cycles per unit), ``line1_amplitude`` (Nm or
    N), ``line1_label``, ..."""
    t = spec.peaks_table()
    out: dict = {}
    if t.empty:
        return out
    t = t[t["fap"] <= LINE_FAP].copy()
    t["key"] = [lab if isinstance(lab, str) and lab else f"{f:.6g}" for lab, f in zip(t["label"], t["frequency"])]
    for d, name in ((1, "positive"), (-1, "negative")):
        g = t[t["direction"] == d].groupby("key").agg(frequency=("frequency", "median"),
                                                      amplitude=("amplitude", "median"),
                                                      label=("label", "first"))
        g = g.sort_values("amplitude", ascending=False).head(N_LINES)
        row = {}
        for i, (_, r) in enumerate(g.iterrows(), 1):
            row.update({f"line{i}_frequency": float(r["frequency"]), f"line{i}_amplitude": float(r["amplitude"]),
                        f"line{i}_label": r["label"] if isinstance(r["label"], str) else None})
        out[name] = row
    return out


def _diagnosis(rec, seg, law: str) -> dict:
    """The closed loop with ``gearspec diagnose``'s defaults: the effects it accepted, named."""
    from ..diagnose import DiagnoseData
    from ..diagnose import diagnose as run

    diag = run(DiagnoseData.from_recording(rec, seg, by="segment", inertia=True), None, law=law)
    names = [e.name for e in diag.accepted]
    return {"n_effects": len(names), "effects": "; ".join(names)}


def pair_counts(df: pd.DataFrame) -> dict:
    """How the (source, joint) pairs of a batch table fared: ``pairs``; ``fitted`` (every row "ok"),
    ``partly`` (fitted in one direction, the other's row an error) and ``refused`` (no row "ok")."""
    ok = (df["status"] == "ok").groupby([df["source"], df["joint"]], dropna=False)
    n_ok, n = ok.sum(), ok.size()
    return {"pairs": int(len(n)), "fitted": int((n_ok == n).sum()), "partly": int(((n_ok > 0) & (n_ok < n)).sum()),
            "refused": int((n_ok == 0).sum())}


def _frame(results: list[dict]) -> pd.DataFrame:
    rows = [r for res in results for r in res["rows"]]
    df = pd.DataFrame(rows)
    for c in BASE_COLUMNS:
        if c not in df:
            df[c] = None
    rest = [c for c in df.columns if c not in BASE_COLUMNS]
    df = df[list(BASE_COLUMNS) + rest]
    df["start_time"] = pd.to_numeric(df["start_time"], errors="coerce")
    for c in df.columns:  # text columns as plain objects, the same whichever rows hold text
        if c in ("source", "robot", "joint", "direction", "status", "error", "warnings", "law", "effects") \
                or c.endswith("_label"):
            df[c] = pd.Series(df[c].tolist(), dtype=object, index=df.index)
    for c in ("rmse", "rmse_holdout"):
        df[c] = pd.to_numeric(df[c], errors="coerce")
    return df.reset_index(drop=True)


def batch(recordings, gear=None, *, law: str = "silo4", diagnose: bool = False, workers: int | None = None,
          scheduler: str | None = None, joint: str | None = "all", progress: bool = True,
          fits: dict | None = None, start: str | None = None, **load_options) -> pd.DataFrame:
    """Spectrum + fit (+ diagnosis) of every (recording, joint), one row per (source, joint, direction).

    Parameters
    ----------
    recordings : iterable of path
        Files, ROS bags or folders (as :func:`gearspec.recording.load_recording` reads them).
    gear : GearTrain, preset name or TOML path, optional
        The gear spec of every recording.
    law : str
        The friction law fitted (as ``gearspec fit --law``).
    diagnose : bool
        Also run the closed loop (``gearspec diagnose``'s defaults); columns ``n_effects``, ``effects``.
    workers : int, optional
        1: a plain loop in this process (no Dask).  N > 1: a local Dask cluster of N single-threaded
        processes, started and closed here.  Default: one process per CPU (at most the tasks).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); ``workers`` is then ignored.
    joint : str
        "all" (default): every joint of each bag; a name: that joint.  Files other than bags have one.
    progress : bool
        A progress bar on stderr (tqdm) as tasks finish.
    fits : dict, optional
        Filled with each task's ``gearspec fit --json`` form, keyed by ``(source, joint)``.
    start : {"fork", "spawn", "forkserver"}, optional
        How the local worker processes start.  Default: "fork" on Linux (a copy of this process,
        whose imports are done: a fraction of a second), elsewhere Dask's configured method
        ("spawn").  Give "spawn" when this process runs threads of its own that fork would copy in
        an unsafe state.
    **load_options
        Recording and segment options (``map``, ``scale``, ``fs``, ``topic``, ``window``, ...).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`BASE_COLUMNS` (``start_time`` in s since 1970 when the recording has it,
        ``rmse`` and ``rmse_holdout`` in Nm or N), the law's parameters with ``_se`` in SI, each line's
        amplitude/decay/phase with ``_se``, ``line1_frequency`` ... (cycles per unit, Nm or N).  Rows
        in task order whatever ran them.  A failing input has one row, ``status`` "error" and its
        sentence in ``error``.
    """
    if workers is not None and (int(workers) != workers or workers < 1):
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    todo = tasks(recordings, joint, load_options.get("topic", "/joint_states"))
    if not todo:
        raise InputError("no recording given to the batch")
    args = [(src, j, gear, law, diagnose, load_options) for src, j in todo]
    n = len(todo)
    if scheduler is None and (workers == 1 or n == 1):
        it = (analyse_one(*a) for a in args)
        results = list(_bar(it, n, progress))
    else:
        results = _on_dask(args, workers, scheduler, progress, start=start, diagnose=diagnose)
    if fits is not None:
        fits.update({(src, j): r["fit"] for (src, j), r in zip(todo, results) if r["fit"] is not None})
    return _frame(results)


def _bar(it, total: int, enabled: bool):
    if not enabled:
        return it
    from tqdm import tqdm

    return tqdm(it, total=total, desc="recordings", unit="task", file=sys.stderr)


def _start_method(start: str | None) -> str:
    """How local worker processes start: ``start`` when given; else "fork" where the system has it
    (Linux: a copy of this process, whose imports are done, starts in a fraction of a second) and
    otherwise Dask's configured method ("spawn": a fresh interpreter that imports distributed,
    numpy, scipy, pandas and gearspec again, about 2 s of CPU per worker on an idle machine)."""
    import multiprocessing

    import dask

    if start is not None:
        if start not in multiprocessing.get_all_start_methods():
            raise InputError(f"start must be one of {', '.join(multiprocessing.get_all_start_methods())} "
                             f"on this system, got {start!r}")
        return start
    if can_fork():
        return "fork"
    return dask.config.get("distributed.worker.multiprocessing-method", "spawn")


def _warm(diagnose: bool) -> None:
    """Import what a task needs here, before worker processes are forked from this one."""
    from .. import identify, lag, recording, segment, spectrum  # noqa: F401
    if diagnose:
        from .. import diagnose as _d  # noqa: F401


def _one_blas_thread(fn, *args):
    """``fn(*args)`` with numpy's BLAS / OpenMP pools held to one thread: a worker is one process on
    one core, and threads of its own only contend with the other workers (a forked worker inherits
    this process's pools, which Dask's ``OMP_NUM_THREADS=1`` does not reach)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return fn(*args)


def _largest_first(args: list) -> list[int]:
    """The order tasks are submitted in: the largest files first (a long task started last would run
    alone at the end while the other workers wait), ties and unreadable paths in task order."""
    def size(a) -> int:
        try:
            p = Path(a[0])
            return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else p.stat().st_size
        except OSError:
            return 0
    sizes = [size(a) for a in args]
    return sorted(range(len(args)), key=lambda i: -sizes[i])


def _on_dask(args: list, workers: int | None, scheduler: str | None, progress: bool, start: str | None = None,
             diagnose: bool = False, fn=analyse_one) -> list:
    """Run ``fn`` (:func:`analyse_one`) over ``args`` on a Dask cluster, the largest files first,
    each task with one BLAS thread; results in the order of ``args``."""
    import logging
    import os

    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        n = min(len(args), workers or os.cpu_count() or 1)
        method = _start_method(start)
        if method == "fork":
            _warm(diagnose)
        with dask.config.set({**QUIET_CLUSTER, "distributed.worker.multiprocessing-method": method}):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=logging.ERROR)
    try:
        try:
            client = Client(cluster if cluster is not None else scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: no Dask scheduler answers there ({_one_line(exc)})") from None
        with client:
            order = _largest_first(args)
            futures = {client.submit(_one_blas_thread, fn, *args[i], pure=False): i for i in order}
            index = {f.key: i for f, i in futures.items()}
            results: list = [None] * len(args)
            for fut, res in _bar(as_completed(list(futures), with_results=True), len(args), progress):
                results[index[fut.key]] = res
            return results
    finally:
        if cluster is not None:
            cluster.close()
