"""The repository's rooms (DEVELOPERS.md): core/ is pure, command lines live apart, no import circles.

* ``core/`` imports nothing from ``hw_bridge``/``console`` and no GUI, serial, socket, thread or
  subprocess module; a process pool (``multiprocessing``, ``concurrent.futures``) or ``ray`` only in a
  command line (``__main__.py``), never in a library module.
* Library modules under ``core/`` and ``hw_bridge/`` have no ``argparse``, ``print``,
  ``sys.exit`` or ``if __name__ == "__main__"``: those belong to the command-line modules.
* ``console/core/`` (the console's headless state and its one safety route) imports no
  ``viser`` and nothing of ``console`` outside ``console.core``, not even lazily or for type
  checking: the views import the core, never the other way round.
* No import circle: counting every import anywhere in a file (module level, inside a function,
  under ``TYPE_CHECKING``), the modules form no cycle; the module-level imports alone form none
  either; and every module of ``core``, ``console`` and ``hw_bridge`` imports when it is the first
  one imported, each in a fresh interpreter (so no module depends on another imported before it).
* No back arrow: with the layers of :data:`LAYERS` (lowest first), a module imports only from its
  own layer or a lower one, counting every import as above.
* viser's internals are touched in one room: no module under ``console/`` but ``console/web/``
  imports a private viser module (``viser._...``, ``viser.infra``); ``# type: ignore`` under
  ``console/`` does not grow.

The console is being reorganised (issue #27) so some of these hold only up to the allow-lists
below (KNOWN_...). Each list may only shrink: a test fails on an entry that is not listed *and* on
a listed entry that no longer occurs (delete it), so the lists record progress toward empty.
"""

from __future__ import annotations

import ast
import io
import os
import pickle
import subprocess
import sys
import tokenize
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("core", "console", "hw_bridge")

# Never imported by anything under core/ (pure numpy/scipy: no GUI, no hardware, no I/O threads).
CORE_FORBIDDEN = {"hw_bridge", "console", "viser", "serial", "threading", "_thread", "socket",
                  "subprocess", "asyncio"}
# Process pools and Ray: the caller's business (a command line, the console), not core's library.
CORE_CLI_ONLY = {"multiprocessing", "concurrent", "ray"}
# Command-line modules: argparse, printing and exit codes are their job.
CLI_MODULES = {"hw_bridge.emulator", "hw_bridge.probe", "hw_bridge.tty_keeper"}

# Layers, lowest first: a module imports only from its own layer or lower ones (every import,
# lazy and TYPE_CHECKING ones too). A module's layer is the longest entry that is its name or a
# package above it; "console" holds the composition (app.py, header.py, tabs.py, the serve-side
# modules) and, until they move into a sub-package, the console's other top-level modules.
LAYERS = ("core", "hw_bridge", "console.web", "console.core", "console.recording", "console.scene",
          "console.playback", "console.panels", "console")


# --- Allow-lists of what issue #27's reorganisation has not fixed yet. They only shrink: the tests
# fail on anything not listed and on a listed entry that no longer occurs. Goal: all empty.

#: Import circles (strongly connected modules, every import counted), each a sorted tuple.
KNOWN_CIRCLES: frozenset[tuple[str, ...]] = frozenset()

#: (importer, imported) pairs that point up the layers of LAYERS. Today: panels (and the flat
#: console/recording/recorder.py, already named like its layer) importing top-level console modules that
#: have not yet moved into a lower sub-package (console.core.state, console.scene.plan_view, ...) or that are
#: the composition itself (console.app, console.header).
KNOWN_BACK_ARROWS: frozenset[tuple[str, str]] = frozenset()

#: (console module, private viser module) imports outside console/web/.
KNOWN_PRIVATE_VISER: frozenset[tuple[str, str]] = frozenset()

#: ``# type: ignore`` comments per file under console/ (a file not listed has none).
KNOWN_TYPE_IGNORES: dict[str, int] = {
    'console/web/client_message_checks.py': 1,
    'console/web/scene_clicks.py': 2,
    'console/web/share_tunnel.py': 1,
    'console/web/shared_sends.py': 2,
}


_PARSE_ALL = """
import ast, pickle, sys
from pathlib import Path
trees = {p: ast.parse(Path(p).read_text()) for p in sys.argv[1:]}
sys.stdout.buffer.write(pickle.dumps(trees))
"""
_TREES: dict[str, ast.Module] = {}


def parse_file(path: Path) -> ast.Module:
    """``path``'s syntax tree; the files of PACKAGES are parsed once, in a child interpreter.

    CPython 3.11 before 3.11.8 (gh-106905) keeps the AST converter's recursion depth per
    interpreter: a compile in another thread (a console a test left running importing a module
    for the first time, as in a fresh clone without .pyc files) during this thread's
    ``ast.parse`` raised "SystemError: AST constructor recursion depth mismatch" (fresh40). The
    child has no other threads."""
    key = str(Path(path).resolve())
    if not _TREES:
        files = sorted(str(p.resolve()) for p in modules(*PACKAGES).values())
        out = subprocess.run([sys.executable, "-c", _PARSE_ALL, *files],
                             capture_output=True, check=True, timeout=300)
        _TREES.update(pickle.loads(out.stdout))
    if key not in _TREES:  # a test's own small file (tmp_path), perhaps rewritten: read now
        return ast.parse(Path(path).read_text())
    return _TREES[key]


def module_name(path: Path, root: Path = REPO) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules(*packages: str, root: Path = REPO) -> dict[str, Path]:
    return {module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}


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
        for line, imported in imported_names(name, parse_file(path), path):
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
        for line, imported in imported_names(name, parse_file(path), path):
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
        tree = parse_file(path)
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
    graph = {name: module_level_imports(name, parse_file(path), path, known)
             for name, path in mods.items()}
    assert graph["core.control.trials"] >= {"core.control.sim_loop", "core.robots"}
    assert not _cycles(graph), _cycles(graph)


def import_edges(name: str, tree: ast.AST, path: Path, known: set[str]) -> set[str]:
    """Project modules ``name`` imports anywhere in its file (module level, in a function, under
    ``TYPE_CHECKING``): the cycle and layer rules' edges.

    ``import a.b.c`` and ``from a.b import c`` name module ``a.b.c`` when that is a module, else
    ``a.b`` (``from a.b import Name``); a name that is no project module counts as its longest
    prefix that is one. A package above ``name`` (``console.panels.x`` -> ``console.panels``) is
    no edge: importing a submodule runs its package first anyway, so that edge would close a
    circle with every package that imports its own submodules.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    named: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            named += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            named += [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                      for a in node.names]
    edges: set[str] = set()
    for dep in named:
        while dep and dep not in known:
            dep = dep.rpartition(".")[0]
        if dep and dep != name and not name.startswith(dep + "."):
            edges.add(dep)
    return edges


def import_graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Every module's :func:`import_edges`."""
    known = set(mods)
    return {name: import_edges(name, parse_file(path), path, known)
            for name, path in mods.items()}


def layer_of(name: str) -> int | None:
    """Index in :data:`LAYERS` of the longest entry that is ``name`` or a package above it."""
    hits = [layer for layer in LAYERS if name == layer or name.startswith(layer + ".")]
    return LAYERS.index(max(hits, key=len)) if hits else None


def back_arrows(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """(importer, imported) edges of ``graph`` that point to a higher layer."""
    out: set[tuple[str, str]] = set()
    for name, deps in graph.items():
        own = layer_of(name)
        for dep in deps:
            up = layer_of(dep)
            if own is not None and up is not None and up > own:
                out.add((name, dep))
    return out


def _only_shrinks(found: set[tuple[str, ...]], known: frozenset[tuple[str, ...]],
                  listing: str) -> str:
    """Empty when ``found`` is exactly ``known``; otherwise what is new, what is gone and the
    list to paste (a listed entry that is gone is deleted: the list only shrinks)."""
    new, gone = sorted(found - known), sorted(known - found)
    if not new and not gone:
        return ""
    lines = [f"{listing}: new ones (fix them, do not list them): {new}" if new else "",
             f"{listing}: gone (delete them from the list): {gone}" if gone else "",
             f"{listing} today:"] + [f"    {e!r}," for e in sorted(found)]
    return "\n".join(line for line in lines if line)


def test_import_edges_count_every_import_and_resolve_submodules(tmp_path):
    """Lazy and TYPE_CHECKING imports are edges; ``from pkg import sub`` is the submodule,
    ``from pkg.mod import Name`` the module; a package above the importer is no edge."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    for f in ("__init__.py", "helpers.py", "other.py", "sub/__init__.py", "sub/y.py", "sub/z.py",
              "sub/w.py", "sub/lazy.py", "sub/typed.py"):
        (pkg / f).write_text("")
    (pkg / "sub" / "x.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "import numpy\n"
        "from pkg.sub import y, CONSTANT\n"        # y: a module; CONSTANT: pkg.sub, above x
        "from pkg import helpers\n"                # a module of pkg, not pkg itself
        "from pkg.other import Thing\n"            # a name: the module pkg.other
        "from . import z\n"                        # relative: pkg.sub.z
        "import pkg.sub.w\n"
        "if TYPE_CHECKING:\n"
        "    from pkg.sub.typed import T\n"
        "def f():\n"
        "    from pkg.sub import lazy\n"
        "    import pkg\n")                         # a package above x: no edge
    mods = modules("pkg", root=tmp_path)
    assert import_graph(mods)["pkg.sub.x"] == {
        "pkg.sub.y", "pkg.helpers", "pkg.other", "pkg.sub.z", "pkg.sub.w", "pkg.sub.typed",
        "pkg.sub.lazy"}
    # A package's __init__ importing its own submodule is an edge (down, not above it).
    (pkg / "__init__.py").write_text("from pkg.helpers import H\n")
    assert import_graph(modules("pkg", root=tmp_path))["pkg"] == {"pkg.helpers"}


def test_the_cycle_finder_catches_type_checking_and_lazy_circles(tmp_path):
    """A circle closed only by a TYPE_CHECKING import, and one closed only by an import inside a
    function, are both found (the module-level graph sees neither)."""
    for pkg, closing in (("typed", "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                   "    from typed.a import A\n"),
                         ("lazy", "def f():\n    from lazy.a import A\n    return A\n")):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
        (tmp_path / pkg / "a.py").write_text(f"from {pkg}.b import B\nA = 1\n")
        (tmp_path / pkg / "b.py").write_text(closing + "B = 2\n")
        (tmp_path / pkg / "c.py").write_text(f"from {pkg}.a import A\n")  # into it, not in it
    mods = modules("typed", "lazy", root=tmp_path)
    assert sorted(_cycles(import_graph(mods))) == [["lazy.a", "lazy.b"], ["typed.a", "typed.b"]]
    module_level = {name: module_level_imports(name, parse_file(path), path, set(mods))
                    for name, path in mods.items()}
    assert _cycles(module_level) == []


def test_no_import_circles_beyond_the_known_ones():
    """Counting every import (lazy and TYPE_CHECKING ones too): no circle but KNOWN_CIRCLES,
    and every known one still exists (fixed ones leave the list)."""
    graph = import_graph(modules(*PACKAGES))
    assert "core.robots" in graph["core.control.trials"]
    found = {tuple(c) for c in _cycles(graph)}
    assert not [c for c in KNOWN_CIRCLES if any(not m.startswith("console.") for m in c)]
    problem = _only_shrinks(found, KNOWN_CIRCLES, "KNOWN_CIRCLES")
    assert not problem, problem


def test_layers_are_the_longest_matching_prefix():
    cases = {"core.robots": "core", "hw_bridge.loop": "hw_bridge", "console.web.guard":
             "console.web", "console.recording.recorder": "console.recording", "console.panels.common.jog":
             "console.panels", "console.panels.soft_arm.jog": "console.panels",
             "console.scene.arm_view": "console.scene", "console.app": "console",
             "console": "console"}
    assert {name: LAYERS[layer_of(name)] for name in cases} == cases
    assert layer_of("serve") is None and layer_of("cores") is None
    assert layer_of("console_extra") is None


def test_the_layer_rule_catches_a_back_arrow(tmp_path):
    """A lazy import from a lower layer into a higher one is a back arrow; imports down the
    layers and within one are not."""
    files = {
        "core/__init__.py": "",
        "core/geometry.py": "def f():\n    from hw_bridge.link import Link\n",  # up: back
        "hw_bridge/__init__.py": "",
        "hw_bridge/link.py": "from core.geometry import f\n",                    # down: fine
        "console/__init__.py": "",
        "console/app.py": "from console.panels.common.jog import Jog\n",                # down: fine
        "console/scene/__init__.py": "",
        "console/scene/arm.py": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                 "    from console.panels.common.jog import Jog\n"),   # up: back
        "console/panels/__init__.py": "",
        "console/panels/common/jog.py": ("from console.scene.arm import draw\n"        # down: fine
                                  "from console.panels import helpers\n"),      # same layer
        "console/panels/helpers.py": "import console.app\n",                     # up: back
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph = import_graph(modules("core", "hw_bridge", "console", root=tmp_path))
    assert back_arrows(graph) == {("core.geometry", "hw_bridge.link"),
                                  ("console.scene.arm", "console.panels.common.jog"),
                                  ("console.panels.helpers", "console.app")}


def test_no_back_arrows_beyond_the_known_ones():
    """No module imports from a higher layer but KNOWN_BACK_ARROWS, each of which still
    exists."""
    found = back_arrows(import_graph(modules(*PACKAGES)))
    problem = _only_shrinks(found, KNOWN_BACK_ARROWS, "KNOWN_BACK_ARROWS")
    assert not problem, problem


def private_viser(tree: ast.AST) -> set[str]:
    """Private viser modules (``viser._x``, ``viser.infra``) a file imports or reaches as an
    attribute of an imported ``viser``, anywhere in it; dunders (``viser.__version__``) are
    public."""
    def private(dotted: str) -> str:
        """``viser.<private>`` of a dotted name in viser, else ""."""
        parts = dotted.split(".")
        if parts[0] != "viser" or len(parts) < 2:
            return ""
        second = parts[1]
        dunder = second.startswith("__") and second.endswith("__")
        return f"viser.{second}" if second == "infra" or (second[:1] == "_" and not dunder) else ""

    named: list[str] = []
    aliases: set[str] = set()  # names bound to the viser package itself
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                named.append(a.name)
                if a.name == "viser" or (a.asname is None and a.name.startswith("viser.")):
                    aliases.add(a.asname or "viser")
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            named += [node.module] + [f"{node.module}.{a.name}" for a in node.names]
    named += [f"viser.{node.attr}" for node in ast.walk(tree)
              if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
              and node.value.id in aliases]
    return {private(n) for n in named} - {""}


def test_the_private_viser_rule_catches_each_way_in():
    src = ("import viser\nimport viser as v\nimport viser.transforms as vtf\n"
           "from viser import GuiApi, __version__\nfrom viser.infra import _infra\n"
           "def f():\n    from viser import _messages\n    import viser._gui_api\n"
           "    return viser._scene_api, v._client_autobuild, vtf.SO3\n")
    assert private_viser(ast.parse(src)) == {"viser.infra", "viser._messages", "viser._gui_api",
                                             "viser._scene_api", "viser._client_autobuild"}
    assert private_viser(ast.parse("import viser\nx = viser.ViserServer\n")) == set()
    assert private_viser(ast.parse("from viser._messages import GuiSliderMark\n")) == {
        "viser._messages"}


def test_private_viser_only_in_console_web_beyond_the_known_ones():
    """viser's internals in one room (console/web/): elsewhere under console/ only the
    KNOWN_PRIVATE_VISER imports, each of which still exists."""
    found = {(name, inner) for name, path in modules("console").items()
             if not (name == "console.web" or name.startswith("console.web."))
             for inner in private_viser(parse_file(path))}
    problem = _only_shrinks(found, KNOWN_PRIVATE_VISER, "KNOWN_PRIVATE_VISER")
    assert not problem, problem


def type_ignores(text: str) -> int:
    """``# type: ignore`` comments in Python source (comments only, not strings)."""
    return sum(1 for tok in tokenize.generate_tokens(io.StringIO(text).readline)
               if tok.type == tokenize.COMMENT and "type: ignore" in tok.string.replace(
                   "type:ignore", "type: ignore"))


def test_type_ignores_are_counted_in_comments_only():
    src = ('x = f()  # type: ignore[arg-type]\ny = "# type: ignore"\n'
           'z = g()  #type:ignore\n# a note, then  # type: ignore[misc]\n')
    assert type_ignores(src) == 3


def test_type_ignores_under_console_only_shrink():
    """No file under console/ has more ``# type: ignore`` than KNOWN_TYPE_IGNORES says, and none
    fewer (lower its count: the list only shrinks)."""
    counts = {str(path.relative_to(REPO)): type_ignores(path.read_text())
              for path in sorted((REPO / "console").rglob("*.py"))}
    found = {rel: n for rel, n in counts.items() if n}
    more = {rel: n for rel, n in found.items() if n > KNOWN_TYPE_IGNORES.get(rel, 0)}
    fewer = {rel: n for rel, n in KNOWN_TYPE_IGNORES.items() if found.get(rel, 0) < n}
    assert not more and not fewer, (
        f"more '# type: ignore' than KNOWN_TYPE_IGNORES allows (type it instead): {more}\n"
        f"fewer than listed (lower the list): {fewer}\nKNOWN_TYPE_IGNORES today:\n"
        + "\n".join(f"    {rel!r}: {n}," for rel, n in sorted(found.items())))


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
