"""The registry of real, measured data sets (:data:`REGISTRY`): files with their SHA-256 checksums,
source, licence, download URL where one exists, and how to load each.  The files are never part of
the package.  A set lives in a folder of its name under ``$GEARSPEC_DATA`` (if set), then
``../shared/datasets`` from the folder gearspec runs in (the data beside a project checkout, when
that folder exists), then the user cache ``pooch.os_cache("gearspec")`` (where :func:`fetch`
downloads); the first holding all its files is used, and every file is checked against its
checksum before it is read.  Nothing is downloaded unless asked (``fetch``, ``download=True``).

>>> rec = datasets.load("kinova_gen3_joint7", part=["0.3", "0.5"])   # doctest: +SKIP
>>> datasets.commanded_velocity(rec)               # {0: 0.3, 1: 0.5}  # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import pandas as pd
import pooch

from .errors import InputError
from .recording import Recording, load_recording

__all__ = ["DataSet", "REGISTRY", "ENV_VAR", "get", "names", "cache_dir", "data_dir", "search_path", "catalog_efficiency",
           "fetch", "list_datasets", "describe", "load", "commanded_velocity", "kinova_breakaway"]

#: environment variable naming a folder with one subfolder per data set
ENV_VAR = "GEARSPEC_DATA"

KINOVA_NAMES = ("torque_command", "theta", "velocity", "torque", "current_command", "current",
                "friction_estimate")
KINOVA_FS = 999.0
_KINOVA_RUN = re.compile(r"velocity_([0-9]+(?:\.[0-9]*)?)readings\.csv$")


@dataclass(frozen=True)
class DataSet:
    """One entry of the registry: ``name`` (also its folder's), ``files`` (name -> SHA-256 hex),
    ``url_base`` (download URL of the folder, None without one), ``kind`` ("recording" or "tables":
    what :func:`load` returns), ``parts`` (what its ``part`` may select), and the ``loader``."""

    name: str
    title: str
    files: Mapping[str, str] = field(hash=False)
    source: str
    licence: str
    url_base: str | None
    citation: str
    notes: str
    kind: str
    parts: tuple[str, ...]
    loader: Callable[["DataSet", dict[str, Path], object], object] = field(repr=False, compare=False, hash=False)

    @property
    def download(self) -> bool:
        """Whether the files can be downloaded from the source."""
        return self.url_base is not None

    def url(self, fname: str) -> str | None:
        """Download URL of one file, or None when the set has no download."""
        if fname not in self.files:
            raise InputError(f"data set '{self.name}' has no file '{fname}' (files: {', '.join(self.files)})")
        return None if self.url_base is None else self.url_base + fname


# ---------------------------------------------------------------------- loaders
def _load_emps(ds: DataSet, paths: dict[str, Path], part) -> Recording:
    aliases = {None: "DATA_EMPS", "data_emps": "DATA_EMPS", "data_emps.mat": "DATA_EMPS", "estimation": "DATA_EMPS",
               "data_emps_pulses": "DATA_EMPS_PULSES", "data_emps_pulses.mat": "DATA_EMPS_PULSES",
               "pulses": "DATA_EMPS_PULSES", "cross-test": "DATA_EMPS_PULSES", "validation": "DATA_EMPS_PULSES"}
    key = part.lower() if isinstance(part, str) else part
    if key not in aliases:
        raise InputError(f"data set '{ds.name}': unknown part {part!r} (parts: {', '.join(ds.parts)})")
    stem = aliases[key]
    rec = load_recording(paths[stem + ".mat"], "emps", map={"theta": "qm", "torque": "vir"},
                         scale={"torque": "gtau"})
    rec.meta.update(dataset=ds.name, part=stem)
    rec.notes.append(f"EMPS {stem}: torque is the motor force on the load side, gtau x vir "
                     f"(gtau = {rec.meta['gtau']:.10g} N/V, read from the file); theta is qm (m)")
    return rec


def _kinova_speed(path: str | Path) -> float | None:
    m = _KINOVA_RUN.search(Path(path).name)
    return float(m.group(1)) if m else None


def _as_speeds(ds: DataSet, part, available: dict[float, Path]) -> list[float]:
    if part is None:
        return sorted(available)
    items = [part] if isinstance(part, (str, int, float)) else list(part)
    if not items:
        raise InputError(f"data set '{ds.name}': part is an empty list; give commanded speeds, e.g. '0.3'")
    chosen = []
    listed = ", ".join(f"{s:g}" for s in sorted(available))
    for item in items:
        try:
            v = float(item)
        except (TypeError, ValueError):
            raise InputError(f"data set '{ds.name}': part {item!r} is not a commanded speed in rad/s "
                             f"(available: {listed})") from None
        match = [s for s in available if abs(s - v) <= 1e-9 + 1e-6 * abs(v)]
        if not match:
            raise InputError(f"data set '{ds.name}': no run at commanded speed {v:g} rad/s (available: {listed})")
        chosen.append(match[0])
    return sorted(set(chosen))


def _load_kinova(ds: DataSet, paths: dict[str, Path], part) -> Recording:
    available = {_kinova_speed(f): p for f, p in paths.items() if _kinova_speed(f) is not None}
    speeds = _as_speeds(ds, part, available)
    rec = load_recording([available[s] for s in speeds], "kinova-gen3-joint7", sep="whitespace", header=False,
                         names=list(KINOVA_NAMES), fs=KINOVA_FS)
    rec.meta.update(dataset=ds.name, commanded_velocity=commanded_velocity(rec))
    rec.notes.append("Kinova Gen3 joint 7: one run per commanded speed ("
                     + ", ".join(f"run {r}: {v:g} rad/s" for r, v in rec.meta["commanded_velocity"].items())
                     + "); torque is the joint torque sensor, positive direction only. The sensor sits after the gear: "
                     "it reads the torque reaching the link (-0.14 to -0.26 Nm on the plateaus), not the gear's "
                     "friction, which is torque_command - torque (= -friction_estimate, the source project's own "
                     "estimate; 1.6 to 2.8 Nm)")
    return rec


def _load_catalog(ds: DataSet, paths: dict[str, Path], part):
    tables = {Path(f).stem: pd.read_csv(p) for f, p in paths.items()}
    if part is None:
        return tables
    key = Path(str(part)).stem
    if key not in tables:
        raise InputError(f"data set '{ds.name}': unknown part {part!r} (parts: {', '.join(tables)})")
    return tables[key]


# ---------------------------------------------------------------------- the table
_KINOVA_FILES = {
    "velocity_0.030000readings.csv": "ed052775fe2ba5aa4c85ce5e7a44c4c77c0fdf826c7f39791ec742bb095a8b8c",
    "velocity_0.050000readings.csv": "bcec7657b52178d4934d3db3aaae417a4b738fa6e234d6f80ebe9d335ccb16b8",
    "velocity_0.090000readings.csv": "c625ae88fb66400a2d1c61045fc0b1e6e0969958463ead11875c587727b151a5",
    "velocity_0.100000readings.csv": "6f1786c1aeaf8b463343a7ed0a3750bcd44d212485b9839f9613128505eb89ed",
    "velocity_0.300000readings.csv": "8bc58c52c37c1ce5998e6126f64140c1b387770ad07135cf5fc25b184a3f1769",
    "velocity_0.500000readings.csv": "e854426c724891b324ca606174a237c056bdb3ea18969c696a267fe733ee3390",
    "velocity_0.700000readings.csv": "8776c89770ff839790909eea0a7574c2386666b14768c461eebf223fcf1d6aa4",
    "velocity_0.900000readings.csv": "54b61bf4c2e74aed34e07d91a2f07a8798ce353146e281ae887b93b2cd697cef",
    "velocity_1.300000readings.csv": "092df6040e28ec0e9ec33a1d2e77d95a47b5904bc2b3f7ec3c2df7be37aa9c77",
    "velocity_1.500000readings.csv": "0c0d5e298cd22797ef9faa5903b953efb50771c38eaca1192d9158f62f3a124a",
    "static_torque_breakaway_point.csv": "444d9436c221ba8b4675613d5e748212f29bdec266071a8ec143cc2400c9698c",
}

REGISTRY: tuple[DataSet, ...] = (
    DataSet(
        name="emps",
        title="EMPS electro-mechanical positioning system (ball-screw linear axis), measured",
        files=MappingProxyType({
            "DATA_EMPS.mat": "6cf6814ae14618795da0101aae2bb97ff0c6351b0501b5492751b02b07facf7e",
            "DATA_EMPS_PULSES.mat": "0eab75bb1f6b16228ee78791343a88bf9bfd9a51036ac9807d7b5fc11c0e1704",
        }),
        source="GitHub forgi86/sysid-neural-continuous, examples/EMPS/data/",
        licence="Apache-2.0 (repository); none stated by the data set",
        url_base="https://raw.githubusercontent.com/forgi86/sysid-neural-continuous/master/examples/EMPS/data/",
        citation='A. Janot, M. Gautier, M. Brunot, "Data Set and Reference Models of EMPS", ONERA / LS2N, '
                 "nonlinear system-identification benchmarks",
        notes="A copy of the EMPS benchmark (nonlinear system-identification benchmark collection). Closed-loop prismatic axis (Maxon DC motor, Star ball screw), 1 kHz, 24,841 samples (~25 s), "
              "velocity plateaus near +-0.04, 0.08, 0.12 m/s. Loaded with theta = qm (m) and "
              "torque = gtau * vir (N; gtau, N/V, is stored in the file and kept in meta). "
              "part 'DATA_EMPS' (default) is the estimation set, 'DATA_EMPS_PULSES' the cross-test set "
              "with external force pulses (channel pulses_N).",
        kind="recording",
        parts=("DATA_EMPS", "DATA_EMPS_PULSES"),
        loader=_load_emps,
    ),
    DataSet(
        name="kinova_gen3_joint7",
        title="Kinova Gen3 arm, joint 7 (strain-wave gear): constant-velocity friction runs, measured",
        files=MappingProxyType(_KINOVA_FILES),
        source="GitHub HBRS-SDP/joint-friction-model, data/",
        licence="none stated (no licence file)",
        url_base="https://raw.githubusercontent.com/HBRS-SDP/joint-friction-model/main/data/",
        citation="HBRS-SDP/joint-friction-model, a student project (Hochschule Bonn-Rhein-Sieg) identifying "
                 "the joint friction of a Kinova Gen3 arm",
        notes="10 runs of ~3 s at commanded 0.03 ... 1.5 rad/s, positive direction only, 999 Hz, no time "
              "column; whitespace-separated columns " + ", ".join(KINOVA_NAMES) + ". Position wraps into "
              "[0, 2*pi) and is unwrapped on loading. The download URL assumes the branch 'main'; the "
              "repository changed these files several times, so a download may differ from the registered "
              "version and is then refused by its checksum. part selects commanded speeds ('0.3' or a "
              "list); static_torque_breakaway_point.csv (breakaway torque, ramp rate) is read by "
              "kinova_breakaway().",
        kind="recording",
        parts=tuple(f"{float(_KINOVA_RUN.search(f).group(1)):g}" for f in _KINOVA_FILES if _KINOVA_RUN.search(f)),
        loader=_load_kinova,
    ),
    DataSet(
        name="harmonic_drive_catalog",
        title="Strain-wave (HarmonicDrive) gear efficiency, catalog-style tables",
        files=MappingProxyType({
            "compensation_vs_load_torque.csv": "2188ecd63508d1dec721e2686a591defc2d8cb7c3edec83a8374a2aa524f421f",
            "efficiency_vs_input_speed.csv": "b4cad39b76b818ed5ca990b94d75e1f8e71302ef24615037463946941d585ca0",
        }),
        source="transcribed by hand from GitHub ihmcrobotics/ihmc-open-robotics-software (a Java file)",
        licence="none stated for the tables",
        url_base=None,
        citation="ihmcrobotics/ihmc-open-robotics-software, ExampleSimulations/src/us/ihmc/exampleSimulations/m2/"
                 "HarmonicDriveEfficiencyCalculator.java",
        notes="No download exists: the csv files were written by hand from two lookup tables in that Java file. "
              "eta(n_in, T_load) = eta_R(n_in) * K(T_load): efficiency at rated torque versus input speed "
              "(rpm; the 1.00 at 0 rpm is the source's extrapolation) and the compensation coefficient K "
              "versus output load torque (Nm; 67.2 Nm used where the code says 67.0). Gear model not named. "
              "load() returns both tables as pandas DataFrames.",
        kind="tables",
        parts=("compensation_vs_load_torque", "efficiency_vs_input_speed"),
        loader=_load_catalog,
    ),
)

_BY_NAME = {ds.name: ds for ds in REGISTRY}


def names() -> list[str]:
    """Names of all registered data sets."""
    return list(_BY_NAME)


def get(name: str | DataSet) -> DataSet:
    """The registry entry of a data set (``-`` and ``_`` are interchangeable in the name)."""
    if isinstance(name, DataSet):
        return name
    key = str(name).strip().lower().replace("-", "_")
    if key not in _BY_NAME:
        raise InputError(f"unknown data set '{name}' (data sets: {', '.join(_BY_NAME)}; see `gearspec data list`)")
    return _BY_NAME[key]


# ---------------------------------------------------------------------- locations
def cache_dir() -> Path:
    """The user cache, ``pooch.os_cache("gearspec")``: where downloads go."""
    return Path(pooch.os_cache("gearspec"))


def _env_dir() -> Path | None:
    value = os.environ.get(ENV_VAR, "").strip()
    return Path(value).expanduser() if value else None


#: the default folder of the data sets beside a project checkout, from the working folder
SHARED = Path("..") / "shared" / "datasets"


def shared_dir() -> Path | None:
    """``../shared/datasets`` from the working folder, resolved, when it exists (else None)."""
    p = (Path.cwd() / SHARED).resolve()
    return p if p.is_dir() else None


def data_dir() -> Path:
    """The first folder searched (see :func:`search_path`)."""
    return search_path()[0][0]


def search_path() -> list[tuple[Path, str]]:
    """The folders searched for data sets, in order, each with what it is: ``$GEARSPEC_DATA`` (if
    set), ``../shared/datasets`` (if it exists), the user cache."""
    env, shared = _env_dir(), shared_dir()
    return ([] if env is None else [(env, ENV_VAR)]) + ([] if shared is None else [(shared, str(SHARED))]) \
        + [(cache_dir(), "user cache")]


def _locate(ds: DataSet) -> tuple[Path | None, list[tuple[Path, str, list[str]]]]:
    """The first folder holding all files of ``ds``, and what is missing in each folder searched."""
    tried = []
    for base, what in search_path():
        folder = base / ds.name
        missing = [f for f in ds.files if not (folder / f).is_file()]
        if not missing:
            return folder, tried
        tried.append((folder, what, missing))
    return None, tried


# ---------------------------------------------------------------------- checksums
_HASH_MEMO: dict[tuple[str, int, int], str] = {}


def _sha256(path: Path) -> str:
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _HASH_MEMO:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _HASH_MEMO[key] = h.hexdigest()
    return _HASH_MEMO[key]


def _verify(ds: DataSet, fname: str, path: Path) -> Path:
    expected = ds.files[fname]
    actual = _sha256(path)
    if actual != expected:
        if not ds.download:
            fix = "restore the original file (no download exists for this data set)"
        elif _is_in(path, cache_dir()):
            fix = f"`gearspec data fetch {ds.name}` downloads it again"
        else:
            fix = (f"replace it with the registered version, or remove the folder {path.parent} (or unset "
                   f"{ENV_VAR}) and run `gearspec data fetch {ds.name}` to download into the user cache")
        raise InputError(f"{path}: checksum mismatch for data set '{ds.name}': expected sha256 {expected}, "
                         f"got {actual}; the file is damaged or a different version; {fix}")
    return path


def _is_in(path: Path, folder: Path) -> bool:
    return path.resolve().is_relative_to(folder.resolve())


# ---------------------------------------------------------------------- public API
def fetch(name: str, download: bool = False) -> dict[str, Path]:
    """Paths of a data set's files (file name -> path, in the registry's order), each checked against
    its checksum (InputError naming both hashes, or where the files were looked for).

    ``download``: when the files are in no searched folder (:func:`search_path`), download them into
    the user cache (``pooch.retrieve`` with the checksum and a progress bar), if the set has a URL.
    """
    ds = get(name)
    folder, tried = _locate(ds)
    can_download = download and ds.download
    if folder is not None:
        try:
            return {f: _verify(ds, f, folder / f) for f in ds.files}
        except InputError:
            # a damaged copy in the user cache is repaired by downloading again (pooch re-downloads
            # only the files whose checksum differs); anywhere else it is refused
            if not (can_download and _is_in(folder, cache_dir())):
                raise
    if can_download:
        target = cache_dir() / ds.name
        out = {}
        for fname, sha in ds.files.items():
            url = ds.url(fname)
            try:
                got = pooch.retrieve(url, known_hash=f"sha256:{sha}", path=target, fname=fname, progressbar=True)
            except ValueError as exc:  # pooch: the downloaded file's hash differs from the registered one
                raise InputError(f"{url}: the downloaded file does not match the registered checksum of data set "
                                 f"'{ds.name}' (expected sha256 {sha}): the source has changed the file; "
                                 f"put the registered version in $GEARSPEC_DATA/{ds.name}/ instead "
                                 f"({str(exc).splitlines()[0] if str(exc) else 'hash mismatch'})") from None
            except OSError as exc:  # network errors (requests' exceptions are OSErrors) and disk errors
                raise InputError(f"{url}: download of data set '{ds.name}' failed ({exc}); check the network, or "
                                 f"put the files in $GEARSPEC_DATA/{ds.name}/") from None
            out[fname] = Path(got)
        return out
    raise InputError(_missing_message(ds, tried))


def _missing_message(ds: DataSet, tried) -> str:
    where = "; ".join(
        f"{folder} ({what}): " + ("folder does not exist" if not folder.is_dir() else
                                  "missing " + (", ".join(missing) if len(missing) <= 3 else
                                                f"{len(missing)} of {len(ds.files)} files"))
        for folder, what, missing in tried)
    msg = f"data set '{ds.name}' is not available; looked in {where}. "
    how_env = (f"set {ENV_VAR} to a folder holding a subfolder '{ds.name}/' with its files "
               f"({', '.join(ds.files) if len(ds.files) <= 3 else f'{len(ds.files)} files, see `gearspec data describe {ds.name}`'})")
    if ds.download:
        msg += (f"To get it, {how_env}, or download it into the user cache with `gearspec data fetch {ds.name}` "
                f"(in Python: fetch('{ds.name}', download=True))")
    else:
        msg += (f"No download exists for this data set ({ds.source}); {how_env}")
    return msg + "."


def list_datasets() -> pd.DataFrame:
    """The registry as a table: name, title, number of files, source, licence, whether a download
    exists, whether the files are present locally (not checksummed here), and where."""
    rows = []
    for ds in REGISTRY:
        folder = _locate(ds)[0]
        rows.append({"name": ds.name, "title": ds.title, "files": len(ds.files), "source": ds.source,
                     "licence": ds.licence, "download": ds.download, "present": folder is not None,
                     "location": "" if folder is None else str(folder)})
    return pd.DataFrame(rows, columns=["name", "title", "files", "source", "licence", "download", "present",
                                       "location"])


def describe(name: str) -> str:
    """A human description of one data set: source, licence, citation, files and checksums, where
    it is, and how to load it."""
    ds = get(name)
    folder, _ = _locate(ds)
    lines = [f"{ds.name}: {ds.title}", "",
             f"source:   {ds.source}",
             f"licence:  {ds.licence}",
             f"cite:     {ds.citation}",
             f"download: {ds.url_base if ds.download else 'none (no source URL for these files)'}",
             f"present:  {folder if folder is not None else 'no'}",
             "", "notes: " + ds.notes, "", f"files ({len(ds.files)}, sha256):"]
    width = max(len(f) for f in ds.files)
    lines += [f"  {f:<{width}}  {sha}" for f, sha in ds.files.items()]
    lines += ["", "searched, in order: " + ", ".join(f"{b / ds.name} ({w})" for b, w in search_path()),
              f"load:     gearspec.datasets.load('{ds.name}'" + (", part=...)" if ds.parts else ")")
              + (f"  (parts: {', '.join(ds.parts)})" if ds.parts else "")
              + ("  -> Recording" if ds.kind == "recording" else "  -> dict of pandas DataFrames")]
    return "\n".join(lines)


def load(name: str, part=None, download: bool = False):
    """A data set, verified (``download`` as :func:`fetch`) and loaded: a
    :class:`~gearspec.recording.Recording`, or for ``harmonic_drive_catalog`` a dict of its two
    tables (one DataFrame when ``part`` names it).

    ``part``: ``emps``: ``"DATA_EMPS"`` (default, estimation set) or ``"DATA_EMPS_PULSES"``
    (cross-test set); ``kinova_gen3_joint7``: a commanded speed (``"0.3"`` or ``0.3``) or a list of
    them, default all ten runs sorted by speed.
    """
    ds = get(name)
    return ds.loader(ds, fetch(ds.name, download=download), part)


def commanded_velocity(recording: Recording) -> dict[int, float]:
    """Commanded velocity (rad/s) of each run of a Kinova recording, read from its file names
    (``velocity_<v>readings.csv``, one run per file)."""
    out = {}
    for run, src in enumerate(recording.sources):
        v = _kinova_speed(src)
        if v is None:
            raise InputError(f"{src}: not a Kinova run file (velocity_<v>readings.csv); no commanded velocity known")
        out[run] = v
    return out


def kinova_breakaway(download: bool = False) -> pd.DataFrame:
    """The Kinova static breakaway tests: ``breakaway_torque`` (Nm) at each ``ramp_rate`` (Nm/s) of the
    torque ramp, 10 repeats at each of 5 rates."""
    paths = fetch("kinova_gen3_joint7", download=download)
    return pd.read_csv(paths["static_torque_breakaway_point.csv"], sep=r"\s+", header=None,
                       names=["breakaway_torque", "ramp_rate"])


def catalog_efficiency(download: bool = False) -> pd.DataFrame:
    """The strain-wave catalog tables as one efficiency grid, the catalog's product form
    ``eta(n_in, T_load) = eta_R(n_in) * K(T_load)``: columns ``input_speed_rpm``, ``load`` (output
    torque, Nm), ``eta_rated``, ``compensation`` and ``efficiency`` (see the data set's SOURCE.md;
    the 0 rpm row is the source's own extrapolation)."""
    tables = load("harmonic_drive_catalog", download=download)
    grid = tables["efficiency_vs_input_speed"].merge(tables["compensation_vs_load_torque"], how="cross")
    grid = grid.rename(columns={"efficiency_at_rated_torque": "eta_rated", "output_load_torque_Nm": "load",
                                "compensation_coefficient": "compensation"})
    grid["efficiency"] = grid["eta_rated"] * grid["compensation"]
    return grid[["input_speed_rpm", "load", "eta_rated", "compensation", "efficiency"]]
