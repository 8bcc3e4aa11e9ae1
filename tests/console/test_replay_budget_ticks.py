"""The replay's read budget counts what the replay reads, not the 100 Hz tick channels: a long
recording's ``/control/ticks`` (about 1 MB a minute) made a replayable session refused as
"larger than 256 MB uncompressed" although its drawn states and events were small. The same
bytes on a replayed channel are still refused, and ``load_recording`` applies the caller's
budget to MCAP files too (it used the default)."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from console.core.model import model_for
from console.recording.mcap_format import load_mcap
from console.recording.recorder import ReadBudget, load_recording
from core.labdata.channels import ArmGeometry
from core.labdata.mcap_file import McapLog, stored_size
from core.robots import load

SOFT = load("soft-arm")
START = 1_700_000_000_000_000_000
BUDGET = ReadBudget(max_bytes=1 << 20)


def write(path: Path, bulk_topic: str, n_bulk: int) -> None:
    """Five drawn states and ``n_bulk`` ~1 kB messages on ``bulk_topic``, 10 ms apart."""
    model = model_for(SOFT)
    header = {"robot": SOFT.name, "robot_kind": model.kind, "shape": list(model.shape)}
    with McapLog(path, header, START, ArmGeometry(SOFT)) as log:
        for i in range(5):
            log.record({"kind": "state", "q": [float(i)] * 6, "seq": i, "source": "jog",
                        "ns": START + i * 10_000_000})
        for i in range(n_bulk):
            msg = {"timestamp": {"sec": 0, "nsec": 0}, "tick": i + 1, "t_s": i * 0.01,
                   "kappa_measured_1_per_m": [0.123456789 * k for k in range(100)]}
            if bulk_topic != "/control/ticks":
                msg = {"timestamp": msg["timestamp"], "kind": "bulk", "who": "server",
                       "data": str(msg)}
            log.write(bulk_topic, msg, START + 50_000_000 + i * 10_000_000, clamp=False)


def test_tick_channels_do_not_count_against_the_replay_budget(tmp_path: Path) -> None:
    path = tmp_path / "ticks.mcap"
    write(path, "/control/ticks", 2000)  # ~2.6 MB of ticks: more than the 1 MB budget
    assert path.stat().st_size < BUDGET.max_bytes  # compressed, it is small
    rec = load_mcap(path, model_for(SOFT), BUDGET)
    assert [q[0] for q in rec.qs] == [0.0, 1.0, 2.0, 3.0, 4.0]
    # the summary's count of the replayed bytes matches the replayed messages as the mcap
    # package reads them (31 bytes of record header each; schema and channel records in a
    # chunk count with the message before them)
    with open(path, "rb") as f:
        counted, n = stored_size(f, exclude=("/control/ticks",))
        f.seek(0)
        sizes = [len(m.data) + 31 for _, ch, m in make_reader(f).iter_messages()
                 if ch.topic != "/control/ticks"]
    assert n == len(sizes) == 15  # 5 states, each on 3 channels
    assert sum(sizes) <= counted <= sum(sizes) + 32 * 1024


def test_the_same_bytes_on_a_replayed_channel_are_still_refused(tmp_path: Path) -> None:
    """Through ``load_recording`` (which did not hand its budget to the MCAP reader)."""
    path = tmp_path / "bulk.mcap"
    write(path, "/console/bulk", 2000)
    with pytest.raises(ValueError, match="larger than 1 MB uncompressed"):
        load_recording(path, model_for(SOFT), BUDGET)
