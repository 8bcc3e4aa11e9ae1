"""The test suite's own groups and parts (tests/conftest.py): scripts/test runs the tests
without wall-clock limits on two workers, the browser tests two at a time and the
timing-sensitive tests (``TIMING_FILES`` and the browser tests marked ``alone``) one at a
time; a file renamed or moved must not silently leave its group."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO, TIMING_FILES, in_suite_part, suite_part_of, xdist_group_of


def test_every_timing_file_exists_and_is_grouped() -> None:
    missing = sorted(p for p in TIMING_FILES if not (REPO / p).is_file())
    assert missing == [], f"in TIMING_FILES but not in the repository: {missing}"
    for path in TIMING_FILES:
        assert xdist_group_of(f"{path}::test_x[a]") == "timing"


def test_browser_tests_share_one_group_and_the_rest_none() -> None:
    for path in sorted((REPO / "tests" / "browser").glob("test_*.py")):
        rel = path.relative_to(REPO).as_posix()
        assert xdist_group_of(f"{rel}::test_x") == "browser"
    assert xdist_group_of(f"{Path(__file__).relative_to(REPO).as_posix()}::t") is None
    assert xdist_group_of("tests/core/test_units.py::test_radians_read_as_degrees") is None


class _Item:
    """What suite_part_of reads of a pytest item: its node id and markers."""

    def __init__(self, nodeid: str, *markers: str) -> None:
        self.nodeid, self.markers = nodeid, markers

    def get_closest_marker(self, name: str) -> object | None:
        return pytest.mark.alone if name in self.markers else None


def test_suite_parts_split_the_browser_tests_by_the_alone_marker() -> None:
    browser = "tests/browser/test_browser_lab.py::test_x"
    assert suite_part_of(_Item(browser, "browser")) == "browser"  # type: ignore[arg-type]
    assert suite_part_of(_Item(browser, "browser", "alone")) == "serial"  # type: ignore[arg-type]
    timing = f"{sorted(TIMING_FILES)[0]}::test_x"
    assert suite_part_of(_Item(timing)) == "serial"  # type: ignore[arg-type]
    assert suite_part_of(_Item("tests/core/test_units.py::t")) == "parallel"  # type: ignore[arg-type]


def test_the_serial_part_splits_into_timing_and_alone() -> None:
    """SUITE_PART=timing and SUITE_PART=alone are the serial part's two halves, and every test
    is in exactly one part of the four."""
    timing = f"{sorted(TIMING_FILES)[0]}::test_x"
    browser = "tests/browser/test_browser_lab.py::test_x"
    items = {"timing": _Item(timing), "alone": _Item(timing, "alone"),
             "browser": _Item(browser, "browser"),
             "alone browser": _Item(browser, "browser", "alone"),
             "parallel": _Item("tests/core/test_units.py::t")}
    parts = {name: [p for p in ("parallel", "browser", "timing", "alone")
                    if in_suite_part(item, p)] for name, item in items.items()}  # type: ignore[arg-type]
    assert parts == {"timing": ["timing"], "alone": ["alone"], "browser": ["browser"],
                     "alone browser": ["alone"], "parallel": ["parallel"]}
    assert all(in_suite_part(items[n], "serial") for n in ("timing", "alone", "alone browser"))  # type: ignore[arg-type]
