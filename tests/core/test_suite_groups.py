"""The test suite's own groups and parts (tests/conftest.py): scripts/test runs the tests
without wall-clock limits on two workers, the browser tests two at a time and the
timing-sensitive tests (marked ``timing``, and the browser tests marked ``alone``) one at a
time; the marker, not a list of paths, puts a test in the timing part."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO, in_suite_part, slow_first, suite_part_of, xdist_group_of

PARTS = ("parallel", "browser", "timing", "alone")
pytest_plugins = ["pytester"]  # its `pytester` fixture: real items from a module's source


class _Item:
    """What suite_part_of reads of a pytest item: its node id and markers."""

    def __init__(self, nodeid: str, *markers: str) -> None:
        self.nodeid, self.markers = nodeid, markers

    def get_closest_marker(self, name: str) -> pytest.Mark | None:
        return getattr(pytest.mark, name).mark if name in self.markers else None


def test_browser_tests_share_one_group_and_the_rest_none() -> None:
    for path in sorted((REPO / "tests" / "browser").glob("test_*.py")):
        rel = path.relative_to(REPO).as_posix()
        assert xdist_group_of(_Item(f"{rel}::test_x", "browser")) == "browser"  # type: ignore[arg-type]
    here = f"{Path(__file__).relative_to(REPO).as_posix()}::t"
    assert xdist_group_of(_Item(here)) is None  # type: ignore[arg-type]
    assert xdist_group_of(_Item("tests/core/test_units.py::t")) is None  # type: ignore[arg-type]


def test_a_test_marked_timing_is_in_the_timing_part_and_an_unmarked_one_in_parallel() -> None:
    """The ``timing`` marker alone decides, wherever the file is (no list of paths)."""
    for path in ("tests/core/test_units.py", "tests/hw_bridge/test_loop.py"):
        marked, unmarked = _Item(f"{path}::t", "timing"), _Item(f"{path}::t")
        assert xdist_group_of(marked) == "timing"  # type: ignore[arg-type]
        assert suite_part_of(marked) == "serial"  # type: ignore[arg-type]
        assert [p for p in PARTS if in_suite_part(marked, p)] == ["timing"]  # type: ignore[arg-type]
        assert suite_part_of(unmarked) == "parallel"  # type: ignore[arg-type]
        assert [p for p in PARTS if in_suite_part(unmarked, p)] == ["parallel"]  # type: ignore[arg-type]


def test_a_modules_timing_pytestmark_reaches_its_collected_tests(pytester: pytest.Pytester) -> None:
    """Real items: ``pytestmark = pytest.mark.timing`` in a module (as the timing files have it)
    puts each of its tests, parametrised or in a class, in the timing part; a module without
    it stays in the parallel part."""
    pytester.makeini("[pytest]\nmarkers = timing: as in tests/conftest.py\n")
    pytester.makepyfile(
        test_marked="import pytest\n"
        "pytestmark = [pytest.mark.skipif(False, reason='-'), pytest.mark.timing]\n"
        "def test_a(): pass\n"
        "@pytest.mark.parametrize('x', [1, 2])\n"
        "def test_b(x): pass\n"
        "class TestC:\n"
        "    def test_c(self): pass\n",
        test_unmarked="def test_d(): pass\n")
    items, _ = pytester.inline_genitems()
    assert [(i.nodeid, suite_part_of(i)) for i in items] == [
        ("test_marked.py::test_a", "serial"), ("test_marked.py::test_b[1]", "serial"),
        ("test_marked.py::test_b[2]", "serial"), ("test_marked.py::TestC::test_c", "serial"),
        ("test_unmarked.py::test_d", "parallel")]
    assert [in_suite_part(i, "timing") for i in items] == [True, True, True, True, False]


def test_the_timing_marker_is_registered(pytestconfig: pytest.Config) -> None:
    assert any(line.startswith("timing:") for line in pytestconfig.getini("markers"))


def test_suite_parts_split_the_browser_tests_by_the_alone_marker() -> None:
    browser = "tests/browser/test_browser_lab.py::test_x"
    assert suite_part_of(_Item(browser, "browser")) == "browser"  # type: ignore[arg-type]
    assert suite_part_of(_Item(browser, "browser", "alone")) == "serial"  # type: ignore[arg-type]
    timing = "tests/hw_bridge/test_loop.py::test_x"
    assert suite_part_of(_Item(timing, "timing")) == "serial"  # type: ignore[arg-type]
    assert suite_part_of(_Item("tests/core/test_units.py::t")) == "parallel"  # type: ignore[arg-type]


def test_the_serial_part_splits_into_timing_and_alone() -> None:
    """SUITE_PART=timing and SUITE_PART=alone are the serial part's two halves, and every test
    is in exactly one part of the four."""
    timing = "tests/hw_bridge/test_loop.py::test_x"
    browser = "tests/browser/test_browser_lab.py::test_x"
    items = {"timing": _Item(timing, "timing"), "alone": _Item(timing, "timing", "alone"),
             "alone only": _Item(timing, "alone"),  # (not in the parallel part: CPU hogs)
             "browser": _Item(browser, "browser"),
             "alone browser": _Item(browser, "browser", "alone"),
             "parallel": _Item("tests/core/test_units.py::t")}
    parts = {name: [p for p in PARTS if in_suite_part(item, p)]
             for name, item in items.items()}  # type: ignore[arg-type]
    assert parts == {"timing": ["timing"], "alone": ["alone"], "alone only": ["alone"],
                     "browser": ["browser"],
                     "alone browser": ["alone"], "parallel": ["parallel"]}
    assert all(in_suite_part(items[n], "serial") for n in ("timing", "alone", "alone browser"))  # type: ignore[arg-type]


def _first_batches(items: list, workers: int) -> list[list]:
    """What pytest-xdist's load scheduling sends each worker first (xdist/scheduler/load.py,
    ``schedule``): consecutive chunks of ``max(len // workers // 4, 2)`` items."""
    chunk = max(len(items) // workers // 4, 2)
    return [items[k * chunk:(k + 1) * chunk] for k in range(workers)]


@pytest.mark.parametrize("n_slow", [1, 4, 7])
@pytest.mark.parametrize("workers", [2, 4])
def test_slow_tests_open_each_workers_first_batch_and_lead_the_rest(workers, n_slow) -> None:
    """The ``slow`` tests (a simulated arm in real time, ~30-60 s) used to sit where the
    collection put them, and the parallel part ended with one of them running alone for ~50 s.
    Reordered, each worker's first batch starts with one; the others lead what is sent next; no
    test is lost or doubled and the rest keep their order."""
    items = [_Item(f"tests/t.py::t{i}", *(("slow",) if i % 97 == 5 and i < 97 * n_slow else ()))
             for i in range(1345)]
    slow = [i for i in items if i.markers]
    assert len(slow) == n_slow
    ordered = slow_first(items, workers)  # type: ignore[arg-type]
    assert sorted(i.nodeid for i in ordered) == sorted(i.nodeid for i in items)
    batches = _first_batches(ordered, workers)
    firsts = [b[0] for b in batches]
    assert firsts[:min(n_slow, workers)] == slow[:workers]
    assert sum(bool(i.markers) for b in batches for i in b) == min(n_slow, workers)
    sent = sum(len(b) for b in batches)
    assert ordered[sent:sent + max(n_slow - workers, 0)] == slow[workers:]
    rest = [i for i in ordered if not i.markers]
    assert rest == [i for i in items if not i.markers]
