"""The data registry: checksums, locations, loaders, and downloads (mocked: no network in tests).

Real-data tests read the data sets from ``$GEARSPEC_DATA`` or, when it is not set, from
``../shared/datasets`` next to the project; they are skipped when that folder is absent.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gearspec import datasets
from gearspec.errors import InputError
from gearspec.recording import Recording

PROJECT = Path(__file__).resolve().parents[1]
REAL_DATA = Path(os.environ.get("GEARSPEC_DATA") or PROJECT.parent / "shared" / "datasets")
HAVE_REAL = all((REAL_DATA / name).is_dir() for name in datasets.names())
needs_real = pytest.mark.skipif(not HAVE_REAL, reason=f"real data sets not found in {REAL_DATA} "
                                "(set GEARSPEC_DATA to the folder holding emps/, kinova_gen3_joint7/, ...)")


#: the module's own search of ../shared/datasets (every test but these sees none: see isolated)
REAL_SHARED_DIR = datasets.shared_dir


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    """Every test gets its own empty user cache and no network: pooch.retrieve fails if called."""
    cache = tmp_path / "user-cache"
    monkeypatch.setattr(datasets, "cache_dir", lambda: cache)
    monkeypatch.setattr(datasets, "shared_dir", lambda: None)     # no ../shared/datasets either
    monkeypatch.delenv("GEARSPEC_DATA", raising=False)

    def no_network(*args, **kwargs):
        raise AssertionError(f"pooch.retrieve called in a test: {args} {kwargs}")

    monkeypatch.setattr(datasets.pooch, "retrieve", no_network)
    return cache


@pytest.fixture
def real_data(monkeypatch):
    if not HAVE_REAL:
        pytest.skip(f"real data sets not found in {REAL_DATA}")
    monkeypatch.setenv("GEARSPEC_DATA", str(REAL_DATA))
    return REAL_DATA


# ---------------------------------------------------------------------- registry (no data needed)
def test_registry_table():
    df = datasets.list_datasets()
    assert list(df["name"]) == ["emps", "kinova_gen3_joint7", "harmonic_drive_catalog"]
    assert {"name", "title", "files", "source", "licence", "download", "present"} <= set(df.columns)
    lic = dict(zip(df["name"], df["licence"]))
    assert "Apache-2.0" in lic["emps"]
    assert "none" in lic["kinova_gen3_joint7"]
    assert "none" in lic["harmonic_drive_catalog"]
    assert dict(zip(df["name"], df["download"])) == {"emps": True, "kinova_gen3_joint7": True,
                                                     "harmonic_drive_catalog": False}
    assert dict(zip(df["name"], df["files"])) == {"emps": 2, "kinova_gen3_joint7": 11, "harmonic_drive_catalog": 2}
    assert not df["present"].any()  # empty cache, no GEARSPEC_DATA
    for ds in datasets.REGISTRY:
        assert all(len(h) == 64 and int(h, 16) >= 0 for h in ds.files.values())
        assert ds.source and ds.licence and ds.citation


def test_urls():
    emps = datasets.get("emps")
    assert emps.url("DATA_EMPS.mat") == ("https://raw.githubusercontent.com/forgi86/sysid-neural-continuous/"
                                         "master/examples/EMPS/data/DATA_EMPS.mat")
    kin = datasets.get("kinova-gen3-joint7")  # hyphens accepted, as in the gear preset's name
    assert kin.name == "kinova_gen3_joint7"
    assert kin.url("velocity_0.300000readings.csv") == ("https://raw.githubusercontent.com/HBRS-SDP/"
                                                        "joint-friction-model/main/data/velocity_0.300000readings.csv")
    assert datasets.get("harmonic_drive_catalog").url("efficiency_vs_input_speed.csv") is None
    with pytest.raises(InputError, match="unknown data set 'nope'.*emps"):
        datasets.get("nope")


def test_describe():
    text = datasets.describe("emps")
    for piece in ("forgi86/sysid-neural-continuous", "Apache-2.0", "Janot", "DATA_EMPS_PULSES.mat",
                  datasets.get("emps").files["DATA_EMPS.mat"], "gtau"):
        assert piece in text
    assert "no source URL" in datasets.describe("harmonic_drive_catalog")


def test_module_holds_no_machine_path_only_the_documented_relative_default():
    source = Path(datasets.__file__).read_text()
    assert "/work/" not in source
    assert datasets.SHARED == Path("..") / "shared" / "datasets"


def test_the_data_beside_a_checkout_are_found_without_configuration(monkeypatch, tmp_path, isolated, capsys):
    # a project checkout with the data sets beside it: tmp/project and tmp/shared/datasets
    project, shared = tmp_path / "project", tmp_path / "shared" / "datasets"
    project.mkdir()
    monkeypatch.chdir(project)
    monkeypatch.setattr(datasets, "shared_dir", REAL_SHARED_DIR)
    assert [w for _, w in datasets.search_path()] == ["user cache"]          # no such folder: not searched
    from gearspec.cli import main
    assert main(["data", "list"]) == 0                                        # nothing found: a hint, no network
    out = capsys.readouterr().out
    assert "No data set found" in out and "GEARSPEC_DATA" in out and "gearspec data fetch" in out
    shared.mkdir(parents=True)
    assert datasets.search_path() == [(shared.resolve(), str(datasets.SHARED)), (isolated, "user cache")]
    monkeypatch.setenv("GEARSPEC_DATA", str(tmp_path / "mine"))              # the variable comes first
    assert [p for p, _ in datasets.search_path()] == [tmp_path / "mine", shared.resolve(), isolated]
    assert datasets.data_dir() == tmp_path / "mine"


def test_shared_dir_is_the_relative_default_when_it_exists(monkeypatch, tmp_path):
    (tmp_path / "shared" / "datasets").mkdir(parents=True)
    (tmp_path / "project").mkdir()
    monkeypatch.chdir(tmp_path / "project")
    assert REAL_SHARED_DIR() == (tmp_path / "shared" / "datasets").resolve()
    monkeypatch.chdir(tmp_path)
    assert REAL_SHARED_DIR() is None


def test_locations(monkeypatch, tmp_path, isolated):
    assert datasets.data_dir() == isolated
    assert [w for _, w in datasets.search_path()] == ["user cache"]
    monkeypatch.setenv("GEARSPEC_DATA", str(tmp_path / "mine"))
    assert datasets.data_dir() == tmp_path / "mine"
    assert [p for p, _ in datasets.search_path()] == [tmp_path / "mine", isolated]


def test_missing_data_message(monkeypatch, tmp_path):
    empty = tmp_path / "nothing-here"
    monkeypatch.setenv("GEARSPEC_DATA", str(empty))
    with pytest.raises(InputError) as err:
        datasets.fetch("emps")
    msg = str(err.value)
    assert "data set 'emps' is not available" in msg
    assert str(empty / "emps") in msg and "GEARSPEC_DATA" in msg and "user cache" in msg
    assert "gearspec data fetch emps" in msg and "download=True" in msg
    with pytest.raises(InputError) as err:
        datasets.load("harmonic_drive_catalog", download=True)
    msg = str(err.value)
    assert "No download exists" in msg and "GEARSPEC_DATA" in msg and "fetch" not in msg


def test_missing_files_listed(monkeypatch, tmp_path):
    (tmp_path / "emps").mkdir()
    (tmp_path / "emps" / "DATA_EMPS.mat").write_bytes(b"x")
    monkeypatch.setenv("GEARSPEC_DATA", str(tmp_path))
    with pytest.raises(InputError, match=r"missing DATA_EMPS_PULSES\.mat.*folder does not exist"):
        datasets.fetch("emps")


# ---------------------------------------------------------------------- downloads (mocked)
def test_download_calls_pooch(monkeypatch, tmp_path, isolated):
    monkeypatch.setenv("GEARSPEC_DATA", str(tmp_path / "empty"))
    calls = []

    def fake_retrieve(url, known_hash=None, fname=None, path=None, processor=None, downloader=None,
                      progressbar=False):
        calls.append(dict(url=url, known_hash=known_hash, fname=fname, path=Path(path), progressbar=progressbar))
        return str(Path(path) / fname)

    monkeypatch.setattr(datasets.pooch, "retrieve", fake_retrieve)
    paths = datasets.fetch("emps", download=True)
    ds = datasets.get("emps")
    assert [c["fname"] for c in calls] == ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"]
    for c in calls:
        assert c["url"] == ds.url_base + c["fname"]
        assert c["known_hash"] == "sha256:" + ds.files[c["fname"]]
        assert c["path"] == isolated / "emps"
        assert c["progressbar"] is True
    assert paths == {f: isolated / "emps" / f for f in ds.files}
    # without download=True nothing is fetched
    calls.clear()
    with pytest.raises(InputError):
        datasets.fetch("kinova_gen3_joint7")
    assert calls == []


def test_download_hash_mismatch_is_input_error(monkeypatch):
    def changed_upstream(url, known_hash=None, **kw):
        raise ValueError(f"SHA256 hash of downloaded file does not match the known hash: expected {known_hash}")

    monkeypatch.setattr(datasets.pooch, "retrieve", changed_upstream)
    with pytest.raises(InputError, match=r"velocity_0\.030000readings\.csv: the downloaded file does not match"):
        datasets.fetch("kinova_gen3_joint7", download=True)


def test_download_network_error_is_input_error(monkeypatch):
    def offline(url, **kw):
        raise ConnectionError("Name or service not known")

    monkeypatch.setattr(datasets.pooch, "retrieve", offline)
    with pytest.raises(InputError, match="download of data set 'emps' failed"):
        datasets.fetch("emps", download=True)


# ---------------------------------------------------------------------- real data
@pytest.mark.realdata
@needs_real
def test_checksums_verify(real_data):
    for name in datasets.names():
        paths = datasets.fetch(name)
        ds = datasets.get(name)
        assert list(paths) == list(ds.files)
        for f, p in paths.items():
            assert p == real_data / name / f and p.is_file()
    assert datasets.list_datasets()["present"].all()


@pytest.mark.realdata
@needs_real
def test_corrupted_copy_refused(real_data, tmp_path, monkeypatch):
    copy = tmp_path / "data" / "harmonic_drive_catalog"
    copy.mkdir(parents=True)
    for f in datasets.get("harmonic_drive_catalog").files:
        shutil.copyfile(real_data / "harmonic_drive_catalog" / f, copy / f)
    target = copy / "efficiency_vs_input_speed.csv"
    raw = bytearray(target.read_bytes())
    i = raw.index(b"0.75")
    raw[i + 3] = ord("6")  # 0.75 -> 0.76: one byte changed
    target.write_bytes(bytes(raw))
    monkeypatch.setenv("GEARSPEC_DATA", str(tmp_path / "data"))
    expected = datasets.get("harmonic_drive_catalog").files["efficiency_vs_input_speed.csv"]
    import hashlib
    actual = hashlib.sha256(bytes(raw)).hexdigest()
    with pytest.raises(InputError) as err:
        datasets.load("harmonic_drive_catalog")
    msg = str(err.value)
    assert str(target) in msg and "checksum mismatch" in msg
    assert f"expected sha256 {expected}" in msg and f"got {actual}" in msg
    assert "no download exists" in msg


@pytest.mark.realdata
@needs_real
def test_env_before_cache_and_cache_alone(real_data, isolated, monkeypatch):
    # a set only in the user cache is found when GEARSPEC_DATA is unset ...
    shutil.copytree(real_data / "harmonic_drive_catalog", isolated / "harmonic_drive_catalog")
    monkeypatch.delenv("GEARSPEC_DATA")
    paths = datasets.fetch("harmonic_drive_catalog")
    assert all(p.parent == isolated / "harmonic_drive_catalog" for p in paths.values())
    # ... and GEARSPEC_DATA comes first when set
    monkeypatch.setenv("GEARSPEC_DATA", str(real_data))
    paths = datasets.fetch("harmonic_drive_catalog")
    assert all(p.parent == real_data / "harmonic_drive_catalog" for p in paths.values())


@pytest.mark.realdata
@needs_real
def test_load_emps(real_data):
    import scipy.io

    rec = datasets.load("emps")
    assert isinstance(rec, Recording)
    assert len(rec) == 24841 and rec.n_read == 24841
    assert rec.unit == "m" and rec.torque_unit == "N"
    assert rec.gear is not None and rec.gear.unit == "m" and rec.gear.stages == ()
    mat = scipy.io.loadmat(real_data / "emps" / "DATA_EMPS.mat")
    gtau = float(mat["gtau"].ravel()[0])
    assert rec.meta["gtau"] == pytest.approx(gtau)
    assert gtau == pytest.approx(35.15, abs=0.01)
    vir = mat["vir"].ravel()
    for i in (0, 12345, 24840):
        assert rec.tau[i] == pytest.approx(gtau * vir[i], rel=1e-12)
    np.testing.assert_allclose(rec.theta, mat["qm"].ravel())
    np.testing.assert_allclose(rec.t, mat["t"].ravel())
    assert rec.meta["part"] == "DATA_EMPS"


@pytest.mark.realdata
@needs_real
def test_load_emps_pulses(real_data):
    rec = datasets.load("emps", part="DATA_EMPS_PULSES")
    assert len(rec) == 24841 and rec.unit == "m"
    assert "pulses_N" in rec.data and "qg" in rec.data
    assert rec.meta["part"] == "DATA_EMPS_PULSES"
    assert datasets.load("emps", part="pulses").meta["part"] == "DATA_EMPS_PULSES"
    with pytest.raises(InputError, match="unknown part 'bogus'.*DATA_EMPS_PULSES"):
        datasets.load("emps", part="bogus")


def _rows(path: Path) -> int:
    return sum(1 for line in path.read_text().splitlines() if line.strip())


@pytest.mark.realdata
@needs_real
def test_load_kinova(real_data):
    folder = real_data / "kinova_gen3_joint7"
    files = sorted(folder.glob("velocity_*readings.csv"), key=lambda p: float(p.name[9:-12]))
    expected_rows = [_rows(p) for p in files]
    assert sum(expected_rows) == 29739

    rec = datasets.load("kinova_gen3_joint7")
    assert isinstance(rec, Recording)
    assert len(rec) == sum(expected_rows) and rec.n_read == sum(expected_rows)
    assert rec.unit == "rad" and rec.gear.name == "Kinova Gen3, joint 7"
    assert list(np.unique(rec.run)) == list(range(10))
    assert list(rec.data.groupby("run").size()) == expected_rows
    cv = datasets.commanded_velocity(rec)
    assert cv == {0: 0.03, 1: 0.05, 2: 0.09, 3: 0.1, 4: 0.3, 5: 0.5, 6: 0.7, 7: 0.9, 8: 1.3, 9: 1.5}
    assert rec.meta["commanded_velocity"] == cv
    for col in ("torque_command", "velocity", "current_command", "current", "friction_estimate"):
        assert col in rec.data
    # t from fs = 999 Hz
    t0 = rec.t[rec.run == 0]
    assert t0[0] == 0 and np.diff(t0) == pytest.approx(1 / 999)
    # position unwrapped: the fast runs cross 2*pi once and keep going
    for run, v in cv.items():
        th = rec.theta[rec.run == run]
        assert np.diff(th).min() > -0.1, run
        if v >= 0.9:
            assert np.ptp(th) > 2.5
    assert any("unwrapped" in n for n in rec.notes)
    # the reached velocity on the plateau (second half) is near the commanded one at high speed
    for run in (8, 9):
        sel = rec.run == run
        n = sel.sum()
        v = np.median(rec.channel("velocity")[sel][n // 2:])
        assert v == pytest.approx(cv[run], rel=0.05)


@pytest.mark.realdata
@needs_real
def test_load_kinova_parts(real_data):
    one = datasets.load("kinova_gen3_joint7", part="0.3")
    assert len(np.unique(one.run)) == 1
    assert len(one) == _rows(real_data / "kinova_gen3_joint7" / "velocity_0.300000readings.csv")
    assert datasets.commanded_velocity(one) == {0: 0.3}
    two = datasets.load("kinova_gen3_joint7", part=[1.5, "0.03"])
    assert datasets.commanded_velocity(two) == {0: 0.03, 1: 1.5}
    with pytest.raises(InputError, match="no run at commanded speed 0.2 rad/s.*0.03, 0.05"):
        datasets.load("kinova_gen3_joint7", part="0.2")


@pytest.mark.realdata
@needs_real
def test_kinova_breakaway(real_data):
    df = datasets.kinova_breakaway()
    assert list(df.columns) == ["breakaway_torque", "ramp_rate"]
    assert len(df) == 50
    assert df.groupby("ramp_rate").size().tolist() == [10] * 5


@pytest.mark.realdata
@needs_real
def test_load_catalog(real_data):
    tables = datasets.load("harmonic_drive_catalog")
    assert set(tables) == {"compensation_vs_load_torque", "efficiency_vs_input_speed"}
    eff = tables["efficiency_vs_input_speed"]
    comp = tables["compensation_vs_load_torque"]
    assert isinstance(eff, pd.DataFrame) and list(eff.columns) == ["input_speed_rpm", "efficiency_at_rated_torque"]
    assert list(comp.columns) == ["output_load_torque_Nm", "compensation_coefficient"]
    assert comp["compensation_coefficient"].iloc[-1] == 1.0 and comp["output_load_torque_Nm"].iloc[-1] == 96.0
    assert 67.2 in comp["output_load_torque_Nm"].tolist()
    one = datasets.load("harmonic_drive_catalog", part="efficiency_vs_input_speed")
    pd.testing.assert_frame_equal(one, eff)


def test_damaged_cache_copy_is_downloaded_again(monkeypatch, isolated):
    ds = datasets.get("emps")
    folder = isolated / "emps"
    folder.mkdir(parents=True)
    for f in ds.files:
        (folder / f).write_bytes(b"not the registered file")
    with pytest.raises(InputError, match="checksum mismatch.*`gearspec data fetch emps` downloads it again"):
        datasets.fetch("emps")
    calls = []
    monkeypatch.setattr(datasets.pooch, "retrieve",
                        lambda url, known_hash=None, fname=None, path=None, **kw: calls.append(fname) or str(Path(path) / fname))
    datasets.fetch("emps", download=True)
    assert calls == list(ds.files)
