"""ROS bags and URDF gear ratios (issue 15 items 1-2): bags written with ``rosbags``' own writers
(rosbag2 in sqlite3 and mcap storage, as a folder and as a single file, and ROS 1) from twin data
give exactly the recording, the ``gearspec fit`` JSON and the spectrum of the CSV of the same
samples; bad messages are counted in the ledger; damaged bags and ambiguous joints are refused
with one sentence.

Known answers: the bag and the CSV hold the same float64 samples and the same nanosecond stamps,
so the recordings are compared EXACTLY (no tolerance); a linear temperature ramp interpolated at
the joint's stamps has a known value (tolerance 1e-9 degC: float rounding of 1e9 ns sums).
"""

from __future__ import annotations

import json
import shutil
from collections import Counter

import numpy as np
import pandas as pd
import pytest

rosbags = pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from gearspec.cli import main  # noqa: E402
from gearspec.errors import InputError  # noqa: E402
from gearspec.model import FrictionModel  # noqa: E402
from gearspec.recording import bag_joints, gear_from_urdf, load_recording, urdf_reductions  # noqa: E402
from gearspec.simulate import Ripple, model_recording, plateau_recording  # noqa: E402

JS = "sensor_msgs/msg/JointState"
TEMP = "sensor_msgs/msg/Temperature"
T0_NS = 1_700_000_000 * 10**9          # the stamps' epoch: 2023-11-14, s since 1970 in ns
SPEEDS = [0.5, 1.0, 2.0, 4.0, -0.5, -1.0, -2.0, -4.0]   # rad/s
FS = 250.0                              # Hz
TRUTH = {"tau_c": 0.1, "tau_s": 0.15, "v_s": 2.0, "viscous": 1e-3,
         "harmonics": [{"frequency": 0.8, "amplitude": 0.01, "decay": 0.01, "phase": 1.0}]}
K_MISS, K_NAN, K_LEN = 700, 900, 1100   # messages: elbow missing; elbow effort NaN; effort of length 1


def _twin():
    """Two joints on one clock (shoulder: a SILO4-law twin; elbow: plateaus with a 0.8 cycles/rad
    ripple) and a wrist on a jittered clock, each with t, theta, velocity, torque."""
    model = FrictionModel("silo4", TRUTH, dict(TRUTH, tau_c=0.12))
    sh, _ = model_recording(model, SPEEDS, duration=1.0, fs=FS, noise=1e-3, seed=1, one_run_per_plateau=False)
    el, _ = plateau_recording(SPEEDS, ripples=[Ripple(0.8, 0.01)], level=0.05, duration=1.0, fs=FS, noise=1e-3,
                              seed=2)
    t = sh.t
    assert np.array_equal(el.t, t)
    stamp = T0_NS + np.round(t * 1e9).astype(np.int64)
    joints = {"shoulder": sh, "elbow": el}
    cols = {name: {"theta": r.theta, "velocity": np.gradient(r.theta, t), "torque": r.tau}
            for name, r in joints.items()}
    rng = np.random.default_rng(7)
    # the wrist's logger clock jitters by up to +-1 ms around its 4 ms period: the samples are taken at
    # the jittered times (the twin interpolated there), so stamps and values agree
    tw = t + rng.uniform(-1e-3, 1e-3, len(t))
    tw[0] = 0.0
    wrist = {"theta": np.interp(tw, t, sh.theta), "torque": np.interp(tw, t, sh.tau)}
    wrist["velocity"] = np.gradient(wrist["theta"], tw)
    return {"stamp": stamp, "cols": cols, "wrist_stamp": T0_NS + np.round(tw * 1e9).astype(np.int64),
            "wrist": wrist, "latency": rng.integers(100_000, 3_000_000, len(t))}


def _header(ts, ns, ros1):
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=int(ns // 10**9), nanosec=int(ns % 10**9))
    extra = {"seq": 0} if ros1 else {}
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id="", **extra)


def _js(ts, ns, ros1, names, pos, vel, eff):
    return ts.types[JS](header=_header(ts, ns, ros1), name=list(names), position=np.asarray(pos, float),
                        velocity=np.asarray(vel, float), effort=np.asarray(eff, float))


def _messages(tw, ts, ros1, zero_stamps=False):
    """(topic, log ns, message) of the twin in log order, with the three bad messages."""
    out = []
    c = tw["cols"]
    for i, ns in enumerate(tw["stamp"]):
        names = ["shoulder", "elbow"]
        pos = [c[j]["theta"][i] for j in names]
        vel = [c[j]["velocity"][i] for j in names]
        eff = [c[j]["torque"][i] for j in names]
        if i == K_MISS:
            names, pos, vel, eff = names[:1], pos[:1], vel[:1], eff[:1]
        elif i == K_NAN:
            eff[1] = np.nan
        elif i == K_LEN:
            eff = eff[:1]
        # the log time is the stamp plus a transport latency of 0.1 to 3 ms: not the sampling time
        log = int(ns + tw["latency"][i])
        out.append(("/joint_states", log, _js(ts, 0 if zero_stamps else ns, ros1, names, pos, vel, eff)))
        w = tw["wrist"]
        wns = int(tw["wrist_stamp"][i])
        out.append(("/wrist/joint_states", wns + 500_000,
                    _js(ts, wns, ros1, ["wrist"], [w["theta"][i]], [w["velocity"][i]], [w["torque"][i]])))
    for k in range(-1, int((tw["stamp"][-1] - T0_NS) / 1e8) + 2):   # 10 Hz, beyond both ends
        ns = T0_NS + k * 100_000_000
        msg = ts.types[TEMP](header=_header(ts, ns, ros1), temperature=30.0 + 0.5 * k * 0.1, variance=0.0)
        out.append(("/motor_temperature", ns + 1000, msg))
    out.sort(key=lambda m: m[1])
    return out


def _write2(path, tw, storage, zero_stamps=False):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(path, version=9, storage_plugin=storage) as w:
        conns = {}
        for topic, log, msg in _messages(tw, ts, False, zero_stamps):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msg.__msgtype__, typestore=ts)
            w.write(conns[topic], log, ts.serialize_cdr(msg, msg.__msgtype__))
    return path


def _write1(path, tw):
    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as w:
        conns = {}
        for topic, log, msg in _messages(tw, ts, True):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msg.__msgtype__, typestore=ts)
            w.write(conns[topic], log, ts.serialize_ros1(msg, msg.__msgtype__))
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    tw = _twin()
    out = {"twin": tw, "dir": d}
    out["sqlite3 folder"] = _write2(d / "run_sqlite", tw, StoragePlugin.SQLITE3)
    out["mcap folder"] = _write2(d / "run_mcap", tw, StoragePlugin.MCAP)
    out["db3 file"] = next(out["sqlite3 folder"].glob("*.db3"))
    out["mcap file"] = next(out["mcap folder"].glob("*.mcap"))
    out["ros1 bag"] = _write1(d / "run.bag", tw)
    # the CSV of the same samples: the messages that carry the joint with arrays of the right length
    # (the NaN row is kept: the common cleaning excludes it as in any CSV)
    keep = np.setdiff1d(np.arange(len(tw["stamp"])), [K_MISS, K_LEN])
    for name in ("shoulder", "elbow"):
        rows = keep if name == "elbow" else np.setdiff1d(np.arange(len(tw["stamp"])), [K_LEN])
        c = tw["cols"][name]
        frame = pd.DataFrame({"t": (tw["stamp"][rows] - T0_NS) / 1e9, **{k: v[rows] for k, v in c.items()}})
        if name == "elbow":
            frame.loc[frame.index[np.searchsorted(rows, K_NAN)], "torque"] = np.nan
        frame.to_csv(d / f"{name}.csv", index=False, float_format="%.17g")
    w = tw["wrist"]
    pd.DataFrame({"t": (tw["wrist_stamp"] - T0_NS) / 1e9, **w}).to_csv(d / "wrist.csv", index=False,
                                                                       float_format="%.17g")
    return out


STORAGES = ["sqlite3 folder", "db3 file", "mcap folder", "mcap file", "ros1 bag"]
COLS = ["t", "theta", "velocity", "torque", "run"]


@pytest.mark.parametrize("storage", STORAGES)
def test_bag_gives_the_recording_of_the_csv_of_the_same_samples(bags, storage):
    rec = load_recording(bags[storage], joint="elbow")
    ref = load_recording(bags["dir"] / "elbow.csv")
    pd.testing.assert_frame_equal(rec.data[COLS], ref.data[COLS], check_exact=True)
    n = len(bags["twin"]["stamp"])
    # the ledger: every message is a row, read or counted under one reason
    assert rec.n_read == n == len(rec) + sum(rec.excluded.values())
    assert rec.excluded == ref.excluded + Counter(missing_joint=1, array_length_mismatch=1)
    assert rec.excluded["nan_or_inf"] == 1
    assert rec.sources == [f"{bags[storage]} (joint elbow)"]
    assert rec.meta["joint"] == "elbow" and rec.meta["start_time"] == T0_NS / 1e9
    # the other joint of the same messages: only the length mismatch concerns it
    sh = load_recording(bags[storage], joint="shoulder")
    pd.testing.assert_frame_equal(sh.data[COLS], load_recording(bags["dir"] / "shoulder.csv").data[COLS],
                                  check_exact=True)
    assert sh.excluded == Counter(array_length_mismatch=1)


def test_jittered_clock_is_kept_as_stamped(bags):
    # the wrist's own topic, one joint: no --joint needed; its irregular stamps are the sample times
    rec = load_recording(bags["mcap folder"], topic="/wrist/joint_states")
    ref = load_recording(bags["dir"] / "wrist.csv")
    pd.testing.assert_frame_equal(rec.data[COLS], ref.data[COLS], check_exact=True)
    steps = np.diff(rec.t)
    assert steps.std() > 3e-4   # uniform +-1 ms jitter on both ends of a step: sd 0.82 ms, far above 0


def test_other_topic_mapped_to_a_column(bags):
    rec = load_recording(bags["sqlite3 folder"], joint="elbow", map="temperature=/motor_temperature.temperature")
    # 30 degC + 0.5 degC/s: linear, so interpolation between the 10 Hz messages is exact up to rounding
    assert np.allclose(rec.channel("temperature"), 30.0 + 0.5 * rec.t, rtol=0, atol=1e-9)
    assert rec.n_read == len(rec) + sum(rec.excluded.values()) and "outside_mapped_topic" not in rec.excluded
    with pytest.raises(InputError, match=r"no field 'temp'.*fields: header, temperature, variance"):
        load_recording(bags["sqlite3 folder"], joint="elbow", map="temperature=/motor_temperature.temp")
    with pytest.raises(InputError, match=r"no topic '/nope' \(given by --map temperature=/nope\.temperature\).*"
                                         r"/motor_temperature \(sensor_msgs/msg/Temperature\)"):
        load_recording(bags["sqlite3 folder"], joint="elbow", map="temperature=/nope.temperature")


def _small_bag(path, joint="a", n=1000, swap=None, empty_effort=None, temp_span=None, zero_stamp=None):
    """One joint of the shoulder twin on /joint_states (no velocity arrays): messages ``swap`` and
    ``swap + 1`` logged in each other's place, message ``empty_effort`` with an empty effort array,
    a /temp topic (40 degC) from ``temp_span[0]`` to ``temp_span[1]`` s, and message ``zero_stamp``
    stamped 0."""
    tw = _twin()
    ts = get_typestore(Stores.ROS2_HUMBLE)
    c = tw["cols"]["shoulder"]
    logs = tw["stamp"][:n].copy()
    if swap is not None:
        logs[[swap, swap + 1]] = logs[[swap + 1, swap]]
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cj = w.add_connection("/joint_states", JS, typestore=ts)
        msgs = []
        for i, ns in enumerate(tw["stamp"][:n]):
            eff = [] if i == empty_effort else [c["torque"][i]]
            stamp = 0 if i == zero_stamp else ns
            msgs.append((int(logs[i]), cj, _js(ts, stamp, False, [joint], [c["theta"][i]], [], eff)))
        if temp_span:
            ct = w.add_connection("/temp", TEMP, typestore=ts)
            for k in (round(10 * temp_span[0]), round(10 * temp_span[1])):
                ns = T0_NS + k * 100_000_000
                msgs.append((ns, ct, ts.types[TEMP](header=_header(ts, ns, False), temperature=40.0, variance=0.0)))
        for log, conn, msg in sorted(msgs, key=lambda m: m[0]):
            w.write(conn, log, ts.serialize_cdr(msg, msg.__msgtype__))
    return path


def test_rows_outside_a_mapped_topic_are_excluded(tmp_path):
    rec = load_recording(_small_bag(tmp_path / "late", temp_span=(2, 3), empty_effort=10),
                         map="temperature=/temp.temperature")
    # rows at 4 ms from 0 to 3.996 s: 2 s to 3 s inclusive is 251 rows, the other 748 are outside, and
    # the message without effort (at 40 ms, outside too) is counted under its own reason first
    assert len(rec) == 251 and rec.excluded == Counter(outside_mapped_topic=748, array_length_mismatch=1)
    assert "velocity" not in rec.data   # empty velocity arrays: the topic does not carry velocity
    # a message without effort among messages with effort: excluded, not a NaN torque
    rec = load_recording(_small_bag(tmp_path / "empty", empty_effort=500))
    assert rec.excluded == Counter(array_length_mismatch=1) and len(rec) == 999


def test_one_zero_stamp_among_real_ones_is_excluded(tmp_path):
    rec = load_recording(_small_bag(tmp_path / "zero_one", zero_stamp=300))
    assert rec.excluded == Counter(zero_stamp=1) and len(rec) == 999 and rec.t[0] == 0.0
    with pytest.raises(InputError, match=r"--map temperature=/joint_states\.name: field 'name' of '/joint_states' "
                                         r"is not a number \(list\)"):
        load_recording(tmp_path / "zero_one", map="temperature=/joint_states.name")


def test_messages_logged_out_of_stamp_order_are_sorted_by_stamp(tmp_path):
    rec = load_recording(_small_bag(tmp_path / "swapped", swap=500))
    assert len(rec) == 1000 and not rec.excluded and np.all(np.diff(rec.t) > 0)
    assert any("logged out of the order of their stamps; sorted by stamp" in n for n in rec.notes)


def test_bags_of_different_joints_are_not_joined(tmp_path, bags):
    a, b = _small_bag(tmp_path / "a", "a", n=300), _small_bag(tmp_path / "b", "b", n=300)
    with pytest.raises(InputError, match=r"a \(joint a\) and .*b \(joint b\) are different joints; choose one"):
        load_recording([a, b])
    with pytest.raises(InputError, match=r"shoulder\.csv: --joint all makes one recording per joint of a ROS bag"):
        load_recording([a, bags["dir"] / "shoulder.csv"], joint="all")


def test_bag_without_message_definitions_is_read_with_the_standard_ones(bags, tmp_path):
    # rosbag2 files written before ROS 2 Iron hold no message definitions
    import sqlite3

    old = tmp_path / "foxy.db3"
    shutil.copy(bags["db3 file"], old)
    with sqlite3.connect(old) as db:
        db.execute("DELETE FROM message_definitions")
    rec = load_recording(old, joint="elbow")
    pd.testing.assert_frame_equal(rec.data[COLS], load_recording(bags["db3 file"], joint="elbow").data[COLS],
                                  check_exact=True)


def test_several_joints_need_joint_and_all_gives_one_recording_each(bags):
    with pytest.raises(InputError, match=r"run\.bag: topic '/joint_states' carries 2 joints \(shoulder, elbow\); "
                                         r"choose one with --joint NAME"):
        load_recording(bags["ros1 bag"])
    with pytest.raises(InputError, match=r"no joint 'knee' on topic '/joint_states' \(joints: shoulder, elbow\)"):
        load_recording(bags["ros1 bag"], joint="knee")
    recs = load_recording(bags["mcap file"], joint="all")
    assert [r.meta["joint"] for r in recs] == ["shoulder", "elbow"]
    assert recs[1].excluded["missing_joint"] == 1 and recs[0].excluded["missing_joint"] == 0
    assert bag_joints(bags["mcap file"]) == ["shoulder", "elbow"]


def test_wrong_topic_and_wrong_type_are_one_sentence(bags):
    with pytest.raises(InputError, match=r"no topic '/joint_state' \(given by --topic\)"):
        load_recording(bags["db3 file"], topic="/joint_state", joint="elbow")
    with pytest.raises(InputError, match=r"topic '/motor_temperature' carries sensor_msgs/msg/Temperature, "
                                         r"not sensor_msgs/msg/JointState"):
        load_recording(bags["db3 file"], topic="/motor_temperature")


@pytest.mark.parametrize("storage", ["ros1 bag", "db3 file", "mcap file"])
def test_corrupt_bag_is_one_sentence(bags, storage, tmp_path):
    src = bags[storage]
    bad = tmp_path / src.name
    bad.write_bytes(src.read_bytes()[: src.stat().st_size // 2])    # a copy cut in half
    with pytest.raises(InputError) as err:
        load_recording(bad, joint="elbow")
    msg = str(err.value)
    assert msg.startswith(f"{bad}: ") and "\n" not in msg and ("cannot be read" in msg or "damaged" in msg)


def test_cli_corrupt_bag_and_joint_all_exit_2(bags, tmp_path, capsys):
    bad = tmp_path / "cut.bag"
    bad.write_bytes(bags["ros1 bag"].read_bytes()[:5000])
    assert main(["spectrum", str(bad), "--joint", "elbow", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"gearspec: error: {bad}: ") and len(err.splitlines()) == 1
    assert main(["fit", str(bags["ros1 bag"]), "--quiet"]) == 2
    assert "carries 2 joints (shoulder, elbow)" in capsys.readouterr().err
    assert main(["fit", str(bags["ros1 bag"]), "--joint", "all", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--joint all: `gearspec fit` analyses one joint at a time" in err and "shoulder, elbow" in err


def _fit_json(path, tmp_path, name, *extra):
    out = tmp_path / f"{name}.json"
    assert main(["fit", str(path), "--law", "stribeck", "--no-published", "--folds", "3", "--quiet",
                 "--json", str(out), *extra]) == 0
    d = json.loads(out.read_text())
    return {k: d[k] for k in ("law", "directions", "rmse", "rmse_holdout")}


def test_fit_and_spectrum_of_a_bag_equal_those_of_the_csv(bags, tmp_path):
    csv = bags["dir"] / "elbow.csv"
    assert _fit_json(bags["sqlite3 folder"], tmp_path, "bag", "--joint", "elbow") == _fit_json(csv, tmp_path, "csv")
    spec = {}
    for name, path, extra in (("bag", bags["ros1 bag"], ["--joint", "elbow"]), ("csv", csv, [])):
        out = tmp_path / f"spectrum_{name}.json"
        assert main(["spectrum", str(path), "--quiet", "--json", str(out), *extra]) == 0
        spec[name] = json.loads(out.read_text())
    assert spec["bag"]["segments"] == spec["csv"]["segments"] and len(spec["csv"]["segments"]) == len(SPEEDS)
    # the ledger differs by exactly the two messages the CSV never had
    diff = Counter(spec["bag"]["excluded"]) - Counter(spec["csv"]["excluded"])
    assert diff == Counter(missing_joint=1, array_length_mismatch=1)


def test_zero_stamps_use_the_log_time_with_a_note(bags, tmp_path):
    path = _write2(tmp_path / "zero", bags["twin"], StoragePlugin.MCAP, zero_stamps=True)
    rec = load_recording(path, joint="shoulder")
    tw = bags["twin"]
    log = tw["stamp"] + tw["latency"]
    rows = np.setdiff1d(np.arange(len(log)), [K_LEN])
    assert np.array_equal(rec.t, (log[rows] - log[0]) / 1e9)
    assert any("every header stamp on '/joint_states' is zero; t is the time the bag logged" in n for n in rec.notes)


# ---------------------------------------------------------------------- URDF
CLASSIC = """<?xml version="1.0"?>
<robot name="arm">
  <joint name="shoulder" type="revolute"/>
  <transmission name="tr_shoulder">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="shoulder"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>160</mechanicalReduction></actuator>
  </transmission>
  <transmission name="tr_old" type="pr2_mechanism_model/SimpleTransmission">
    <joint name="wrist"/><actuator name="m3"/><mechanicalReduction>-50</mechanicalReduction>
  </transmission>
  <transmission name="diff">
    <joint name="a"/><joint name="b"/><actuator name="m4"><mechanicalReduction>9</mechanicalReduction></actuator>
  </transmission>
</robot>
"""
ROS2_CONTROL = """<?xml version="1.0"?>
<robot name="arm">
  <ros2_control name="arm_hw" type="system">
    <transmission name="tr_elbow">
      <plugin>transmission_interface/SimpleTransmission</plugin>
      <actuator name="m2" role="actuator1"/>
      <joint name="elbow" role="joint1"><mechanical_reduction>100.0</mechanical_reduction><offset>0.0</offset></joint>
    </transmission>
  </ros2_control>
</robot>
"""


def test_urdf_both_forms_give_the_reduction(tmp_path):
    (tmp_path / "classic.urdf").write_text(CLASSIC)
    (tmp_path / "ros2.urdf").write_text(ROS2_CONTROL)
    # the coupled (differential) transmission has no single ratio: left out
    assert urdf_reductions(tmp_path / "classic.urdf") == {"shoulder": 160.0, "wrist": -50.0}
    assert urdf_reductions(tmp_path / "ros2.urdf") == {"elbow": 100.0}
    gear, note = gear_from_urdf(tmp_path / "ros2.urdf")      # one joint: no name needed
    assert gear.total_ratio == 100.0 and gear.reference == "output" and [s.kind for s in gear.stages] == ["other"]
    assert note == f"gear ratio 100 from URDF {tmp_path / 'ros2.urdf'}, joint elbow"
    gear, note = gear_from_urdf(tmp_path / "classic.urdf", "wrist")
    assert gear.total_ratio == 50.0 and "reverses the direction" in note
    with pytest.raises(InputError, match=r"transmissions for 2 joints \(shoulder, wrist\); say which with --joint"):
        gear_from_urdf(tmp_path / "classic.urdf")
    (tmp_path / "xacro.urdf").write_text(ROS2_CONTROL.replace("100.0", "${ratio}"))
    with pytest.raises(InputError, match=r"'\$\{ratio\}' is not a number; it looks like a xacro expression"):
        urdf_reductions(tmp_path / "xacro.urdf")
    (tmp_path / "broken.urdf").write_text(CLASSIC[:200])
    with pytest.raises(InputError, match=r"broken\.urdf: not a valid XML file"):
        urdf_reductions(tmp_path / "broken.urdf")


def test_urdf_gives_the_recording_its_gear_and_says_so(bags, tmp_path, capsys):
    urdf = tmp_path / "ros2.urdf"
    urdf.write_text(ROS2_CONTROL)
    rec = load_recording(bags["mcap folder"], joint="elbow", urdf=urdf)
    assert rec.gear.total_ratio == 100.0
    assert f"gear ratio 100 from URDF {urdf}, joint elbow" in rec.notes
    # a gear spec given wins; the URDF is only checked against it
    with pytest.warns(Warning, match=r"total ratio of .* but the URDF .* gives 100 for joint elbow"):
        rec = load_recording(bags["mcap folder"], joint="elbow", urdf=urdf, gear="silo4-joint3")
    assert rec.gear.name != "elbow (URDF)"
    with pytest.raises(InputError, match=r"no simple transmission with a mechanical reduction for joint 'shoulder'"):
        load_recording(bags["mcap folder"], joint="shoulder", urdf=urdf)
    # through the command line: the report's recording summary carries the sentence
    out = tmp_path / "out"
    assert main(["fit", str(bags["mcap folder"]), "--joint", "elbow", "--urdf", str(urdf), "--law", "stribeck",
                 "--no-published", "--folds", "3", "--quiet", "--out", str(out)]) == 0
    assert f"gear ratio 100 from URDF {urdf}, joint elbow" in (out / "report.md").read_text()


def test_folder_of_bags_and_bag_folder(bags, tmp_path):
    # a rosbag2 folder is one recording; a folder holding bags is expanded like one holding CSVs
    d = tmp_path / "many"
    d.mkdir()
    shutil.copytree(bags["mcap folder"], d / "a")
    shutil.copy(bags["ros1 bag"], d / "b.bag")
    rec = load_recording(d, joint="elbow")
    one = load_recording(bags["ros1 bag"], joint="elbow")
    assert rec.n_read == 2 * one.n_read and len(np.unique(rec.run)) == 2
    assert rec.excluded["missing_joint"] == 2
