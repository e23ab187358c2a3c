"""ROS bags as recordings (``CONTRACTS.md`` section 1): rosbag2 (a bag folder with ``metadata.yaml``,
or a single ``.db3`` / ``.mcap`` file) and ROS 1 ``.bag``, read with the pure-Python ``rosbags``
library (no ROS install).  ``sensor_msgs/msg/JointState`` on a topic gives, for one joint, the
columns ``t`` (header stamp, s from the topic's first stamp), ``theta`` (position), ``velocity``
(when the messages carry it) and ``torque`` (effort); other topics give columns through ``--map``
(``temperature=/motor_temperature.temperature``: topic, then the field path).

Messages the joint cannot use (the joint missing, arrays of another length than ``name``, a zero
stamp among real ones, a row outside a mapped topic's time span) are counted per reason in the
recording's ledger like any other excluded row; NaN values reach the common cleaning and are counted
there as ``nan_or_inf``.  Nothing is mapped, scaled or cleaned here otherwise.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError

__all__ = ["BAG_SUFFIXES", "JOINT_STATE", "DEFAULT_TOPIC", "is_bag", "bag_joints", "read_bag"]

#: file suffixes read as bags (a folder holding ``metadata.yaml`` is a rosbag2 bag too)
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
#: the message type read for joints
JOINT_STATE = "sensor_msgs/msg/JointState"
#: the topic read when none is given
DEFAULT_TOPIC = "/joint_states"
#: the three arrays of a JointState and the column each becomes
_ARRAYS = (("position", "theta"), ("velocity", "velocity"), ("effort", "torque"))


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a ROS bag: a ``.bag`` / ``.mcap`` / ``.db3`` file or a rosbag2 folder."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in BAG_SUFFIXES


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:200]


class _Bag:
    """An open bag: its topics, and the messages of one topic as ``(log_ns, message)``."""

    def __init__(self, path: Path):
        self.path = path

    def __enter__(self):
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        if not self.path.exists():
            raise InputError(f"{self.path}: no such file")
        if self.path.is_file() and self.path.stat().st_size == 0:
            raise InputError(f"{self.path}: the file is empty")
        try:
            # bags of ROS 2 distributions before Iron store no message definitions: the standard
            # messages' (JointState, Temperature, ...) are the same in every distribution since Foxy
            self.reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            self.reader.open()
        except Exception as exc:  # rosbags raises many types for a damaged file
            raise InputError(f"{self.path}: cannot be read as a ROS bag; it is damaged or cut short "
                             f"({_first_line(exc)})") from None
        return self

    def __exit__(self, *exc):
        try:
            self.reader.close()
        except Exception:  # closing a damaged bag may fail again; the first error is the one to say
            pass
        return False

    def topics(self) -> dict[str, str]:
        return {name: info.msgtype for name, info in self.reader.topics.items()}

    def check_topic(self, topic: str, msgtype: str | None = JOINT_STATE, why: str = "--topic") -> None:
        topics = self.topics()
        if topic not in topics:
            listed = ", ".join(f"{k} ({v})" for k, v in sorted(topics.items())) or "none"
            raise InputError(f"{self.path}: no topic '{topic}' (given by {why}); the bag's topics are: {listed}")
        if msgtype is not None and topics[topic] != msgtype:
            raise InputError(f"{self.path}: topic '{topic}' carries {topics[topic]}, not {msgtype}; "
                             "choose the joint-state topic with --topic")

    def messages(self, topic: str):
        conns = [c for c in self.reader.connections if c.topic == topic]
        try:
            for conn, log_ns, raw in self.reader.messages(connections=conns):
                yield int(log_ns), self.reader.deserialize(raw, conn.msgtype)
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"{self.path}: a message on '{topic}' cannot be read, the bag is damaged "
                             f"({_first_line(exc)})") from None


def _stamp_ns(msg) -> int:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return 0
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _scan(bag: _Bag, topic: str):
    """The JointState messages of ``topic`` as arrays: stamp and log time (ns), names, and the three
    value arrays (an array of another length than ``name`` is kept as is, judged per joint)."""
    stamps, logs, names, values = [], [], [], {a: [] for a, _ in _ARRAYS}
    for log_ns, msg in bag.messages(topic):
        stamps.append(_stamp_ns(msg))
        logs.append(log_ns)
        names.append(tuple(msg.name))
        for a, _ in _ARRAYS:
            values[a].append(np.asarray(getattr(msg, a), dtype=float))
    if not stamps:
        raise InputError(f"{bag.path}: topic '{topic}' holds no messages")
    return np.array(stamps, np.int64), np.array(logs, np.int64), names, values


def _joint_order(names: Sequence[tuple]) -> list[str]:
    """Every joint name in the order of first appearance."""
    return list(dict.fromkeys(n for tup in dict.fromkeys(names) for n in tup))


def bag_joints(path: str | Path, topic: str = DEFAULT_TOPIC) -> list[str]:
    """The joint names on ``topic`` of the bag ``path``, in the order they first appear.

    Parameters
    ----------
    path : str or Path
        A ``.bag``, ``.mcap`` or ``.db3`` file, or a rosbag2 folder.
    topic : str
        A ``sensor_msgs/msg/JointState`` topic.
    """
    with _Bag(Path(path)) as bag:
        bag.check_topic(topic)
        return _joint_order(_scan(bag, topic)[2])


def _choose_joints(path: Path, topic: str, joint: str | None, found: list[str]) -> list[str]:
    if joint == "all":
        return found
    if joint is None:
        if len(found) == 1:
            return found
        raise InputError(f"{path}: topic '{topic}' carries {len(found)} joints ({', '.join(found)}); choose one with "
                         "--joint NAME, or --joint all for one recording per joint")
    if joint not in found:
        raise InputError(f"{path}: no joint '{joint}' on topic '{topic}' (joints: {', '.join(found) or 'none'})")
    return [joint]


def _clock(path: Path, topic: str, stamps: np.ndarray, logs: np.ndarray, notes: list[str]):
    """The time of every message (ns) and which messages keep it: header stamps; the log time when
    every stamp is zero (said in ``notes``); a zero stamp among real ones is excluded."""
    zero = stamps == 0
    if zero.all():
        notes.append(f"{path}: every header stamp on '{topic}' is zero; t is the time the bag logged each message")
        return logs.copy(), np.ones(len(logs), bool)
    return stamps.copy(), ~zero


def _joint_frame(path: Path, name: str, names, values, keep: np.ndarray, excluded: Counter) -> dict:
    """Columns of joint ``name`` over all messages (NaN where a message cannot give it); ``keep`` is
    narrowed to the messages that carry the joint with arrays as long as ``name``."""
    n = len(names)
    cols = {c: np.full(n, np.nan) for _, c in _ARRAYS}
    present = {a: False for a, _ in _ARRAYS}
    missing = np.zeros(n, bool)
    mismatch = np.zeros(n, bool)
    for i, tup in enumerate(names):
        try:
            j = tup.index(name)
        except ValueError:
            missing[i] = True
            continue
        for a, c in _ARRAYS:
            arr = values[a][i]
            if len(arr) == len(tup):
                cols[c][i] = arr[j]
                present[a] = True
            elif len(arr) or a == "position":  # an empty velocity or effort: not carried (judged below)
                mismatch[i] = True
    for a, c in _ARRAYS:
        if present[a]:
            # a quantity the topic carries must be in every message used
            empty = np.array([len(values[a][i]) == 0 for i in range(n)]) & ~missing
            mismatch |= empty
    missing &= keep
    mismatch &= keep & ~missing
    excluded["missing_joint"] += int(missing.sum())
    excluded["array_length_mismatch"] += int(mismatch.sum())
    keep &= ~missing & ~mismatch
    return {c: cols[c] for a, c in _ARRAYS if present[a]}


def _field(path: Path, source: str, msg, option: str):
    topic, _, field = source.partition(".")
    value = msg
    for part in field.split("."):
        if not hasattr(value, part):
            have = [k for k in getattr(value, "__dataclass_fields__", {}) if not k.startswith("_")]
            raise InputError(f"{path}: {option}: the message on '{topic}' has no field '{part}' "
                             f"(fields: {', '.join(have) or 'none'})")
        value = getattr(value, part)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{path}: {option}: field '{field}' of '{topic}' is not a number "
                         f"({type(value).__name__})")
    return float(value)


def _mapped_topics(bag: _Bag, sources: Sequence[str] | Mapping[str, str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For each ``/topic.field`` in ``sources`` (a mapping: to the column named in ``--map``):
    message times (ns; header stamp, else log time) and values, sorted by time."""
    out = {}
    for source in sources:
        option = f"--map {sources[source] if isinstance(sources, Mapping) else 'COL'}={source}"
        topic, dot, field = source.partition(".")
        if not dot or not field:
            raise InputError(f"{option}: a bag topic is mapped as /topic.field (e.g. "
                             "temperature=/motor_temperature.temperature)")
        bag.check_topic(topic, None, why=option)
        times, vals = [], []
        for log_ns, msg in bag.messages(topic):
            times.append(_stamp_ns(msg) or log_ns)
            vals.append(_field(bag.path, source, msg, option))
        if not times:
            raise InputError(f"{bag.path}: topic '{topic}' (given in {option}) holds no messages")
        order = np.argsort(np.array(times, np.int64), kind="stable")
        out[source] = (np.array(times, np.int64)[order], np.array(vals)[order])
    return out


def read_bag(path: str | Path, *, topic: str = DEFAULT_TOPIC, joint: str | None = None,
             sources: Sequence[str] | Mapping[str, str] = ()) -> list[tuple[str, pd.DataFrame, dict]]:
    """The recording tables of the joints chosen from one bag.

    Parameters
    ----------
    path : str or Path
        A ``.bag`` (ROS 1), ``.mcap`` or ``.db3`` file, or a rosbag2 folder with ``metadata.yaml``.
    topic : str
        The ``sensor_msgs/msg/JointState`` topic (default ``/joint_states``).
    joint : str or None
        The joint's name; None when the topic carries one joint only; ``"all"``: every joint.
    sources : sequence of str, or mapping of str to str
        Other topics' fields wanted as columns, ``/topic.field[.field...]`` (a mapping: to the column
        named in ``--map``, for messages): each becomes a column of that name (renamed by ``--map``),
        linearly interpolated at the joint's times; rows outside the topic's time span are excluded
        (``outside_mapped_topic``).

    Returns
    -------
    list of (source, frame, meta)
        Per joint: ``"FILE (joint NAME)"``; columns ``t`` (s from the topic's first time), ``theta``
        (rad or m), ``torque`` (Nm or N; when the messages carry effort), ``velocity`` (when they
        carry it) and the ``sources``; ``meta``: ``joint``, ``topic``, ``start_time`` (the first time,
        s since 1970 UTC), ``_excluded`` (messages excluded, per reason) and ``_notes``.
    """
    path = Path(path)
    with _Bag(path) as bag:
        bag.check_topic(topic)
        stamps, logs, names, values = _scan(bag, topic)
        chosen = _choose_joints(path, topic, joint, _joint_order(names))
        mapped = _mapped_topics(bag, sources)
    parts = []
    for name in chosen:
        notes: list[str] = []
        excluded: Counter = Counter()
        time_ns, keep = _clock(path, topic, stamps, logs, notes)
        excluded["zero_stamp"] += int((~keep).sum())
        cols = _joint_frame(path, name, names, values, keep, excluded)
        t0 = int(time_ns[time_ns > 0].min()) if (time_ns > 0).any() else 0
        for source, (mt, mv) in mapped.items():
            inside = (time_ns >= mt[0]) & (time_ns <= mt[-1])
            excluded["outside_mapped_topic"] += int((keep & ~inside).sum())
            keep &= inside
            cols[source] = np.interp((time_ns - t0).astype(float), (mt - t0).astype(float), mv)
        idx = np.flatnonzero(keep)
        order = idx[np.argsort(time_ns[idx], kind="stable")]
        if np.any(order != idx):
            notes.append(f"{path}: messages on '{topic}' were logged out of the order of their stamps; "
                         "sorted by stamp")
        if excluded["missing_joint"]:
            notes.append(f"{path}: {excluded['missing_joint']} of {len(names)} messages on '{topic}' do not "
                         f"carry joint '{name}'; excluded (missing_joint)")
        if not len(order):
            raise InputError(f"{path} (joint {name}): none of the {len(names)} messages on '{topic}' can be used "
                             f"({', '.join(f'{k} {v}' for k, v in sorted(excluded.items()) if v)})")
        frame = pd.DataFrame({"t": (time_ns[order] - t0) / 1e9, **{c: v[order] for c, v in cols.items()}})
        meta = {"joint": name, "topic": topic, "start_time": t0 / 1e9,
                "_excluded": Counter({k: v for k, v in excluded.items() if v}), "_notes": notes}
        parts.append((f"{path} (joint {name})", frame, meta))
    return parts
