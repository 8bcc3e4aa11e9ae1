"""One robot schema: every section of both shipped files is read once, typed, bounded, and every
error names the file, the section and the key; unknown keys are refused with the known ones.

The checks walk the shipped TOML tables themselves (every section, every key), so a key added
to a file without a reader, or a reader that skips a check, fails here.
"""

from __future__ import annotations

import copy
import math
import re
import tracemalloc
from typing import Any, Iterator

import numpy as np
import pytest

from core import robots
from core.robot_schema import RobotFileError, tomllib

SHIPPED = {name: tomllib.loads((robots.ROBOTS_DIR / f"{name}.toml").read_text())
           for name in ("soft-arm", "extensible")}
STRINGS = {"name", "kind", "synchronization", "mode", "mapping"}


def tables(t: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, dict[str, Any]]]:
    """(dotted section name, table) for every table of a file, the top level as ""."""
    yield prefix, t
    for k, v in t.items():
        if isinstance(v, dict):
            yield from tables(v, f"{prefix}.{k}" if prefix else k)


def leaves(t: dict[str, Any]) -> list[tuple[str, str]]:
    """(section, key) for every non-table value."""
    return [(sec, k) for sec, tab in tables(t) for k, v in tab.items() if not isinstance(v, dict)]


def edited(name: str, section: str, key: str, value: Any = None, *, delete: bool = False):
    table = copy.deepcopy(SHIPPED[name])  # the file as read, fresh for each edit
    node = table
    for part in filter(None, section.split(".")):
        node = node[part]
    if delete:
        del node[key]
    else:
        node[key] = value
    return table


def parse(table: dict[str, Any], name: str):
    return robots.parse(table, robots.ROBOTS_DIR / f"{name}.toml")


def field(section: str, key: str) -> str:
    return f"{section}.{key}" if section else key


def refusal(case: str, table: dict[str, Any], name: str, pattern: str) -> str | None:
    """None if parsing ``table`` raises RobotFileError whose message matches ``pattern``
    (``re.search``, as ``pytest.raises(match=)``); else what went wrong, naming ``case``.

    The generated cases (every section and key of both files, ~800) run as loops in a few
    tests rather than one pytest item each (which cost pytest's per-item overhead 800 times);
    every failing case is named in the assertion message.
    """
    try:
        parse(table, name)
    except RobotFileError as err:
        msg = str(err)
        if not re.search(pattern, msg):
            return f"{case}: message {msg!r} does not match {pattern!r}"
        if "Traceback" in msg:
            return f"{case}: a traceback in the message {msg!r}"
        return None
    except Exception as err:  # noqa: BLE001 - any other exception is a failure of this case
        return f"{case}: {type(err).__name__}: {err}"
    return f"{case}: accepted (no RobotFileError)"


CASES = [(n, s, k) for n in SHIPPED for s, k in leaves(SHIPPED[n])]
SECTIONS = [(n, s) for n in SHIPPED for s, _ in tables(SHIPPED[n])]


FLAT = {"segments.count": "n_segments", "segments.length": "segment_length",
        "motors.mapping": "motor_mapping", "base.pose": "base_pose"}
FLAT_SECTIONS = ("", "segments", "limits", "motors", "actuation", "base")


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_files_round_trip_into_the_typed_sections(name):
    """Every value of the file is what the typed robot holds (nothing read twice or dropped)."""
    robot = robots.load(name)
    for sec, key in leaves(SHIPPED[name]):
        value = _node(SHIPPED[name], sec)[key] if sec else SHIPPED[name][key]
        dotted = field(sec, key)
        if dotted == "bin.mode":
            assert value == "straight" and not robot.bin.kappa.any()
            continue
        if sec in FLAT_SECTIONS:
            got = getattr(robot, FLAT.get(dotted, key))
        else:
            obj: Any = robot
            for part in sec.split("."):
                obj = getattr(obj, part)
            got = getattr(obj, key)
        if isinstance(got, (np.ndarray, tuple, list)):
            want = np.broadcast_to(np.asarray(value, float), np.shape(got))
            np.testing.assert_array_equal(np.asarray(got, float), want, err_msg=dotted)
        else:
            assert got == value and type(got) in (type(value), float), dotted


def test_unknown_key_refused_in_every_section_with_the_known_ones():
    assert len(SECTIONS) > 20
    for name, section in SECTIONS:
        case = f"{name} [{section}]"
        known = sorted(SHIPPED[name] if not section else _node(SHIPPED[name], section))
        with pytest.raises(RobotFileError) as err:
            parse(edited(name, section, "wieghts", 1.0), name)
        msg = str(err.value)
        where = f"[{section}]" if section else "top level"
        assert msg.startswith(f"{name}.toml: {where}: unknown key 'wieghts'; known keys: "), \
            (case, msg)
        listed = msg.split("known keys: ")[1].split(", ")
        assert set(known) <= set(listed), (case, known, listed)


def _node(t: dict[str, Any], section: str) -> dict[str, Any]:
    for part in section.split("."):
        t = t[part]
    return t


@pytest.mark.parametrize("name", SHIPPED)
def test_missing_key_either_defaults_or_names_file_section_and_key(name):
    optional = {"planner.weights", "planner.clearance_margin", "planner.base_keepout",
                "planner.max_restarts", "planner.max_insertions", "planner.line_samples",
                "planner.seed_table", "bridge.velocities", "trajectory.synchronization",
                "motors.mapping", "gripper.fingers",
                "segments.body_radius"} | {field(s, k) for s, k in leaves(SHIPPED["extensible"])
                                     if s in ("ik", "paths")}
    failures = []
    cases = [c for c in CASES if c[0] == name]
    assert len(cases) > 20
    for _, section, key in cases:
        case = f"{name}: without {field(section, key)}"
        table = edited(name, section, key, delete=True)
        if field(section, key) in optional:
            try:
                parse(table, name)
            except Exception as err:  # noqa: BLE001 - an optional key must default
                failures.append(f"{case}: {type(err).__name__}: {err}")
            continue
        failures.append(refusal(case, table, name, rf"^{name}\.toml: .*"
                                rf"{'kind' if key == 'kind' else field(section, key)}"))
    failures = [f for f in failures if f]
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("name", SHIPPED)
def test_wrong_type_names_file_section_and_key(name):
    failures = []
    cases = [c for c in CASES if c[0] == name and c[2] != "name"]
    assert len(cases) > 20
    for _, section, key in cases:
        for bad in (["x"], {"x": 1} if key not in STRINGS else 3, True if key != "velocities"
                    and key != "pass_over" else 1):
            failures.append(refusal(f"{name}: {field(section, key)} = {bad!r}",
                                    edited(name, section, key, bad), name,
                                    rf"^{name}\.toml: {field(section, key)}\b"))
    failures = [f for f in failures if f]
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -1e300, 1e300])
def test_non_finite_and_absurd_numbers_are_refused(name, bad):
    failures = []
    cases = [c for c in CASES if c[0] == name and c[2] not in STRINGS
             and c[2] not in ("velocities", "pass_over")]
    assert len(cases) > 20
    for _, section, key in cases:
        value = _node(SHIPPED[name], section)[key] if section else SHIPPED[name][key]
        if isinstance(value, list) and key != "pose":
            given: Any = [bad] * len(value)
        elif key == "pose":
            given = [0.0, bad, 0.0]
        else:
            given = bad
        failures.append(refusal(f"{name}: {field(section, key)} = {given!r}",
                                edited(name, section, key, given), name,
                                rf"^{name}\.toml: {field(section, key)}"))
    failures = [f for f in failures if f]
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("name,limit", [("soft-arm", 15), ("extensible", 4)])
def test_segment_count_is_bounded_and_a_huge_one_fails_fast(name, limit):
    for count in (0, -1, limit + 1, 100000):
        table = edited(name, "segments", "count", count)
        tracemalloc.start()
        try:
            with pytest.raises(RobotFileError, match=rf"segments\.count: must be an integer in "
                                                     rf"\[1, {limit}\], got {count}"):
                parse(table, name)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        # Refused before any per-segment work: a list of 100000 numbers alone is 0.8 MB (the
        # refusal peaks at ~3 KB, a whole file's parse at ~10 KB).
        assert peak < 100_000, peak
    assert robots.MAX_SEGMENTS[robots.load(name).kind] == limit
    parse(edited(name, "segments", "count", limit), name)  # the limit itself loads


def test_channel_counts_fit_the_serial_protocol():
    from hw_bridge import protocol
    assert 2 * robots.MAX_SEGMENTS["planar"] + 1 <= protocol.MAX_MOTORS
    assert 3 * robots.MAX_SEGMENTS["delta"] <= protocol.MAX_MOTORS


@pytest.mark.parametrize("section,key,value,message", [
    ("planner", "weights", [1.0] * 5,
     r"planner\.weights: must have 4 entries, one per segment \(segments\.count = 4\), got 5"),
    ("trajectory", "max_velocity", [0.8] * 6, r"trajectory\.max_velocity: must have 4 entries"),
    ("actuation", "drive_cylinders", 13,
     r"actuation\.drive_cylinders: must be 2 per segment \+ gripper = 9 \(segments\.count = 4\)"),
    ("actuation", "prepressurised_segments", 5,
     r"actuation\.prepressurised_segments: must be an integer in \[0, 4\]"),
    ("planner", "weights", [1.0, 1.0, 0.0, 1.0], r"planner\.weights\[2\]: must be > 0"),
])
def test_per_segment_lists_are_checked_against_the_count(section, key, value, message):
    table = edited("soft-arm", "segments", "count", 4)
    _node(table, section)[key] = value
    with pytest.raises(RobotFileError, match=rf"^soft-arm\.toml: {message}"):
        parse(table, "soft-arm")


def test_per_segment_lists_default_from_the_count_and_broadcast_a_number():
    table = edited("soft-arm", "segments", "count", 5)
    arm = parse(table, "soft-arm")
    assert arm.planner.weights == (1.0,) * 5 and arm.drive_cylinders == 11
    assert arm.trajectory.max_velocity.shape == (5,) and arm.bin.kappa.shape == (5,)
    table["planner"]["weights"] = [1.0, 2.0, 3.0, 4.0, 5.0]
    table["bin"].update(mode="kappa", kappa=[1.0, -1.0, 0.0, 2.0, 3.0])
    arm = parse(table, "soft-arm")
    assert arm.planner.weights == (1.0, 2.0, 3.0, 4.0, 5.0)
    np.testing.assert_array_equal(arm.bin.kappa, [1.0, -1.0, 0.0, 2.0, 3.0])
    table["bin"]["kappa"] = [1.0, 2.0]
    with pytest.raises(RobotFileError, match=r"bin\.kappa: must have 5 entries"):
        parse(table, "soft-arm")


def test_extensible_motor_count_defaults_from_the_segments_and_is_checked():
    table = edited("extensible", "segments", "count", 3)
    assert parse(table, "extensible").n_motors == 9
    table["motors"]["count"] = 6
    with pytest.raises(RobotFileError, match=r"motors\.count: must be 3 per segment \(9, "
                                             r"segments\.count = 3\), got 6"):
        parse(table, "extensible")


@pytest.mark.parametrize("name,section,key,value", [
    ("soft-arm", "controller", "cylinder_max", -5.0),
    ("soft-arm", "controller", "prepressure", 5000.0),
    ("soft-arm", "bridge", "rate_hz", 0),
    ("soft-arm", "bridge", "config_retries", 100000),
    ("soft-arm", "emulator", "mocap_port", 70000),
    ("soft-arm", "planner", "seed_table", 10**9),
    ("soft-arm", "sim.gripper", "sweep_steps", 10**8),
    ("soft-arm", "state_machine", "max_replans", 10**6),
    ("soft-arm", "bin", "mode", "elsewhere"),
    ("soft-arm", "trajectory", "synchronization", "none"),
    ("extensible", "ik", "max_iterations", 10**8),
    ("extensible", "paths", "spacing", 1e-9),
    ("extensible", "paths", "max_bisections", 60),
    ("extensible", "motors", "mapping", "diagonal"),
    ("extensible", "emulator", "counts_per_kappa", 60.0),  # a soft-arm key: unknown here
])
def test_bounds_name_file_section_and_key(name, section, key, value):
    with pytest.raises(RobotFileError) as err:
        parse(edited(name, section, key, value), name)
    msg = str(err.value)
    assert msg.startswith(f"{name}.toml: ") and (field(section, key) in msg
                                                or f"[{section}]" in msg), msg


def test_missing_section_is_named():
    table = tomllib.loads((robots.ROBOTS_DIR / "soft-arm.toml").read_text())
    del table["controller"]
    with pytest.raises(RobotFileError, match=r"^soft-arm\.toml: \[controller\]: missing section"):
        parse(table, "soft-arm")
    table = tomllib.loads((robots.ROBOTS_DIR / "extensible.toml").read_text())
    del table["ik"], table["paths"]  # optional: the documented defaults
    arm = parse(table, "extensible")
    assert arm.ik == robots.IKSettings() and arm.paths == robots.PathSettings()


def test_a_file_given_by_path_is_named_by_its_path(tmp_path):
    text = (robots.ROBOTS_DIR / "soft-arm.toml").read_text().replace("kp = 90.0", "kp = -1.0")
    path = tmp_path / "lab-arm.toml"
    path.write_text(text)
    with pytest.raises(RobotFileError, match=rf"^{path}: controller\.kp: must be >= 0, got -1$"):
        robots.load(path)
    with pytest.raises(RobotFileError, match="no such file"):
        robots.load(tmp_path / "none.toml")


def test_a_misspelt_required_key_is_reported_with_the_spelling_found():
    table = edited("soft-arm", "controller", "kp", delete=True)
    table["controller"]["kP"] = 90.0
    with pytest.raises(RobotFileError, match=r"^soft-arm\.toml: controller\.kp: missing \(a "
                                             r"required key of \[controller\]\); the table has "
                                             r"'kP': a misspelling\?$"):
        parse(table, "soft-arm")


@pytest.mark.parametrize("old,new,message", [
    ("kp = 90.0", "kp = \"fast\"", r"controller\.kp: must be a finite number, got 'fast'"),
    ("weights = 1.0 ", "weights = [1.0, 1.0] ",
     r"planner\.weights: must have 6 entries, one per segment \(segments\.count = 6\), got 2"),
    ("baud = 1000000", "baud = -5", r"bridge\.baud: must be an integer in \[300, 100000000\]"),
    ("count = 6 ", "count = 100000 ", r"segments\.count: must be an integer in \[1, 15\]"),
])
def test_serve_refuses_a_bad_robot_file_before_starting_anything(serve_module, tmp_path, capsys,
                                                                  monkeypatch, old, new,
                                                                  message):
    """Issue 20: these used to give a traceback or a GUI stuck on 'starting the control process'."""
    text = (robots.ROBOTS_DIR / "soft-arm.toml").read_text()
    assert old in text
    path = tmp_path / "lab-arm.toml"
    path.write_text(text.replace(old, new))

    def started(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("serve.py started something for a bad robot file")
    monkeypatch.setattr(serve_module, "build", started)
    monkeypatch.setattr(serve_module, "Lifecycle", started)
    assert serve_module.main(["--robot", str(path), "--port", "1"]) == 2
    err = capsys.readouterr().err
    assert re.fullmatch(rf"serve\.py: {re.escape(str(path))}: {message}.*\n", err), err
