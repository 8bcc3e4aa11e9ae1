"""A one-line gigabyte recording is refused without the reader growing: the part of
test_recording_budget.py that used to assert a wall-clock limit ("within a second").

The refusal's time is measured by ``benchmarks/bench_recording_budget.py`` (a few ms, goal
1 s, beside the time gzip takes to inflate the megabyte the refusal has to read), never
asserted here: the suite runs this test beside another on two busy cores. What is checked here
holds under any load: the reason names the line and the limit, and the reader never held more
than one line (1 MB) of the gigabyte in memory.
"""

from __future__ import annotations

from typing import Any

import pytest
from test_recording_budget import GB, SOFT, header, max_rss_mb, write_gzip

from console.core.model import model_for
from console.recording.recorder import load_recording


@pytest.fixture
def model() -> Any:
    return model_for(SOFT)


def test_one_line_gigabyte_is_refused_without_growing(tmp_path, model):
    path = tmp_path / "oneline.jsonl.gz"
    write_gzip(path, header(model) + b'{"t": 0, "kind": "state", "q": "', b"\0" * 4096, GB)
    assert path.stat().st_size < 8 << 20  # ~1 MB compressed
    rss0 = max_rss_mb()
    with pytest.raises(ValueError, match="line 2 is longer than 1024 kB"):
        load_recording(path, model)
    assert max_rss_mb() - rss0 < 50  # never more than one line (1 MB) in memory
