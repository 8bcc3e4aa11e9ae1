"""The test suite's own xdist groups (tests/conftest.py): scripts/test runs ``pytest -n 2``
with the browser tests on one worker in turn and the timing-sensitive tests likewise; a file
renamed or moved must not silently leave its group."""

from __future__ import annotations

from pathlib import Path

from conftest import REPO, TIMING_FILES, xdist_group_of


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
