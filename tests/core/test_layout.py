"""The repository's rooms (DEVELOPERS.md): core/ is pure, command lines live apart, no import circles.

* ``core/`` imports nothing from ``hw_bridge``/``console`` and no GUI, serial, socket, thread or
  subprocess module; a process pool (``multiprocessing``, ``concurrent.futures``) only in a
  command line (``__main__.py``), never in a library module.
* Library modules under ``core/`` and ``hw_bridge/`` have no ``argparse``, ``print``,
  ``sys.exit`` or ``if __name__ == "__main__"``: those belong to the command-line modules.
* ``console/core/`` (the console's headless state and its one safety route) imports no
  ``viser`` and nothing of ``console`` outside ``console.core``, not even lazily or for type
  checking: the views import the core, never the other way round.
* No import circle: the module-level imports form no cycle, and every module of ``core``,
  ``console`` and ``hw_bridge`` imports when it is the first one imported, each in a fresh
  interpreter (so no module depends on another having been imported before it).
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("core", "console", "hw_bridge")

# Never imported by anything under core/ (pure numpy/scipy: no GUI, no hardware, no I/O threads).
CORE_FORBIDDEN = {"hw_bridge", "console", "viser", "serial", "threading", "_thread", "socket",
                  "subprocess", "asyncio"}
# Process pools: the caller's business (a command line, the console), not core's library.
CORE_CLI_ONLY = {"multiprocessing", "concurrent"}
# Command-line modules: argparse, printing and exit codes are their job.
CLI_MODULES = {"hw_bridge.emulator", "hw_bridge.probe", "hw_bridge.tty_keeper"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules(*packages: str) -> dict[str, Path]:
    return {module_name(p): p for pkg in packages for p in sorted((REPO / pkg).rglob("*.py"))}


def is_cli(name: str) -> bool:
    return name.endswith(".__main__") or name in CLI_MODULES


def imported_names(name: str, tree: ast.AST, path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import anywhere in the file, relative ones resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            out.append((node.lineno, base))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names]
    return out


def module_level_imports(name: str, tree: ast.Module, path: Path, known: set[str]) -> set[str]:
    """Project modules executed when ``name`` is imported (module level; not TYPE_CHECKING)."""
    nodes: list[ast.AST] = []
    for node in tree.body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            continue
        nodes += list(ast.walk(node)) if isinstance(node, (ast.If, ast.Try, ast.With)) else [node]
    mini = ast.Module(body=[n for n in nodes if isinstance(n, (ast.Import, ast.ImportFrom))],
                      type_ignores=[])
    deps = set()
    for _, imported in imported_names(name, mini, path):
        parts = imported.split(".")
        for i in range(1, len(parts) + 1):  # importing a.b.c runs a, a.b and a.b.c
            dep = ".".join(parts[:i])
            if dep in known and dep != name:
                deps.add(dep)
    return deps


def test_the_module_list_is_real():
    core = modules("core")
    assert {"core.robots", "core.control.trials", "core.control.trials.__main__",
            "core.control.sim_loop", "core.planning.grasp"} <= set(core)
    assert len(modules(*PACKAGES)) > 80


def test_core_imports_nothing_from_hw_bridge_console_or_io():
    bad = []
    for name, path in modules("core").items():
        for line, imported in imported_names(name, ast.parse(path.read_text()), path):
            root = imported.split(".")[0]
            if root in CORE_FORBIDDEN or (root in CORE_CLI_ONLY and not is_cli(name)):
                bad.append(f"{path.relative_to(REPO)}:{line} imports {imported}")
    assert not bad, "\n".join(sorted(set(bad)))


# Still drawing in the headless room: GraspSession's scene layers move out (issue #27, item 3).
CONSOLE_CORE_PENDING = {"console.core.grasp_session"}


def test_the_console_core_imports_no_viser_and_no_view():
    bad = []
    for name, path in modules("console").items():
        if not name.startswith("console.core") or name in CONSOLE_CORE_PENDING:
            continue
        for line, imported in imported_names(name, ast.parse(path.read_text()), path):
            parts = imported.split(".")
            if parts[0] == "viser" or (parts[0] == "console" and len(parts) > 1
                                       and parts[1] != "core"):
                bad.append(f"{path.relative_to(REPO)}:{line} imports {imported}")
    assert not bad, "\n".join(sorted(set(bad)))
    assert "console.core.console_core" in modules("console")  # the rule has something to check


def test_the_rule_catches_a_forbidden_import(tmp_path):
    """The checker itself: a lazy hw_bridge import inside a function is found."""
    tree = ast.parse("def f():\n    from hw_bridge.loop import LoopRunner\n")
    names = [m for _, m in imported_names("core.x", tree, tmp_path / "x.py")]
    assert "hw_bridge.loop" in names
    rel = ast.parse("from . import sim\nfrom ..kinematics import planar\n")
    names = [m for _, m in imported_names("core.control.x", rel, tmp_path / "x.py")]
    assert {"core.control.sim", "core.kinematics.planar"} <= set(names)


def test_library_modules_have_no_command_line_code():
    bad = []
    for name, path in modules("core", "hw_bridge").items():
        if is_cli(name):
            continue
        tree = ast.parse(path.read_text())
        where = path.relative_to(REPO)
        for line, imported in imported_names(name, tree, path):
            if imported.split(".")[0] == "argparse":
                bad.append(f"{where}:{line} imports argparse")
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                f = node.func
                if isinstance(f, ast.Name) and f.id == "print":
                    bad.append(f"{where}:{node.lineno} prints")
                if (isinstance(f, ast.Attribute) and f.attr == "exit"
                        and isinstance(f.value, ast.Name) and f.value.id == "sys"):
                    bad.append(f"{where}:{node.lineno} calls sys.exit")
            if isinstance(node, ast.If) and "__main__" in ast.unparse(node.test):
                bad.append(f"{where}:{node.lineno} is a __main__ entry point")
    assert not bad, "\n".join(bad)


def test_cli_modules_exist_and_are_entry_points():
    found = modules("core", "hw_bridge")
    for name in CLI_MODULES | {"core.control.trials.__main__", "core.control.capture.__main__",
                               "core.planning.grasp.__main__",
                               "core.planning.reachability.__main__"}:
        assert name in found, name
        assert 'if __name__ == "__main__":' in found[name].read_text(), name


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_module_level_imports_form_no_cycle():
    mods = modules(*PACKAGES)
    known = set(mods)
    graph = {name: module_level_imports(name, ast.parse(path.read_text()), path, known)
             for name, path in mods.items()}
    assert graph["core.control.trials"] >= {"core.control.sim_loop", "core.robots"}
    assert not _cycles(graph), _cycles(graph)


_IMPORT_FIRST = """
import importlib, sys, traceback
name = sys.argv[1]
try:
    importlib.import_module(name)
except BaseException:
    traceback.print_exc()
    sys.exit(1)
"""


# One interpreter imports the third-party modules the project imports (never a project
# module), then forks a child per project module that imports it first: the same question as a
# fresh interpreter each (no project module can lean on another imported before it), without
# paying numpy/scipy.optimize/viser's import time 127 times (a fresh interpreter per module took
# ~45 s of the suite on an idle machine, 340 s on a loaded one). The project reaches these
# third-party modules only by ``from X import Y`` / ``import X``, which import X themselves,
# so having them loaded beforehand hides nothing.
_FORK_IMPORTS = """
import importlib, os, sys, traceback
for pre in sys.argv[1].split(","):
    try:
        importlib.import_module(pre)
    except ImportError:
        pass
assert not any(m.split(".")[0] in ("core", "console", "hw_bridge") for m in sys.modules)
names = sys.argv[2:]
width = max(2, os.cpu_count() or 2)
running = {}
failed = 0

def reap():
    global failed
    pid, status = os.wait()
    name, r = running.pop(pid)
    err = os.read(r, 1 << 20).decode(errors="replace").strip()
    os.close(r)
    if status != 0:
        failed += 1
        last = err.splitlines()[-1] if err else "?"
        print(f"{name}:\\n{last}", flush=True)

for name in names:
    if len(running) >= width:
        reap()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        try:
            importlib.import_module(name)
        except BaseException:
            os.write(w, traceback.format_exc().encode())
            os._exit(1)
        os._exit(0)
    os.close(w)
    running[pid] = (name, r)
while running:
    reap()
sys.exit(1 if failed else 0)
"""
_PRELOAD = ("numpy,scipy.optimize,scipy.linalg,viser,mcap.reader,mcap.writer,ruckig,serial,"
            "websockets.sync.server,websockets.sync.client")


def test_every_module_imports_first_in_a_fresh_interpreter():
    """Each module imported first in its own interpreter (so order cannot hide a circle):
    a forked child of one that holds no project module (a fresh interpreter each without
    ``os.fork``)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    names = sorted(modules(*PACKAGES))
    if hasattr(os, "fork"):
        proc = subprocess.run([sys.executable, "-c", _FORK_IMPORTS, _PRELOAD, *names], cwd=REPO,
                              env=env, capture_output=True, text=True, timeout=600,
                              check=False)
        assert proc.returncode == 0, proc.stdout + proc.stderr[-2000:]
        return
    failures: list[str] = []
    batch = max(2, os.cpu_count() or 2)
    for i in range(0, len(names), batch):
        procs = [(n, subprocess.Popen([sys.executable, "-c", _IMPORT_FIRST, n], cwd=REPO, env=env,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
                 for n in names[i:i + batch]]
        for n, proc in procs:
            _, err = proc.communicate(timeout=120)
            if proc.returncode != 0:
                failures.append(f"{n}:\n{err.strip().splitlines()[-1] if err.strip() else '?'}")
    assert not failures, "\n".join(failures)


def test_the_forked_check_detects_a_circle_and_a_failing_module(tmp_path):
    """The forked check fails on a real circle whichever module is first, and on a module that
    raises, naming it; a clean module passes."""
    pkg = tmp_path / "circ"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from circ.b import B\nA = 1\n")
    (pkg / "b.py").write_text("from circ.a import A\nB = 2\n")
    (pkg / "ok.py").write_text("import numpy\nX = numpy.zeros(2)\n")
    (pkg / "boom.py").write_text("raise RuntimeError('boom at import')\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}

    def run(*names: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-c", _FORK_IMPORTS, "numpy", *names],
                              cwd=tmp_path, capture_output=True, text=True, env=env,
                              timeout=120, check=False)

    assert run("circ.ok").returncode == 0
    proc = run("circ.a", "circ.ok", "circ.b", "circ.boom")  # each first in its own child
    assert proc.returncode == 1 and "circ.ok" not in proc.stdout
    for first in ("circ.a", "circ.b"):
        assert f"{first}:\nImportError" in proc.stdout, proc.stdout
    assert "circ.boom:\nRuntimeError: boom at import" in proc.stdout
