"""A one-line gigabyte recording is refused within a second without the reader growing: the
wall-clock part of test_recording_budget.py, marked `timing` so it runs alone
(the rest of that file asserts no wall-clock time that another test's load could break)."""

from __future__ import annotations

import time
from typing import Any

import pytest
from test_recording_budget import GB, SOFT, header, max_rss_mb, write_gzip

from console.core.model import model_for
from console.recording.recorder import load_recording

pytestmark = pytest.mark.timing


@pytest.fixture
def model() -> Any:
    return model_for(SOFT)


def test_one_line_gigabyte_is_refused_within_a_second_without_growing(tmp_path, model):
    path = tmp_path / "oneline.jsonl.gz"
    write_gzip(path, header(model) + b'{"t": 0, "kind": "state", "q": "', b"\0" * 4096, GB)
    assert path.stat().st_size < 8 << 20  # ~1 MB compressed
    rss0 = max_rss_mb()
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match="line 2 is longer than 1024 kB"):
        load_recording(path, model)
    assert time.perf_counter() - t0 < 1.0
    assert max_rss_mb() - rss0 < 50  # never more than one line (1 MB) in memory
