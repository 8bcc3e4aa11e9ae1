"""serve.py for the lab: token printed (or not), desk vs lab mode, data folder, URLs to open."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def start(*args: str) -> list[str]:
    """Run serve.py until it printed its data folder line; return stdout lines, then stop it."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, str(REPO / "serve.py"), "--port", str(port), *args],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if line.startswith("Data folder:"):
                break
    finally:
        proc.terminate()
        proc.communicate(timeout=60)  # however long a loaded box takes
    assert proc.returncode == 0, lines
    return lines


def test_default_prints_a_token_and_runs_as_a_desk_console(tmp_path: Path) -> None:
    lines = start("--data-dir", str(tmp_path / "d"))
    token = [ln for ln in lines if ln.startswith("Operator token: ")]
    assert token and len(token[0].split()[2]) >= 12
    assert any(ln.startswith("Desk mode:") for ln in lines)
    assert f"Data folder: {(tmp_path / 'd').resolve()}" in lines
    assert (tmp_path / "d" / "recordings").is_dir() and (tmp_path / "d" / "exports").is_dir()


def test_lab_mode_without_token(tmp_path: Path) -> None:
    lines = start("--lab", "--no-token", "--data-dir", str(tmp_path))
    assert "No operator token (--no-token): any browser can take control." in lines
    assert not any(ln.startswith(("Operator token", "Desk mode")) for ln in lines)


def test_lab_network_urls_and_loopback_detection(monkeypatch, serve_module) -> None:
    serve = serve_module
    monkeypatch.setattr(serve, "lan_addresses", lambda: ["10.1.2.3"])
    assert serve.urls("0.0.0.0", 8080) == ["http://127.0.0.1:8080/", "http://10.1.2.3:8080/"]
    assert serve.urls("192.168.0.5", 9000) == ["http://192.168.0.5:9000/"]
    assert serve.urls("::1", 80) == ["http://[::1]:80/"]
    assert serve.is_loopback("127.0.0.1") and serve.is_loopback("localhost")
    assert serve.is_loopback("::1") and not serve.is_loopback("0.0.0.0")
    assert not serve.is_loopback("192.168.0.5")


def test_lan_addresses_are_ipv4_and_never_loopback(serve_module) -> None:
    import ipaddress

    for a in serve_module.lan_addresses():
        assert not ipaddress.IPv4Address(a).is_loopback


def test_help_documents_host_port_and_the_data_folder() -> None:
    out = subprocess.run([sys.executable, str(REPO / "serve.py"), "--help"], cwd=REPO,
                         capture_output=True, text=True, timeout=60).stdout
    for flag in ("--host", "--port", "--data-dir", "--no-token", "--lab", "0.0.0.0"):
        assert flag in out
