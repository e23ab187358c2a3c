"""gearspec batch: many recordings and joints (serially or on Dask), and the fleet trend tests.

The quick fleet twin (1 robot x 3 joints x 6 dates, 18 recordings of 11 s) is analysed once per
module; the full 4 x 6 x 10 twin is in benchmarks/bench_batch.py (four minutes of CPU).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("rosbags")

from gearspec.cli import main  # noqa: E402
from gearspec.fleet import batch  # noqa: E402
from gearspec.fleet.trend import flagged_joints, holm, trend_tests  # noqa: E402
from gearspec.gears import load_gear  # noqa: E402
from gearspec.simulate.fleet import FLEET_GEAR, fleet_twin  # noqa: E402

CHANGED = {("robot1", "joint1"): "coulomb", ("robot1", "joint2"): "ripple"}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """The quick twin and a corrupt bag among its files, analysed on a LocalCluster of 2 processes."""
    d = tmp_path_factory.mktemp("fleet")
    tw = fleet_twin(d / "bags", robots=1, joints=3, dates=6, coulomb_joint=("robot1", "joint1"),
                    ripple_joint=("robot1", "joint2"), seed=1)
    gear = d / "gear.toml"
    gear.write_text(load_gear(FLEET_GEAR).to_toml())
    broken = d / "bags" / "robot1" / "broken.mcap"
    broken.write_bytes(b"not a bag at all" * 10)
    every = batch([*tw["bags"][:3], broken, *tw["bags"][3:]], gear, workers=2, progress=False)
    table = every[every["status"] == "ok"].reset_index(drop=True)
    return {"dir": d, "twin": tw, "gear": gear, "broken": broken, "every": every, "table": table}


def test_serial_batch_rows_per_joint_and_direction(fleet):
    df = fleet["table"]
    # 6 bags x 3 joints x 2 directions, every one fitted, with its bag's start time (s since 1970)
    assert len(df) == 36 and (df["status"] == "ok").all()
    assert sorted(df["joint"].unique()) == ["joint1", "joint2", "joint3"]
    assert set(df["direction"]) == {"positive", "negative"}
    assert np.allclose(sorted(df["start_time"].unique()), fleet["twin"]["start_times"], atol=1e-3)
    # the strongest line is the tooth mesh (10 mNm true, about 1 mNm noise per sample)
    assert (df["line1_label"] == "spur tooth mesh").all()
    assert np.allclose(df["line1_frequency"], 5 / (2 * np.pi))
    # the first joint's Coulomb friction at the first date: 0.08 Nm (x 1.1 negative) within the
    # 1 % date-to-date scatter (3 sd) and its standard error
    first = df[(df["joint"] == "joint1") & (df["start_time"] == df["start_time"].min())].set_index("direction")
    assert first.loc["positive", "tau_c"] == pytest.approx(0.08, rel=0.03)
    assert first.loc["negative", "tau_c"] == pytest.approx(0.088, rel=0.03)


def test_dask_cluster_of_two_gives_the_serial_rows_and_a_corrupt_file_its_row(fleet):
    every = fleet["every"]
    # the corrupt bag has its row with its sentence, in its place; the other 18 tasks ran
    err = every[every["status"] == "error"]
    assert len(err) == 1 and err.index[0] == 18 and err["source"].iloc[0] == str(fleet["broken"])
    assert "cannot be read as a ROS bag" in err["error"].iloc[0]
    bag = fleet["twin"]["bags"][0]
    serial = batch([bag], fleet["gear"], workers=1, progress=False)
    cluster = fleet["table"][fleet["table"]["source"] == str(bag)].reset_index(drop=True)
    # the same function on the same bytes: identical numbers, not merely close (dtypes aside: the
    # error row makes the cluster table's integer columns float)
    pd.testing.assert_frame_equal(cluster[serial.columns], serial, check_exact=True, check_dtype=False)


def test_cli_batch_exit_2_with_the_refused_row_and_fit_json_equal_to_gearspec_fit(fleet, tmp_path, capsys):
    bag = fleet["twin"]["bags"][0]
    out = tmp_path / "out"
    missing = tmp_path / "missing.csv"
    code = main(["batch", str(bag), str(fleet["broken"]), str(missing), "--gear", str(fleet["gear"]), "--out",
                 str(out), "--workers", "1", "--quiet"])
    assert code == 2
    df = pd.read_parquet(out / "fleet.parquet")
    assert (df["status"] == "ok").sum() == 6 and (df["status"] == "error").sum() == 2   # 3 joints x 2 dirs
    assert df.loc[df["source"] == str(missing), "error"].iloc[0] == f"{missing}: no such file"
    assert (out / "report.md").is_file() and (out / "report.html").is_file()
    js = tmp_path / "fit.json"
    assert main(["fit", str(bag), "--gear", str(fleet["gear"]), "--joint", "joint2", "--json", str(js),
                 "--quiet"]) == 0
    alone = json.loads(js.read_text())
    inside = json.loads(next((out / "fits").glob("*joint2.json")).read_text())
    assert inside == alone
    row = df[(df["joint"] == "joint2") & (df["direction"] == "negative")].iloc[0]
    d = alone["directions"]["negative"]
    assert row["tau_c"] == d["tau_c"] and row["v_s_se"] == d["v_s_se"] and row["rmse"] == alone["rmse"]
    mesh = next(h for h in d["harmonics"] if h["label"] == "spur tooth mesh")
    assert row["spur tooth mesh amplitude"] == mesh["amplitude"]


def test_cli_batch_all_ok_exit_0(fleet, tmp_path):
    code = main(["batch", str(fleet["twin"]["bags"][0]), "--gear", str(fleet["gear"]), "--joint", "joint3",
                 "--out", str(tmp_path / "o"), "--workers", "1", "--quiet"])
    assert code == 0
    df = pd.read_parquet(tmp_path / "o" / "fleet.parquet")
    assert list(df["joint"]) == ["joint3", "joint3"]


def test_fleet_twin_flags_exactly_the_two_changed_joints(fleet, tmp_path):
    tr = trend_tests(fleet["table"])
    joints = flagged_joints(tr)
    assert set(zip(joints["robot"], joints["joint"])) == set(CHANGED)
    # Coulomb: 0.08 -> 0.096 Nm linearly, a change of 0.2 / 1.1 = 0.182 of the mean; mesh ripple
    # 0.010 -> 0.015 Nm, 0.5 / 1.25 = 0.40.  Tolerance 0.036: 3 sd of the fitted change from the 1 %
    # date-to-date scatter over 6 dates (sd 0.01 * 5 / sqrt(17.5) = 0.012)
    tc = tr[(tr["joint"] == "joint1") & (tr["parameter"] == "tau_c")]
    assert tc["flagged"].all() and np.allclose(tc["relative_change"], 0.2 / 1.1, atol=0.036)
    rp = tr[(tr["joint"] == "joint2") & (tr["parameter"] == "spur tooth mesh amplitude")]
    assert rp["flagged"].all() and np.allclose(rp["relative_change"], 0.4, atol=0.036)
    # the mesh ripple of the Coulomb joint and the Coulomb friction of the ripple joint did not change
    assert not tr[(tr["joint"] == "joint1") & (tr["parameter"] == "spur tooth mesh amplitude")]["flagged"].any()
    assert not tr[(tr["joint"] == "joint2") & (tr["parameter"] == "tau_c")]["flagged"].any()


def test_fleet_report_shows_the_rule_and_the_flagged_joints(fleet, tmp_path):
    from gearspec.cli.batch import write_fleet_report

    path = write_fleet_report(fleet["table"], trend_tests(fleet["table"]), tmp_path)
    text = path.read_text()
    assert "corrected together by Holm's step-down method (family-wise error 0.01)" in text
    text = text.split("## Flagged joints")[1].split("##")[0]
    assert "| robot1 | joint1 |" in text and "| robot1 | joint2 |" in text and "| robot1 | joint3 |" not in text
    assert (tmp_path / "fleet_overview.png").is_file() and (tmp_path / "flagged_robot1_joint1.png").is_file()


def test_diagnose_adds_the_closed_loop_verdict(fleet):
    # the twin's friction is the SILO4 law with the declared lines and white noise: the closed loop
    # has nothing to add (known answer 0 effects); the columns are there for every direction
    df = batch([fleet["twin"]["bags"][0]], fleet["gear"], joint="joint3", diagnose=True, workers=1, progress=False)
    assert list(df["direction"]) == ["positive", "negative"]
    assert df["n_effects"].tolist() == [0, 0] and df["effects"].tolist() == ["", ""]


def test_warnings_of_a_task_are_in_its_rows(tmp_path):
    # without a gear spec the fit says so (a GearspecWarning): the batch keeps it in the rows, once
    from gearspec.model import FrictionModel
    from gearspec.simulate import model_recording

    truth = FrictionModel("stribeck", {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 1e-3})
    rec, _ = model_recording(truth, [1, 3, 8, 20, -1, -3, -8, -20], duration=1.0, fs=250, noise=1e-3, seed=2)
    df = batch([rec.save(tmp_path / "r.csv")], None, workers=1, progress=False)
    assert (df["status"] == "ok").all() and len(df) == 2
    assert df["warnings"].str.count("without a gear spec").tolist() == [1, 1]
    # Stribeck truth: tau_c 0.1 Nm within 3 % (noise 1 mNm over 4 plateaus of 250 samples)
    assert np.allclose(df["tau_c"], 0.1, rtol=0.03)


def _one_sided(tmp_path, speeds, name):
    """A Stribeck twin (tau_c 0.1 Nm, 1 mNm noise) of plateaus at ``speeds`` (rad/s) as a CSV."""
    from gearspec.model import FrictionModel
    from gearspec.simulate import model_recording

    truth = FrictionModel("stribeck", {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 1e-3})
    rec, _ = model_recording(truth, speeds, duration=1.0, fs=250, noise=1e-3, seed=3)
    return rec.save(tmp_path / name)


def test_every_direction_has_its_row_when_one_cannot_be_analysed(tmp_path, capsys):
    # the fleet twin's odd row: one joint's fit refused in one direction gave one row, not two.
    # (1) plateaus in the positive direction only: the negative row says why, the positive is fitted
    one = _one_sided(tmp_path, [1, 3, 8, 20], "positive_only.csv")
    # (2) the positive direction at one speed, too few for the law's 4 parameters: the fit is
    # refused, as `gearspec fit` refuses it, and each direction has its error row with the sentence
    few = _one_sided(tmp_path, [3, -1, -3, -8, -20], "few_speeds.csv")
    df = batch([one, few], None, law="stribeck", workers=1, progress=False)
    assert list(zip(df["source"], df["direction"], df["status"])) == [
        (str(one), "positive", "ok"), (str(one), "negative", "error"),
        (str(few), "positive", "error"), (str(few), "negative", "error")]
    assert df["error"].iloc[1] == "no segment in the negative direction"
    assert df["tau_c"].iloc[0] == pytest.approx(0.1, rel=0.03)   # as in test_warnings_of_a_task_are_in_its_rows
    said = "law stribeck has 4 parameters per direction but the positive direction has plateaus at only 1 speed(s)"
    assert df["error"].iloc[2].startswith(said) and df["error"].iloc[3] == df["error"].iloc[2]
    assert main(["fit", str(few), "--law", "stribeck", "--quiet"]) == 2
    assert said in capsys.readouterr().err
    # the command line counts pairs, not rows, and names the direction of each refused row
    assert main(["batch", str(one), str(few), "--law", "stribeck", "--workers", "1", "--out",
                 str(tmp_path / "o")]) == 2
    out = capsys.readouterr().out
    assert "2 recording-joint pair(s): 0 fitted, 1 refused, 1 fitted in one direction only" in out
    assert f"refused [negative]: {one}: no segment in the negative direction" in out
    assert "1 fitted in one direction only" in (tmp_path / "o" / "report.md").read_text()


def test_unreachable_scheduler_is_one_sentence(fleet, monkeypatch):
    import gearspec.fleet.runner as fb
    from gearspec.errors import InputError

    monkeypatch.setattr(fb, "CONNECT_TIMEOUT", "1s")
    with pytest.raises(InputError, match=r"--scheduler tcp://127.0.0.1:9: no Dask scheduler answers there"):
        batch([fleet["twin"]["bags"][0]], fleet["gear"], scheduler="tcp://127.0.0.1:9", progress=False)


# ---------------------------------------------------------------------- the local cluster's workers
def _probe(tag):
    """What a worker sees: a mark set in the parent after import (kept only by a forked copy), its BLAS
    threads inside the task, and Dask's profiler setting."""
    import dask
    from threadpoolctl import threadpool_info

    import gearspec.fleet.runner as runner

    blas = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return {"tag": tag, "mark": getattr(runner, "_TEST_MARK", None), "blas": max(blas, default=None),
            "profile": dask.config.get("distributed.worker.profile.enabled")}


def test_local_workers_are_forked_with_one_blas_thread_and_no_profiler(monkeypatch):
    import sys

    from threadpoolctl import threadpool_info

    import gearspec.fleet.runner as runner

    if not sys.platform.startswith("linux"):
        pytest.skip("fork is the default start on Linux only")
    monkeypatch.setattr(runner, "_TEST_MARK", 7, raising=False)
    out = runner._on_dask([("a",), ("b",), ("c",)], 2, None, False, fn=_probe)
    # results in the order given, whatever order the workers ran them in
    assert [r["tag"] for r in out] == ["a", "b", "c"]
    # forked: the workers carry this process's state (a spawned one re-imports and has no mark)
    assert [r["mark"] for r in out] == [7, 7, 7]
    # one BLAS thread in each task, whatever this process has (the test can only fail with more cores)
    if max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas") > 1:
        assert [r["blas"] for r in out] == [1, 1, 1]
    assert [r["profile"] for r in out] == [False, False, False]


def test_largest_files_are_submitted_first_and_a_bad_start_is_one_sentence(tmp_path):
    import gearspec.fleet.runner as runner
    from gearspec.errors import InputError

    sizes = {"small.csv": 10, "big.csv": 300, "middle.csv": 100, "same.csv": 100}
    for name, n in sizes.items():
        (tmp_path / name).write_bytes(b"x" * n)
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "a.mcap").write_bytes(b"x" * 150)
    (folder / "metadata.yaml").write_bytes(b"x" * 60)   # a rosbag2 folder: its files together, 210 bytes
    args = [(str(tmp_path / n),) for n in sizes] + [(str(folder),), (str(tmp_path / "missing.csv"),)]
    # big 300, the folder 210, middle and same 100 each (in task order), small 10, missing (0) last
    assert runner._largest_first(args) == [1, 4, 2, 3, 0, 5]
    with pytest.raises(InputError, match="start must be one of .*fork.*, got 'threads'"):
        runner._start_method("threads")


# ---------------------------------------------------------------------- the trend rule on known series
def _series(n_series, n_dates, rng, slope=0.0, scatter=0.0, se=0.01):
    """A batch-like table: ``n_series`` joints, values 1 + slope * date index + scatter noise, with
    standard error ``se`` (the true sd of the values when ``scatter`` is 0)."""
    rows = []
    for j in range(n_series):
        for d in range(n_dates):
            y = 1.0 + slope * d + rng.normal(0, se) + (rng.normal(0, scatter) if scatter else 0.0)
            rows.append({"robot": "r", "joint": f"j{j}", "direction": "positive", "status": "ok",
                         "start_time": 1.7e9 + d * 86400.0, "law": "coulomb_viscous", "tau_c": y, "tau_c_se": se})
    return pd.DataFrame(rows)


def test_holm_adjusted_p_values_known_answer():
    # sorted 0.005, 0.01, 0.03, 0.04 -> 4 x 0.005, 3 x 0.01, 2 x 0.03, max(1 x 0.04, 0.06)
    assert np.allclose(holm([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02])
    assert np.isnan(holm([np.nan, 0.2])[0]) and holm([np.nan, 0.2])[1] == pytest.approx(0.2)


def test_no_trend_is_flagged_only_with_the_correction():
    # 400 series of 8 dates without a trend, values scattered exactly by their standard errors:
    # each test alone at 1 % flags about 4 of them; corrected together, none (family-wise 1 %)
    df = _series(400, 8, np.random.default_rng(11))
    assert trend_tests(df, correction="none")["flagged"].sum() >= 1
    assert trend_tests(df)["flagged"].sum() == 0
    assert trend_tests(df, correction="bonferroni")["flagged"].sum() == 0


def test_scatter_beyond_the_standard_errors_widens_the_slope_error():
    # 20 series whose dates scatter 5 times more than the fit's standard error says: without the
    # Birge widening a random slope of such a series looks significant
    df = _series(20, 8, np.random.default_rng(12), scatter=0.05)
    tr = trend_tests(df)
    assert tr["flagged"].sum() == 0 and (tr["chi2_dof"] > 5).all()


def test_a_known_slope_is_recovered_within_its_standard_error():
    # slope 0.01 per day, noise sd 0.001 on 10 dates: slope se 0.001 / sqrt(82.5) = 1.1e-4
    df = _series(1, 10, np.random.default_rng(13), slope=0.01, se=0.001)
    r = trend_tests(df).iloc[0]
    assert r["slope_per_day"] == pytest.approx(0.01, abs=3 * 1.1e-4) and r["flagged"]
    # the weighted slope error, widened by the Birge ratio only when the points scatter more than 0.001
    assert r["slope_se"] == pytest.approx(0.001 / np.sqrt(82.5) * np.sqrt(max(1.0, r["chi2_dof"])), rel=1e-9)


def test_bad_alpha_is_one_sentence():
    from gearspec.errors import InputError

    with pytest.raises(InputError, match="alpha"):
        trend_tests(_series(1, 4, np.random.default_rng(0)), alpha=2)


@pytest.mark.slow
def test_two_robot_fleet_flags_the_changes_on_either_robot_and_nothing_else(tmp_path):
    # 2 robots x 3 joints x 8 dates (48 recordings, about a minute on 2 cores): the Coulomb rise on
    # robot1 joint1, the ripple growth on robot2 joint3; the same joints elsewhere did not change
    tw = fleet_twin(tmp_path / "bags", robots=2, joints=3, dates=8, coulomb_joint=("robot1", "joint1"),
                    ripple_joint=("robot2", "joint3"), seed=5)
    df = batch(tw["bags"], FLEET_GEAR, workers=2, progress=False)
    assert (df["status"] == "ok").all() and len(df) == 96
    joints = flagged_joints(trend_tests(df))
    assert set(zip(joints["robot"], joints["joint"])) == {("robot1", "joint1"), ("robot2", "joint3")}


def test_figure_states_a_tiny_adjusted_p_value_as_a_bound():
    from gearspec.plots.fleet import _p_text

    # Holm's adjustment of a p-value that underflowed is exactly 0: the figure gives the bound, not 0
    assert _p_text(0.0) == "p_adj < 1e-16" and _p_text(3e-17) == "p_adj < 1e-16"
    assert _p_text(3.1e-9) == "p_adj 3.1e-09"


def test_expand_paths_is_public_and_the_old_name_stays(tmp_path):
    from gearspec.errors import InputError
    from gearspec.recording.load import _expand, expand_paths

    for name in ("b.csv", "a.parquet", "notes.txt.bak"):
        (tmp_path / name).write_text("x")
    # a folder becomes its recording files, sorted by name; what is not a recording is left out
    assert expand_paths(tmp_path) == [tmp_path / "a.parquet", tmp_path / "b.csv"]
    assert _expand is expand_paths
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="empty: the folder holds no recording files"):
        expand_paths([tmp_path / "empty"])
