"""Recording loaders (CONTRACTS.md section 1): formats, column mapping and scaling, unwrapping,
current to torque, and one clear refusal (InputError) or counted exclusion per kind of bad input."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gearspec.errors import GearspecWarning, InputError
from gearspec.recording import Recording, load_recording, parse_assignments

FS = 1000.0
TWO_PI = 2 * np.pi


# ---------------------------------------------------------------------- helpers
def drive(n: int = 2000, fs: float = FS, speed: float = 2.0, theta0: float = 0.3, seed: int = 0) -> dict:
    """A drive turning at constant speed with friction torque, a position-locked ripple and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    theta = theta0 + speed * t
    torque = 0.2 + 0.02 * np.sin(5 * theta) + 0.005 * rng.standard_normal(n)
    return {"t": t, "theta": theta, "torque": torque}


def write_csv(path, columns: dict, sep: str = ",", header: bool = True):
    pd.DataFrame(columns).to_csv(path, sep=sep, index=False, header=header, float_format="%.17g")
    return path


def quiet(fn, *args, **kwargs):
    """Call fn and fail on any GearspecWarning (the input is clean and should load silently)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", GearspecWarning)
        return fn(*args, **kwargs)


def assert_ledger(rec: Recording) -> None:
    """Nothing is dropped silently: every row read is either usable or counted under a reason."""
    assert rec.n_read == len(rec.data) + sum(rec.excluded.values())


def assert_same_drive(rec: Recording, d: dict) -> None:
    np.testing.assert_allclose(rec.t, d["t"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.theta, d["theta"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.data["torque"].to_numpy(), d["torque"], rtol=0, atol=1e-12)


# ---------------------------------------------------------------------- formats
def test_csv_comma_round_trip(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", d)
    rec = quiet(load_recording, path)
    assert_same_drive(rec, d)
    assert len(rec) == 2000 and rec.n_read == 2000
    assert not rec.excluded
    assert rec.unit == "rad" and rec.signal == "torque"
    assert (rec.run == 0).all()
    assert rec.sources == [str(path)]
    np.testing.assert_allclose(rec.tau, d["torque"], rtol=0, atol=1e-12)
    assert_ledger(rec)


@pytest.mark.parametrize("sep_written, sep_given", [(";", None), (";", ";"), ("\t", None), ("\t", "\t"),
                                                    (" ", None), (" ", "whitespace"), (" ", " ")])
def test_csv_other_separators(tmp_path, sep_written, sep_given):
    d = drive()
    path = write_csv(tmp_path / "a.csv", d, sep=sep_written)
    rec = quiet(load_recording, path, sep=sep_given)
    assert list(rec.data.columns[:3]) == ["t", "theta", "torque"]
    assert_same_drive(rec, d)
    assert_ledger(rec)


def test_csv_runs_of_blanks_with_whitespace_sep(tmp_path):
    d = drive(n=300)
    lines = ["  t     theta    torque"] + [f"  {a!r}   {b!r}\t {c!r}  " for a, b, c in zip(*(d[k].tolist() for k in ("t", "theta", "torque")))]
    path = tmp_path / "a.dat"
    path.write_text("\n".join(lines) + "\n")
    rec = quiet(load_recording, path, sep="whitespace")
    assert_same_drive(rec, d)


@pytest.mark.parametrize("names", ["t, theta ,torque", ["t", "theta", "torque"]])
def test_csv_no_header_with_names(tmp_path, names):
    d = drive()
    path = write_csv(tmp_path / "a.csv", d, header=False)
    rec = quiet(load_recording, path, header=False, names=names)
    assert list(rec.data.columns) == ["t", "theta", "torque", "run"]
    assert len(rec) == 2000  # the first line is data, not a header
    assert_same_drive(rec, d)
    assert_ledger(rec)


def test_csv_no_header_without_names_is_refused(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive(), header=False)
    with pytest.raises(InputError, match=r"a\.csv: --no-header needs --names"):
        load_recording(path, header=False)


def test_csv_names_with_header_is_refused(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"--names is for files without a header row; add --no-header"):
        load_recording(path, names="t,theta,torque")


@pytest.mark.parametrize("names", ["theta,torque", "t,theta,torque,temperature"])
def test_csv_names_count_must_match_the_columns(tmp_path, names):
    path = write_csv(tmp_path / "a.csv", drive(), header=False)
    k = len(names.split(","))
    with pytest.raises(InputError, match=rf"--names gives {k} names but the file has 3 columns"):
        load_recording(path, header=False, names=names)


def test_csv_trailing_separator_on_every_line_is_accepted(tmp_path):
    d = drive(n=500)
    lines = ["t,theta,torque"] + [f"{a!r},{b!r},{c!r}," for a, b, c in zip(*(d[k].tolist() for k in ("t", "theta", "torque")))]
    path = tmp_path / "a.csv"
    path.write_text("\n".join(lines) + "\n")
    rec = quiet(load_recording, path)
    assert list(rec.data.columns) == ["t", "theta", "torque", "run"]
    assert_same_drive(rec, d)


def test_csv_more_fields_than_header_names_is_refused(tmp_path):
    d = drive(n=500)
    lines = ["t,theta,torque"] + [f"{a!r},{b!r},{c!r},7.5" for a, b, c in zip(*(d[k].tolist() for k in ("t", "theta", "torque")))]
    path = tmp_path / "a.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"a\.csv: the header row names 3 columns but data rows have 4 fields"):
        load_recording(path)


def test_csv_wrong_separator_gives_one_column_and_suggests_sep(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive(), sep=";")
    with pytest.raises(InputError, match=r"only one column \('t;theta;torque'\) was found with --sep ','; .*give --sep"):
        load_recording(path, sep=",")


def test_parquet_round_trip_keeps_extra_channels(tmp_path):
    d = drive()
    d["torque_sensor_2"] = 2 * d["torque"]
    path = tmp_path / "a.parquet"
    pd.DataFrame(d).to_parquet(path, index=False)
    rec = quiet(load_recording, path)
    assert_same_drive(rec, d)
    np.testing.assert_array_equal(rec.channel("torque_sensor_2"), d["torque_sensor_2"])
    with pytest.raises(KeyError, match="no channel 'nope'"):
        rec.channel("nope")
    assert_ledger(rec)


def test_mat_column_vectors_and_scalars_to_meta(tmp_path):
    scipy_io = pytest.importorskip("scipy.io")
    d = drive()
    path = tmp_path / "emps_like.mat"
    scipy_io.savemat(path, {"t": d["t"].reshape(-1, 1), "qm": d["theta"].reshape(-1, 1),
                            "vir": (d["torque"] / 35.15).reshape(-1, 1), "gtau": 35.15, "fs": FS})
    rec = quiet(load_recording, path, map="theta=qm,torque=vir", scale="torque=gtau")
    assert rec.meta["gtau"] == 35.15 and rec.meta["fs"] == FS
    assert "gtau" not in rec.data.columns
    assert_same_drive(rec, d)
    assert_ledger(rec)


def test_mat_row_vectors_and_short_vectors(tmp_path):
    scipy_io = pytest.importorskip("scipy.io")
    d = drive()
    path = tmp_path / "a.mat"
    scipy_io.savemat(path, {**d, "calib": np.array([1.0, 2.0, 3.0])})  # 1-D arrays are saved as rows (1, n)
    with pytest.warns(GearspecWarning, match=r"calib .*not vectors of length 2000; kept in meta"):
        rec = load_recording(path)
    assert_same_drive(rec, d)
    np.testing.assert_array_equal(rec.meta["calib"], [1.0, 2.0, 3.0])


def test_npz_round_trip_with_scalar_in_meta(tmp_path):
    d = drive()
    path = tmp_path / "a.npz"
    np.savez(path, **d, k=0.5)
    rec = quiet(load_recording, path, scale={"torque": "k"})
    assert rec.meta == {"k": 0.5}
    np.testing.assert_allclose(rec.data["torque"], 0.5 * d["torque"], rtol=1e-15)
    assert_ledger(rec)


def test_folder_gives_one_run_per_file_in_name_order(tmp_path):
    a, b = drive(n=1000, seed=1), drive(n=1500, speed=-3.0, seed=2)
    write_csv(tmp_path / "b_second.csv", b)
    write_csv(tmp_path / "a_first.csv", a)
    (tmp_path / "notes.md").write_text("not a recording")
    rec = quiet(load_recording, tmp_path)
    assert [Path(p).name for p in rec.sources] == ["a_first.csv", "b_second.csv"]
    assert rec.n_read == 2500 and len(rec) == 2500
    np.testing.assert_array_equal(rec.run, [0] * 1000 + [1] * 1500)
    np.testing.assert_allclose(rec.theta[1000:], b["theta"], atol=1e-12)
    assert rec.pieces() == [(0, 0, 1000), (1, 1000, 2500)]
    assert_ledger(rec)


def test_several_files_mixed_formats_give_separate_runs(tmp_path):
    a, b = drive(n=800, seed=1), drive(n=900, seed=2)
    p1 = write_csv(tmp_path / "x.csv", a)
    p2 = tmp_path / "y.npz"
    np.savez(p2, **b)
    rec = quiet(load_recording, [p2, p1])
    np.testing.assert_array_equal(np.unique(rec.run[:900]), [0])
    np.testing.assert_array_equal(np.unique(rec.run[900:]), [1])
    np.testing.assert_allclose(rec.theta[:900], b["theta"], atol=1e-12)
    assert_ledger(rec)


def test_run_columns_of_several_files_are_renumbered(tmp_path):
    a, b = drive(n=1000, seed=1), drive(n=1000, seed=2)
    a["run"] = np.repeat([5, 9], 500)
    b["run"] = np.repeat([5, 7], 500)
    write_csv(tmp_path / "a.csv", a)
    write_csv(tmp_path / "b.csv", b)
    rec = load_recording(tmp_path)
    np.testing.assert_array_equal(rec.run, np.repeat([0, 1, 2, 3], 500))
    assert any("renumbered 0..1" in n for n in rec.notes) and any("renumbered 2..3" in n for n in rec.notes)


def test_empty_folder_is_refused(tmp_path):
    (tmp_path / "readme.md").write_text("x")
    with pytest.raises(InputError, match=r"the folder holds no recording files"):
        load_recording(tmp_path)


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".npz"])
def test_save_then_load_gives_the_same_data(tmp_path, suffix):
    d = drive()
    d["temperature"] = np.linspace(25.0, 31.0, 2000)
    d["run"] = np.repeat([0, 1], 1000)
    rec = Recording.from_arrays(**d, gear="silo4-joint3")
    path = rec.save(tmp_path / f"saved{suffix}")
    again = quiet(load_recording, path, "silo4-joint3")
    pd.testing.assert_frame_equal(again.data, rec.data, check_exact=True)
    assert again.n_read == 2000 and not again.excluded


def test_parquet_with_a_stored_time_index(tmp_path):
    d = drive()
    path = tmp_path / "a.parquet"
    pd.DataFrame(d).set_index("t").to_parquet(path)
    rec = quiet(load_recording, path)
    assert_same_drive(rec, d)


def test_mat_text_and_struct_variables_are_ignored_with_a_warning(tmp_path):
    scipy_io = pytest.importorskip("scipy.io")
    path = tmp_path / "a.mat"
    scipy_io.savemat(path, {**drive(), "operator": "anna", "setup": {"kp": 3.0}})
    with pytest.warns(GearspecWarning, match=r"variables operator, setup are not numeric vectors .*; ignored"):
        rec = load_recording(path)
    assert "operator" not in rec.meta and "setup" not in rec.data.columns


def test_mat_struct_only_is_refused(tmp_path):
    scipy_io = pytest.importorskip("scipy.io")
    path = tmp_path / "a.mat"
    scipy_io.savemat(path, {"data": {"t": np.arange(3.0)}})
    with pytest.raises(InputError, match=r"a\.mat: holds no numeric vectors \(variables: data\)"):
        load_recording(path)


def test_save_as_mat_is_refused(tmp_path):
    rec = Recording.from_arrays(**drive())
    with pytest.raises(InputError, match=r"cannot write recordings as '\.mat' \(use \.csv, \.parquet or \.npz\)"):
        rec.save(tmp_path / "x.mat")


# ---------------------------------------------------------------------- map, scale, fs
@pytest.mark.parametrize("mapping", ["t=time, theta=qm ,torque=vir", {"t": "time", "theta": "qm", "torque": "vir"}])
def test_map_renames_source_columns(tmp_path, mapping):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"time": d["t"], "qm": d["theta"], "vir": d["torque"]})
    rec = quiet(load_recording, path, map=mapping)
    assert list(rec.data.columns) == ["t", "theta", "torque", "run"]
    assert_same_drive(rec, d)


def test_map_onto_an_existing_canonical_name_keeps_the_original_as_a_channel(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {**d, "torque_filtered": d["torque"] + 1.0})
    rec = quiet(load_recording, path, map="torque=torque_filtered")
    np.testing.assert_allclose(rec.tau, d["torque"] + 1.0, atol=1e-12)
    np.testing.assert_allclose(rec.channel("torque_original"), d["torque"], atol=1e-12)


@pytest.mark.parametrize("scale", ["torque=35.15, theta=-1", {"torque": 35.15, "theta": -1}, {"torque": "35.15", "theta": "-1"}])
def test_scale_multiplies_after_mapping(tmp_path, scale):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"t": d["t"], "q": -d["theta"], "vir": d["torque"] / 35.15})
    rec = quiet(load_recording, path, map="theta=q,torque=vir", scale=scale)
    assert_same_drive(rec, d)


def test_scale_naming_a_source_column_after_map_says_to_use_the_canonical_name(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"t": d["t"], "theta": d["theta"], "vir": d["torque"]})
    with pytest.raises(InputError, match=r"--scale names column 'vir', which is not there .*use --scale torque="):
        load_recording(path, map="torque=vir", scale="vir=2")


def test_scale_by_unknown_name_is_refused(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, **drive(), gtau=2.0)
    with pytest.raises(InputError, match=r"--scale torque=gt: 'gt' is neither a number nor a scalar stored in the file"):
        load_recording(path, scale="torque=gt")


def test_scale_by_a_stored_vector_is_refused(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, **drive(), gains=np.array([1.0, 2.0]))
    with pytest.raises(InputError, match=r"--scale torque=gains: 'gains' .* not a single number"):
        load_recording(path, scale="torque=gains")


@pytest.mark.parametrize("factor", ["0", "nan", "inf"])
def test_scale_by_zero_or_non_finite_is_refused(tmp_path, factor):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=rf"--scale torque={factor}(\.0)?: the factor must be a finite, non-zero number"):
        load_recording(path, scale=f"torque={factor}")


def test_fs_gives_time_from_the_sample_index(tmp_path):
    d = drive(n=1200)
    path = write_csv(tmp_path / "a.csv", {"theta": d["theta"], "torque": d["torque"]})
    rec = quiet(load_recording, path, fs=250.0)
    np.testing.assert_allclose(rec.t, np.arange(1200) / 250.0, rtol=0, atol=1e-15)
    assert any("t = sample index / 250 Hz" in n for n in rec.notes)
    assert_ledger(rec)


def test_fs_with_a_time_column_warns_and_uses_the_column(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", d)
    with pytest.warns(GearspecWarning, match=r"has a time column 't'; --fs 250 is ignored"):
        rec = load_recording(path, fs=250.0)
    np.testing.assert_allclose(rec.t, d["t"], atol=1e-15)


@pytest.mark.parametrize("fs", [0.0, -100.0, float("nan")])
def test_fs_must_be_positive(tmp_path, fs):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"theta": d["theta"], "torque": d["torque"]})
    with pytest.raises(InputError, match=r"--fs must be a positive sample rate in Hz"):
        load_recording(path, fs=fs)


@pytest.mark.parametrize("step", [1, 2, 10])  # sample numbers or ms at 1 kHz; ms at 500 Hz; ms at 100 Hz
def test_time_in_ms_or_sample_numbers_warns(tmp_path, step):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {**d, "t": step * np.arange(2000.0)})
    with pytest.warns(GearspecWarning, match=rf"median time step is {step} s; if 't' is in ms or sample numbers, "
                                             r"use --scale t=0\.001 or --fs HZ"):
        rec = load_recording(path)
    assert len(rec) == 2000


# ---------------------------------------------------------------------- unwrapping
@pytest.mark.parametrize("offset", [0.0, -np.pi])
def test_wrapped_radians_are_unwrapped(offset):
    t = np.arange(5000) / FS
    true = 1.0 + 3.0 * t  # 15 rad: two wraps
    wrapped = np.mod(true - offset, TWO_PI) + offset
    n_wraps = int((np.abs(np.diff(wrapped)) > 6).sum())
    assert n_wraps == (2 if offset == 0 else 3)
    rec = quiet(Recording.from_arrays, t=t, theta=wrapped, torque=np.full(5000, 0.2) + 0.01 * np.sin(7 * true))
    assert np.abs(np.diff(rec.theta)).max() < 0.01
    np.testing.assert_allclose(rec.theta - rec.theta[0], true - true[0], atol=1e-9)
    assert any(f"wraps into a range of 2*pi ({n_wraps} wraps in run 0); unwrapped" in n for n in rec.notes)
    assert "unwrapped" in rec.summary()


def test_position_wrapped_at_360_warns_about_degrees():
    t = np.arange(3000) / 100.0
    deg = np.mod(30.0 * t, 360.0)  # 900 degrees
    with pytest.warns(GearspecWarning, match=r"wraps at 360: it looks like degrees, not radians.*--scale theta=0\.0174533"):
        rec = Recording.from_arrays(t=t, theta=deg, torque=0.2 + 0.01 * np.cos(deg))
    np.testing.assert_allclose(rec.theta, 30.0 * t, atol=1e-9)
    assert any("range of 360" in n and "unwrapped" in n for n in rec.notes)


def test_degrees_scaled_to_radians_are_unwrapped_with_2pi(tmp_path):
    t = np.arange(3000) / 100.0
    path = write_csv(tmp_path / "a.csv", {"t": t, "theta": np.mod(30.0 * t, 360.0), "torque": 0.2 + 0.01 * np.sin(t)})
    rec = quiet(load_recording, path, scale="theta=0.0174533")
    # 360 * 0.0174533 is 2.7e-6 rad more than 2 pi: each unwrapped turn keeps that error
    np.testing.assert_allclose(rec.theta, 30.0 * t * np.pi / 180, atol=1e-5)
    assert np.abs(np.diff(rec.theta)).max() < 0.01
    assert any("range of 2*pi" in n for n in rec.notes)


def test_back_and_forth_motion_is_not_unwrapped():
    t = np.arange(4000) / FS
    theta = 2.5 * np.sin(TWO_PI * 0.5 * t)  # range 5 rad < 2 pi, no jumps
    rec = quiet(Recording.from_arrays, t=t, theta=theta, torque=0.1 * np.sign(np.cos(TWO_PI * 0.5 * t)) + 0.01 * np.sin(9 * theta))
    np.testing.assert_array_equal(rec.theta, theta)
    assert not any("unwrapped" in n for n in rec.notes)


def test_linear_axis_is_never_unwrapped_and_uses_newton(tmp_path):
    t = np.arange(3000) / FS
    x = np.mod(0.2 * t, 0.05)  # a sawtooth in m is not a wrap on a linear axis
    rec = Recording.from_arrays(t=t, theta=x, torque=20 + np.sin(100 * x), gear="emps")
    assert rec.unit == "m" and rec.torque_unit == "N" and rec.speed_unit == "m/s"
    np.testing.assert_array_equal(rec.theta, x)


# ---------------------------------------------------------------------- current to torque
def test_current_to_torque_at_the_motor():
    d = drive()
    current = d.pop("torque") / 0.13
    rec = quiet(Recording.from_arrays, **d, current=current, gear="lola-a")
    assert rec.signal == "current"
    np.testing.assert_allclose(rec.tau, 0.13 * current, rtol=1e-15)
    assert any("torque = 0.13 Nm/A x current" in n for n in rec.notes)
    assert_ledger(rec)


def test_current_to_torque_at_the_output_includes_the_ratio(tmp_path):
    d = drive()
    current = d.pop("torque")
    gear = {"name": "output joint", "reference": "output", "torque_constant": 0.05,
            "stages": [{"name": "hd", "kind": "harmonic", "ratio": 100.0}]}
    path = write_csv(tmp_path / "a.csv", {**d, "i_q": current})
    rec = quiet(load_recording, path, gear, map="current=i_q")
    np.testing.assert_allclose(rec.tau, 5.0 * current, rtol=1e-12)
    assert any("x ratio 100" in n for n in rec.notes)


@pytest.mark.parametrize("gear", [None, "kinova-gen3-joint7"])
def test_current_without_torque_constant_is_refused(gear):
    d = drive()
    d["current"] = d.pop("torque")
    with pytest.raises(InputError, match=r"motor current, which needs the gear spec's torque_constant \(Nm/A\)"):
        Recording.from_arrays(**d, gear=gear)


def test_torque_is_analysed_when_both_unless_signal_current():
    d = drive()
    current = np.full(2000, 1.0) + 0.01 * np.sin(d["theta"])
    rec = quiet(Recording.from_arrays, **d, current=current, gear="lola-a")
    assert rec.signal == "torque"
    np.testing.assert_allclose(rec.tau, d["torque"])
    np.testing.assert_allclose(rec.channel("current"), current)
    rec = quiet(Recording.from_arrays, **d, current=current, gear="lola-a", signal="current")
    np.testing.assert_allclose(rec.tau, 0.13 * current)


def test_signal_current_without_a_current_column_is_refused(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"--signal current but the file has no 'current' column"):
        load_recording(path, "lola-a", signal="current")


def test_files_that_analyse_different_signals_are_refused(tmp_path):
    a, b = drive(seed=1), drive(seed=2)
    b["current"] = b.pop("torque")
    write_csv(tmp_path / "a.csv", a)
    write_csv(tmp_path / "b.csv", b)
    with pytest.raises(InputError, match=r"b\.csv: analyses 'current' but earlier files analyse 'torque'; give --signal"):
        load_recording(tmp_path, "lola-a")


# ---------------------------------------------------------------------- bad input: files
def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nothere\.csv: no such file"):
        load_recording(tmp_path / "nothere.csv")


def test_empty_file(tmp_path):
    path = tmp_path / "a.csv"
    path.write_bytes(b"")
    with pytest.raises(InputError, match=r"a\.csv: the file is empty"):
        load_recording(path)


def test_blank_lines_only_file(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("\n\n  \n")
    with pytest.raises(InputError, match=r"a\.csv: the file is empty"):
        load_recording(path)


def test_header_only_file(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("t,theta,torque\n")
    with pytest.raises(InputError, match=r"a\.csv: the file has a header but no data rows"):
        load_recording(path)


def test_unknown_suffix(tmp_path):
    path = tmp_path / "a.xlsx"
    path.write_bytes(b"PK\x03\x04junk")
    with pytest.raises(InputError, match=r"a\.xlsx: unknown file type '\.xlsx' \(accepted: \.csv, \.parquet, \.mat, \.npz\)"):
        load_recording(path)


@pytest.mark.parametrize("name, what", [("a.parquet", "parquet"), ("a.npz", ".npz"), ("a.mat", "a MATLAB file")])
def test_corrupt_binary_files(tmp_path, name, what):
    path = tmp_path / name
    path.write_bytes(b"this is not a binary table at all" * 10)
    with pytest.raises(InputError, match=rf"{name.replace('.', '[.]')}: cannot be read as {what}"):
        load_recording(path)


def test_missing_theta_lists_columns_and_suggests_map(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"t": d["t"], "pos": d["theta"], "torque": d["torque"]})
    with pytest.raises(InputError, match=r"a\.csv: no column 'theta' \(position\); columns are: t, pos, torque; "
                                         r"name the position column with --map theta=NAME"):
        load_recording(path)


def test_missing_time_without_fs(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"time_s": d["t"], "theta": d["theta"], "torque": d["torque"]})
    with pytest.raises(InputError, match=r"no time column 't' and no --fs; columns are: time_s, theta, torque; "
                                         r"map the time column with --map t=NAME or give the sample rate with --fs HZ"):
        load_recording(path)


def test_neither_torque_nor_current(tmp_path):
    d = drive()
    path = write_csv(tmp_path / "a.csv", {"t": d["t"], "theta": d["theta"], "tau_m": d["torque"]})
    with pytest.raises(InputError, match=r"neither 'torque' nor 'current' is there; columns are: t, theta, tau_m; "
                                         r"map one with --map torque=NAME or --map current=NAME"):
        load_recording(path)


def test_map_naming_a_column_that_is_not_there(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"a\.csv: no column 'qm' \(given in --map theta=qm\); columns are: t, theta, torque"):
        load_recording(path, map="theta=qm")


def test_map_to_a_non_canonical_name(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"--map: 'position' is not a canonical column \(t, theta, torque, current"):
        load_recording(path, map="position=theta")


def test_map_one_source_to_two_columns_is_refused(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"--map: column 'theta' is given for both theta and velocity"):
        load_recording(path, map="theta=theta,velocity=theta")


@pytest.mark.parametrize("col, row", [("theta", 3), ("torque", 1500), ("t", 2000)])
def test_non_numeric_cell_names_column_and_row(tmp_path, col, row):
    d = {k: [repr(x) for x in v.tolist()] for k, v in drive().items()}
    d[col][row - 1] = "12.5 Nm" if col == "torque" else "#err"
    path = write_csv(tmp_path / "a.csv", d)
    value = "12.5 Nm" if col == "torque" else "#err"
    with pytest.raises(InputError, match=rf"a\.csv: column '{col}', data row {row}: '{value}' is not a number"):
        load_recording(path)


def test_non_numeric_cell_in_an_optional_canonical_column(tmp_path):
    d = drive()
    temp = [f"{x:.2f}" for x in np.linspace(20, 30, 2000)]
    temp[10] = "n/a?"
    path = write_csv(tmp_path / "a.csv", {**d, "temperature": temp})
    with pytest.raises(InputError, match=r"column 'temperature', data row 11: 'n/a\?' is not a number"):
        load_recording(path)


def test_too_many_nan_is_refused():
    d = drive()
    d["torque"][100:300] = np.nan  # 10 % of rows
    with pytest.raises(InputError, match=r"column 'torque' is NaN or inf in 10% of rows \(first at data row 101\); too many to exclude"):
        Recording.from_arrays(**d)


def test_all_nan_column_is_refused():
    d = drive()
    d["theta"][:] = np.nan
    with pytest.raises(InputError, match=r"column 'theta' holds no finite number"):
        Recording.from_arrays(**d)


def test_a_few_nan_and_inf_are_excluded_and_counted(tmp_path):
    d = drive()
    d["torque"][[10, 11, 500]] = np.nan
    d["theta"][700] = np.inf
    d["t"][900] = -np.inf
    d["theta"][10] = np.nan  # same row as a NaN torque: counted once
    path = tmp_path / "a.npz"
    np.savez(path, **d)
    with pytest.warns(GearspecWarning, match=r"5 rows with NaN or inf in t, theta, torque excluded"):
        rec = load_recording(path)
    assert rec.excluded == {"nan_or_inf": 5}
    assert len(rec) == 1995 and rec.n_read == 2000
    assert np.isfinite(rec.data[["t", "theta", "torque"]].to_numpy()).all()
    assert "nan_or_inf 5" in rec.summary()
    assert_ledger(rec)


def test_empty_cells_in_a_csv_are_nan_and_counted(tmp_path):
    d = {k: [repr(x) for x in v.tolist()] for k, v in drive().items()}
    d["torque"][42] = ""
    path = write_csv(tmp_path / "a.csv", d)
    rec = load_recording(path)
    assert rec.excluded == {"nan_or_inf": 1}
    assert 42 / FS not in rec.t
    assert_ledger(rec)


def test_duplicate_times_are_excluded_and_counted():
    d = drive()
    for i in (100, 101, 700, 1999):
        d["t"][i] = d["t"][i - 1]
    with pytest.warns(GearspecWarning, match=r"4 rows with duplicate or backward time excluded"):
        rec = Recording.from_arrays(**d)
    assert rec.excluded == {"duplicate_time": 4}
    assert (np.diff(rec.t) > 0).all()
    assert_ledger(rec)


def test_time_rounded_to_whole_seconds_is_refused():
    d = drive(n=3000, fs=100.0)
    d["t"] = np.floor(d["t"])
    with pytest.raises(InputError, match=r"column 't' repeats the previous time in 2970 of 3000 rows; .*right unit"):
        Recording.from_arrays(**d)


def test_a_few_backward_times_are_excluded_and_counted():
    d = drive()
    d["t"][[300, 1200, 1201]] -= 0.0105  # three samples stamped before their predecessor
    rec = Recording.from_arrays(**d)
    assert rec.excluded == {"non_increasing_time": 3}
    assert (np.diff(rec.t) > 0).all()
    assert len(rec) == 1997
    assert_ledger(rec)


def test_time_reset_is_refused_and_suggests_a_run_column():
    a, b = drive(n=1000, seed=1), drive(n=1000, seed=2)
    joined = {k: np.concatenate([a[k], b[k]]) for k in a}
    with pytest.raises(InputError, match=r"column 't' goes backwards in 999 of 2000 rows \(first at data row 1001: "
                                         r"t = 0 after 0\.999\); if the file holds several experiments, give each "
                                         r"its own file or a 'run' column"):
        Recording.from_arrays(**joined)
    rec = quiet(Recording.from_arrays, **joined, run=np.repeat([3, 4], 1000))  # the fix the message suggests
    np.testing.assert_array_equal(rec.run, np.repeat([0, 1], 1000))
    assert len(rec.pieces()) == 2


def test_row_numbers_in_messages_count_rows_excluded_before():
    d = drive()
    d["theta"][5] = np.nan  # excluded first; must not shift the row named below
    d["t"][500:700] -= 0.2
    with pytest.raises(InputError, match=r"goes backwards in 200 of 1999 rows \(first at data row 501: t = 0\.3 after 0\.499\)"):
        Recording.from_arrays(**d)


def test_run_column_must_hold_integers():
    d = drive()
    with pytest.raises(InputError, match=r"column 'run' holds non-integer values"):
        Recording.from_arrays(**d, run=np.linspace(0, 1, 2000))
    run = np.zeros(2000)
    run[7] = np.nan
    with pytest.raises(InputError, match=r"column 'run', data row 8: run ids must be integers, not NaN"):
        Recording.from_arrays(**d, run=run)


def test_position_that_never_changes():
    d = drive()
    d["theta"] = np.full(2000, 1.25)
    with pytest.raises(InputError, match=r"column 'theta' never changes \(always 1\.25\): the drive did not move, "
                                         r"or the wrong column is mapped to theta"):
        Recording.from_arrays(**d)


def test_position_that_only_jitters():
    d = drive()
    d["theta"] = 1.0 + 1e-4 * np.random.default_rng(5).standard_normal(2000)
    with pytest.raises(InputError, match=r"no motion: 'theta' only jitters \(range 0\.00\d+ rad\) without moving"):
        Recording.from_arrays(**d)


def test_position_that_toggles_between_two_encoder_counts():
    d = drive()
    q = TWO_PI / 4096
    d["theta"] = 100 * q + q * np.random.default_rng(6).integers(0, 2, 2000)
    with pytest.raises(InputError, match=r"no motion: 'theta' only jitters"):
        Recording.from_arrays(**d)


def test_slow_motion_with_a_coarse_encoder_is_motion():
    n = 20000
    t = np.arange(n) / FS
    q = TWO_PI / 4096
    theta = np.round((q / 0.2) * t / q) * q  # one count every 200 samples: 100 counts in all
    torque = 0.3 + 0.01 * np.random.default_rng(7).standard_normal(n)
    rec = quiet(Recording.from_arrays, t=t, theta=theta, torque=torque)
    assert len(rec) == n and not rec.excluded


def test_velocity_too_high_for_radians_warns():
    d = drive()
    d["theta"] = d["theta"] * 1500.0  # 3000 "rad/s": degrees or counts
    with pytest.warns(GearspecWarning, match=r"theta moves at up to 3e\+03 rad/s \(2\.86e\+04 rpm\), faster than any robot drive; "
                                             r"if it is in degrees use --scale theta=0\.0174533"):
        rec = Recording.from_arrays(**d)
    assert len(rec) == 2000  # a warning, not a refusal


def test_velocity_too_high_for_metres_warns():
    d = drive()
    d["theta"] = d["theta"] * 100.0  # 200 "m/s": mm
    with pytest.warns(GearspecWarning, match=r"theta moves at up to 200 m/s; if it is in mm use --scale theta=0\.001"):
        Recording.from_arrays(**d, gear="emps")


def test_saturated_torque_is_excluded_and_counted():
    n = 4000
    t = np.arange(n) / FS
    raw = 0.5 * np.sin(TWO_PI * 1.0 * t) + 0.01 * np.random.default_rng(8).standard_normal(n)
    clipped = np.minimum(raw, 0.45)  # the current loop's limit, reached once per cycle
    n_clipped = int((raw >= 0.45).sum())
    assert n_clipped > 100
    with pytest.warns(GearspecWarning, match=rf"column 'torque' sits at its extreme value in {n_clipped} rows; they look saturated"):
        rec = Recording.from_arrays(t=t, theta=1.5 * t, torque=clipped)
    assert rec.excluded == {"saturation": n_clipped}
    assert rec.data["torque"].max() < 0.45
    assert_ledger(rec)


def test_torque_saturated_almost_everywhere_is_refused_with_the_reason():
    n = 4000
    t = np.arange(n) / FS
    raw = 0.5 * np.sin(TWO_PI * 1.0 * t) + 0.01 * np.random.default_rng(8).standard_normal(n)
    n_sat = int((np.abs(raw) >= 0.02).sum())
    with pytest.raises(InputError, match=rf"no stretch of at least 20 contiguous usable rows \(longest \d+, {n - n_sat} usable "
                                         rf"of 4000; excluded: saturation {n_sat}\)"):
        Recording.from_arrays(t=t, theta=1.5 * t, torque=np.clip(raw, -0.02, 0.02))


def test_noise_free_piecewise_constant_torque_is_not_saturation():
    # a simulated Coulomb drive going forth and back: the torque only takes the values +0.3 and -0.3
    n = 4000
    t = np.arange(n) / FS
    v = np.where(t < 2.0, 1.0, -1.0)
    theta = np.concatenate(([0.0], np.cumsum(v[:-1]) / FS))
    torque = 0.3 * np.sign(v)
    rec = quiet(Recording.from_arrays, t=t, theta=theta, torque=torque)
    assert len(rec) == n and not rec.excluded


def test_exclusions_of_several_kinds_add_up(tmp_path):
    n = 4000
    t = np.arange(n) / FS
    raw = 0.5 * np.sin(TWO_PI * 1.0 * t) + 0.01 * np.random.default_rng(9).standard_normal(n)
    torque = np.minimum(raw, 0.45)
    n_sat = int((raw >= 0.45).sum())
    theta = 2.0 * t
    torque[[3, 4]] = np.nan
    t = t.copy()
    t[1000] = t[999]
    t[2000] -= 0.0015
    path = tmp_path / "a.parquet"
    pd.DataFrame({"t": t, "theta": theta, "torque": torque}).to_parquet(path)
    rec = load_recording(path)
    assert rec.excluded == {"nan_or_inf": 2, "duplicate_time": 1, "non_increasing_time": 1, "saturation": n_sat}
    assert rec.n_read == n
    assert_ledger(rec)
    assert "duplicate_time 1, nan_or_inf 2, non_increasing_time 1, saturation" in rec.summary()


def test_time_gap_is_noted_and_splits_pieces():
    d = drive()
    d["t"][1000:] += 1.0
    rec = quiet(Recording.from_arrays, **d)
    assert rec.pieces() == [(0, 0, 1000), (0, 1000, 2000)]
    assert any("gaps longer than 0.005 s (5 x the run's 99% step; set it with --max-gap) split runs: 1 gap(s)" in n
               for n in rec.notes)


def test_unknown_unit_and_signal_are_refused():
    with pytest.raises(InputError, match=r"unit must be 'rad' or 'm', got 'deg'"):
        Recording.from_arrays(**drive(), unit="deg")
    with pytest.raises(InputError, match=r"--signal must be 'torque' or 'current', got 'load'"):
        Recording.from_arrays(**drive(), signal="load")


# ---------------------------------------------------------------------- parse_assignments
def test_parse_assignments_forms():
    assert parse_assignments(None, "--map") == {}
    assert parse_assignments("", "--map") == {}
    assert parse_assignments(" theta = qm , torque=vir,", "--map") == {"theta": "qm", "torque": "vir"}
    assert parse_assignments("torque=35.15,theta=gtau,t=1e-3", "--scale", numeric=True) == \
        {"torque": 35.15, "theta": "gtau", "t": 0.001}
    assert parse_assignments("torque=a=b", "--map") == {"torque": "a=b"}


@pytest.mark.parametrize("text, bad", [("theta", "theta"), ("theta=qm,torque", "torque"), ("=qm", "=qm"),
                                       ("theta=", "theta=")])
def test_parse_assignments_refuses_malformed_parts(text, bad):
    with pytest.raises(InputError, match=rf"--map: '{bad}' is not of the form name=value"):
        parse_assignments(text, "--map")


def test_parse_assignments_refuses_a_name_given_twice():
    with pytest.raises(InputError, match=r"--scale: 'torque' is given twice"):
        parse_assignments("torque=2,theta=1,torque=3", "--scale", numeric=True)


def test_malformed_map_reaches_the_user_through_load_recording(tmp_path):
    path = write_csv(tmp_path / "a.csv", drive())
    with pytest.raises(InputError, match=r"--scale: 'torque:2' is not of the form name=value"):
        load_recording(path, scale="torque:2")


# ---------------------------------------------------------------------- irregular stamps, gaps, coarse clocks
def _jittered(n=6000, seed=11):
    """A 1 kHz log whose steps are uniform in [0.5, 1.5] ms (jitter of +-50 %)."""
    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.5e-3, 1.5e-3, n - 1)
    return dt


def _from_steps(dt, speed=2.0):
    t = np.concatenate(([0.0], np.cumsum(dt)))
    theta = 0.3 + speed * t
    torque = 0.2 + 0.02 * np.sin(5 * theta)
    return {"t": t, "theta": theta, "torque": torque}


def test_jittered_log_splits_exactly_at_the_gaps_longer_than_max_gap():
    dt = _jittered()
    at = {1000: 0.002, 2000: 0.004, 3000: 0.020, 4000: 0.100}  # gaps of known lengths, s
    for i, g in at.items():
        dt[i] = g
    rec = quiet(Recording.from_arrays, **_from_steps(dt), max_gap=0.01)
    assert rec.pieces() == [(0, 0, 3001), (0, 3001, 4001), (0, 4001, 6000)]  # the two gaps > 10 ms
    assert rec.pieces(max_gap=0.003) == [(0, 0, 2001), (0, 2001, 3001), (0, 3001, 4001), (0, 4001, 6000)]
    assert "gaps longer than 0.01 s (--max-gap) split runs: 2 gap(s)" in " ".join(rec.notes)
    # default rule: 5 x the 99th-percentile step; the 99th percentile of U(0.5, 1.5) ms is 1.49 ms
    # (sampling error of the quantile over 6000 steps ~ 0.002 ms), so the limit is 7.45 ms +- 0.05
    auto = quiet(Recording.from_arrays, **_from_steps(dt))
    assert auto.gap_limits()[0] == pytest.approx(5 * 1.49e-3, rel=0.01)
    assert auto.pieces() == [(0, 0, 3001), (0, 3001, 4001), (0, 4001, 6000)]  # 20 and 100 ms split, 2 and 4 ms not
    assert_ledger(auto)


def test_broad_step_distribution_of_rows_stored_at_rest_is_not_shredded():
    # a quasi-static map: 60 % of the steps 13 ms (rows at rest), 40 % 0.1-1 s (the shaft moving to the
    # next point); the old rule (5 x median = 65 ms) cut it into ~1600 pieces.  One pause of 60 s
    # (the operator stopping the sweep) is a real gap.
    rng = np.random.default_rng(3)
    n = 4000
    dt = np.where(rng.random(n - 1) < 0.6, 0.013, rng.uniform(0.1, 1.0, n - 1))
    dt[2500] = 60.0
    t = np.concatenate(([0.0], np.cumsum(dt)))
    theta = 0.002 * np.cumsum(dt > 0.05)  # steps of 2 mrad between rests
    theta = np.concatenate(([0.0], theta))
    torque = 0.05 * np.sign(np.sin(theta)) + 0.01 * np.sin(72 * theta) + 1e-3 * rng.standard_normal(n)
    rec = Recording.from_arrays(t=t, theta=theta, torque=torque)
    assert rec.pieces() == [(0, 0, 2501), (0, 2501, n)]
    assert 1.0 < rec.gap_limits()[0] <= 5.0  # 5 x the 99th percentile (~0.99 s) of the steps
    assert len(rec.pieces(max_gap=5 * 0.013)) > 1000  # the old rule, for contrast


def test_rows_excluded_by_gearspec_leave_gaps_measured_against_the_logged_steps():
    d = _from_steps(np.full(3999, 1e-3))
    d["torque"][1000:1030] = np.nan  # 30 rows lost to NaN: a 31 ms hole in a 1 ms log
    rec = Recording.from_arrays(**d)
    assert rec.gap_limits()[0] == pytest.approx(5e-3)
    assert rec.pieces() == [(0, 0, 1000), (0, 1000, 3970)]
    assert_ledger(rec)


def test_max_gap_must_be_positive():
    with pytest.raises(InputError, match=r"--max-gap must be a positive time in seconds, got -1"):
        Recording.from_arrays(**drive(), max_gap=-1)


def test_coarse_clock_bursts_are_spread_to_the_true_times_and_nothing_is_lost():
    # a 1 kHz log stamped by a 4 ms clock: every stamp repeated by 4 rows
    d = drive(n=4000)
    true_t = d["t"].copy()
    d["t"] = np.floor(np.round(true_t / 1e-3) / 4) * 4e-3
    rec = quiet(Recording.from_arrays, **d)
    assert len(rec) == 4000 and not rec.excluded
    np.testing.assert_allclose(rec.t, true_t, rtol=0, atol=1e-12)  # even spreading is exact for a steady log
    assert any(n.startswith("arrays: 3000 rows repeat the time stamp") and "no row lost" in n for n in rec.notes)
    assert rec.pieces() == [(0, 0, 4000)]
    assert_ledger(rec)


def test_coarse_clock_burst_before_a_gap_is_spread_over_one_period_only():
    d = drive(n=4000)
    true_t = d["t"].copy()
    true_t[2000:] += 0.5  # a half-second dropout after row 1999
    d["t"] = np.floor(np.round(true_t / 1e-3) / 4) * 4e-3
    rec = quiet(Recording.from_arrays, **d)
    np.testing.assert_allclose(rec.t, true_t, rtol=0, atol=1e-12)
    assert rec.pieces() == [(0, 0, 2000), (0, 2000, 4000)]


def test_copied_rows_are_excluded_even_when_many():
    d = drive(n=2000)
    idx = np.sort(np.concatenate((np.arange(2000), np.arange(0, 2000, 10))))  # every 10th row written twice
    d = {k: v[idx] for k, v in d.items()}
    with pytest.warns(GearspecWarning, match=r"200 rows with duplicate or backward time excluded"):
        rec = Recording.from_arrays(**d)
    assert rec.excluded == {"duplicate_time": 200} and len(rec) == 2000
    assert_ledger(rec)


def test_jitter_rounded_to_a_clock_tick_is_spread_not_dropped():
    # 1 kHz with +-0.45 ms jitter stamped by a 1 ms clock (truncated): about a quarter of the stamps
    # repeat, as many ms are skipped; the order of the samples is kept
    rng = np.random.default_rng(2)
    n = 5000
    true_t = 0.01 + np.arange(n) * 1e-3 + rng.uniform(-0.45e-3, 0.45e-3, n)
    d = drive(n=n)
    d["t"] = np.floor(true_t * 1e3 + 1e-9) / 1e3
    assert np.mean(np.diff(d["t"]) == 0) > 0.2
    rec = quiet(Recording.from_arrays, **d)
    assert len(rec) == n and not rec.excluded
    assert (np.diff(rec.t) > 0).all()
    # each spread time stays within the clock tick (1 ms) of the true time
    assert np.max(np.abs(rec.t - true_t)) < 1.5e-3


def _excitation(t):
    """A whole trajectory (sum of sines, 0.3-3 Hz) with its analytic velocity and acceleration."""
    w = 2 * np.pi * np.array([0.3, 1.1, 2.9])
    amp = np.array([1.0, 0.3, 0.05])
    theta = (amp * np.sin(np.outer(t, w))).sum(axis=1)
    v = (amp * w * np.cos(np.outer(t, w))).sum(axis=1)
    acc = -(amp * w ** 2 * np.sin(np.outer(t, w))).sum(axis=1)
    torque = 0.3 * np.tanh(v / 0.01) + 0.05 * v + 0.02 * acc
    return theta, v, acc, torque


def test_trajectory_on_jittered_stamps_is_resampled_and_matches_the_uniform_log():
    from gearspec.diagnose import trajectory_data

    n, fs = 8000, 1000.0
    rng = np.random.default_rng(4)
    t_uni = np.arange(n) / fs
    t_jit = t_uni + rng.uniform(-0.3e-3, 0.3e-3, n)  # +-30 % jitter of a 1 kHz logger
    out = {}
    for name, t in (("uniform", t_uni), ("jittered", t_jit)):
        theta, v, acc, torque = _excitation(t)
        rec = quiet(Recording.from_arrays, t=t, theta=theta, torque=torque)
        out[name] = trajectory_data(rec, cutoff=20.0, decimate_by=1)
    uni, jit = out["uniform"].fit, out["jittered"].fit
    assert not any("resampled" in n for n in out["uniform"].notes)
    assert any("resampled to a uniform grid at its median step" in n for n in out["jittered"].notes)
    # on its own grid each is the same trajectory: compare at the uniform log's times.  Linear
    # interpolation over a 1 ms step errs by h^2/8 |theta''| <= 1.1e-5 rad (|theta''| <= 70 rad/s^2);
    # the 20 Hz filter passes that on, differentiated twice: measured 2e-5 (v) and 7e-5 (acc) of their rms;
    # the torque is not filtered and its Coulomb step (tanh(v/0.01): ~0.2 ms wide at a reversal, less than
    # the +-0.3 ms jitter) is smeared by the interpolation: measured 0.9 % of its rms.
    for name, tol in (("v", 1e-3), ("acc", 1e-3), ("y", 0.02)):
        a, b = getattr(uni, name), np.interp(uni.t, jit.t, getattr(jit, name))
        inner = (uni.t > jit.t[0] + 0.1) & (uni.t < jit.t[-1] - 0.1)
        rel = np.sqrt(np.mean((a[inner] - b[inner]) ** 2)) / np.sqrt(np.mean(a[inner] ** 2))
        assert rel < tol, (name, rel)


def test_trajectory_refuses_a_step_too_long_to_resample_across():
    from gearspec.diagnose import trajectory_data

    t = np.arange(6000) / 1000.0
    t[3000:] += 0.002  # a 3 ms step in a 1 kHz log (below the gap rule's 5 ms): uniform no longer
    theta, v, acc, torque = _excitation(t)
    rec = quiet(Recording.from_arrays, t=t, theta=theta, torque=torque)
    assert len(rec.pieces()) == 1
    trajectory_data(rec, cutoff=20.0)  # 3 ms < a quarter period of 20 Hz (12.5 ms): resampled
    with pytest.raises(InputError, match=r"run 0: the sample times are not uniform and the step of 0\.003 s at "
                                         r"t = 2\.999 s is longer than a quarter period of the 100 Hz filter"):
        trajectory_data(rec, cutoff=100.0)


def test_back_and_forth_with_the_period_of_the_motion_check_block_is_motion():
    # 2e6 rows at 1 kHz turning 5 s forward, 5 s back: the motion check's block (n // 200 = 10 000 rows
    # = 10 s) is exactly one period, so block displacements and block means alone see no motion
    n = 2_000_000
    t = np.arange(n) / FS
    theta = np.cumsum(np.where((t // 5) % 2 == 0, 0.04, -0.04))
    rec = Recording.from_arrays(t=t, theta=theta, torque=0.01 + 1e-4 * np.sin(7 * theta))
    assert len(rec) == n


# ---------------------------------------------------------------------- refusals and notes name what to do
def test_no_files_is_refused_in_a_sentence():
    with pytest.raises(InputError, match=r"^no recording files given$"):
        load_recording([])


def test_a_file_pandas_cannot_tokenise_names_the_file_and_the_separator(tmp_path):
    # a quote opened in row 2 and never closed: pandas' tokeniser gives up; the sentence names the
    # file, what went wrong (pandas' first line) and the first thing to check, the separator
    path = tmp_path / "q.csv"
    path.write_text('t,theta,torque\n0,0.1,0.2\n0.001,0.2,"0.3\n0.002,0.3,0.4\n')
    with pytest.raises(InputError) as info:
        load_recording(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: cannot be read as a table (")
    assert "EOF inside string" in msg and msg.endswith("; check --sep")


def test_a_row_major_matrix_note_names_the_columns_it_makes(tmp_path):
    # a 3 x 1500 matrix (one row per channel) is read as 1500 samples of 3 columns data_0, data_1,
    # data_2; the note names exactly the columns a --map can then use (first and last)
    d = drive(n=1500)
    path = tmp_path / "m.npz"
    np.savez(path, data=np.vstack([d["t"], d["theta"], d["torque"]]))
    with pytest.warns(GearspecWarning, match=r"'data' is a 3 x 1500 matrix; read as 1500 rows of 3 columns "
                                             r"\(data_0 \.\.\. data_2\), one row per sample"):
        rec = load_recording(path, map="t=data_0,theta=data_1,torque=data_2")
    assert_same_drive(rec, d)
    assert len(rec) == 1500


def test_a_recording_of_exactly_twenty_moving_rows_loads():
    # 20 contiguous rows is the shortest stretch that is analysed: a drive turning at 2 rad/s for
    # 20 rows at 1 kHz (travel 0.038 rad, far above its zero noise and its one step of 2 mrad) moved
    d = drive(n=20)
    rec = quiet(Recording.from_arrays, **d)
    assert len(rec) == 20 and rec.n_read == 20
    with pytest.raises(InputError, match=r"no stretch of at least 20 contiguous usable rows \(longest 19"):
        Recording.from_arrays(**drive(n=19))


def test_a_run_whose_rows_are_interleaved_is_checked_as_one_run():
    # run 0's rows come in two blocks around one row of run 1; run 0's second block is stamped
    # back at 10 ms after its first reached 49 ms: 39 of its 100 rows go backwards in time (39 %
    # > the 5 % allowed), which only a check of all of run 0's rows together sees
    t = np.concatenate([np.arange(50), [0.0], np.arange(10, 60)]) / FS
    run = np.repeat([0, 1, 0], [50, 1, 50])
    theta = 0.3 + 2.0 * np.arange(101) / FS
    torque = 0.2 + 0.02 * np.sin(5 * theta)
    with pytest.raises(InputError, match=r"column 't' goes backwards in 39 of 100 rows"):
        Recording.from_arrays(t=t, theta=theta, torque=torque, run=run)


def test_signal_named_explicitly_and_a_text_current_column_refused(tmp_path):
    t = np.arange(400) / 100.0
    rec = Recording.from_arrays(t=t, theta=0.5 * t, torque=0.1 + 0.01 * np.sin(t), signal="torque")
    assert rec.signal == "torque"
    # a current column is checked like the others: its first non-number is named with its row
    path = tmp_path / "cur.csv"
    rows = ["t,theta,torque,current"] + [f"{a:.2f},{0.5 * a:.4f},{0.1 + 0.01 * np.sin(a):.5f},"
                                         f"{'abc' if i == 7 else '0.2'}" for i, a in enumerate(t)]
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match=r"column 'current', data row 8: 'abc' is not a number"):
        load_recording(path)


def test_saturation_at_the_minimum_only_is_excluded():
    # torque clipped at its minimum only: the maximum (one row) is no saturation, the minimum is
    t = np.arange(3000) / 1000.0
    rng = np.random.default_rng(5)
    tau = 0.1 * np.sin(2 * np.pi * 3 * t) + rng.normal(0, 1e-3, t.size)
    floor = -0.08
    clipped = int(np.sum(tau <= floor))
    with pytest.warns(GearspecWarning, match=f"sits at its extreme value in {clipped} rows"):
        rec = Recording.from_arrays(t=t, theta=0.5 * t, torque=np.maximum(tau, floor))
    assert clipped > 100 and rec.excluded == {"saturation": clipped}


def test_motor_current_at_an_output_reference_is_torque_constant_times_ratio():
    from gearspec.gears import GearTrain
    g = GearTrain.from_dict({"name": "out", "reference": "output", "torque_constant": 0.05,
                             "stages": [{"name": "s", "kind": "spur", "ratio": 100.0}]})
    t = np.arange(500) / 100.0
    cur = 0.2 + 0.01 * np.sin(t)
    rec = Recording.from_arrays(gear=g, t=t, theta=0.01 * t, current=cur)
    np.testing.assert_allclose(rec.tau, 0.05 * 100.0 * cur, rtol=1e-12)   # k_M N I at the output
    assert "torque = 5 Nm/A x current (torque constant 0.05 Nm/A x ratio 100, ideal gear)" in rec.notes


def test_fast_motion_is_not_taken_for_a_wrap():
    # 0.4 rad per sample (more than 5 % of a turn) seen modulo 2 pi: fast motion, not a wrapped
    # encoder; theta is left as logged and nothing is said
    from gearspec.recording.cleaning import _unwrap_theta
    th = np.mod(0.4 * np.arange(200), 2 * np.pi)
    frame = pd.DataFrame({"theta": th, "run": np.zeros(200, int)})
    notes = []
    out = _unwrap_theta("f.csv", frame, "rad", notes)
    assert np.array_equal(out["theta"].to_numpy(), th) and notes == []
    slow = pd.DataFrame({"theta": np.mod(0.01 * np.arange(2000), 2 * np.pi), "run": np.zeros(2000, int)})
    out = _unwrap_theta("f.csv", slow, "rad", notes)
    np.testing.assert_allclose(out["theta"].to_numpy(), 0.01 * np.arange(2000), atol=1e-9)


def test_summary_duration_and_pieces_follow_max_gap():
    t = np.concatenate([np.arange(1000), 1500 + np.arange(1000)]) / 1000.0   # 0.5 s gap
    rec = quiet(Recording.from_arrays, t=t, theta=0.5 * t, torque=0.1 + 0.01 * np.sin(t))
    assert len(rec.pieces()) == 2
    # two pieces of 0.999 s each
    assert "2000 usable rows of 2000 read, 1 run(s), 1.998 s in all" in rec.summary()
    rec.max_gap = 1.0                                # a larger limit joins them: the cache follows
    assert len(rec.pieces()) == 1
