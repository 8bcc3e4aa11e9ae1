"""The code runs on Python 3.10: no 3.11+-only stdlib without a fallback, and it compiles there.

``pyproject.toml`` declares ``requires-python = ">=3.10"`` (Ubuntu 22.04 ships 3.10), so every
module of core/, console/, hw_bridge/ and serve.py is scanned with ``ast`` for stdlib modules and
names added in 3.11 or later that are used outside a ``try: ... except ImportError`` fallback, an
``if sys.version_info >= (3, 11)`` guard or ``if TYPE_CHECKING``. If a python3.10 interpreter is on
the machine, the whole tree is also byte-compiled with it (catches 3.11+ syntax such as
``except*``).
"""

from __future__ import annotations

import ast
import functools
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ["core", "console", "hw_bridge", "serve.py"]

#: stdlib modules that do not exist on 3.10.
NEW_MODULES = {"tomllib": "3.11", "wsgiref.types": "3.11"}
#: names added to existing stdlib modules in 3.11+ (module -> {name: version}).
NEW_NAMES = {
    "typing": {n: "3.11" for n in ("Self", "LiteralString", "Never", "assert_never",
                                   "assert_type", "reveal_type", "Required", "NotRequired",
                                   "TypeVarTuple", "Unpack", "dataclass_transform",
                                   "clear_overloads", "get_overloads")}
    | {"override": "3.12", "TypeAliasType": "3.12", "get_protocol_members": "3.13",
       "is_protocol": "3.13", "ReadOnly": "3.13", "TypeIs": "3.13", "NoDefault": "3.13"},
    "enum": {"StrEnum": "3.11", "ReprEnum": "3.11", "EnumCheck": "3.11", "FlagBoundary": "3.11",
             "verify": "3.11", "member": "3.11", "nonmember": "3.11", "global_enum": "3.11",
             "show_flag_values": "3.11"},
    "datetime": {"UTC": "3.11"},
    "contextlib": {"chdir": "3.11"},
    "asyncio": {"TaskGroup": "3.11", "timeout": "3.11", "timeout_at": "3.11", "Runner": "3.11",
                "Barrier": "3.11", "BrokenBarrierError": "3.11"},
    "hashlib": {"file_digest": "3.11"},
    "operator": {"call": "3.11"},
    "itertools": {"batched": "3.12"},
    "math": {"cbrt": "3.11", "exp2": "3.11", "sumprod": "3.12", "fma": "3.13"},
    "inspect": {"markcoroutinefunction": "3.12", "getmembers_static": "3.11"},
    "logging": {"getLevelNamesMapping": "3.11"},
    "string": {},
}
#: builtins added in 3.11+.
NEW_BUILTINS = {"ExceptionGroup": "3.11", "BaseExceptionGroup": "3.11"}


def _python_files() -> list[Path]:
    files: list[Path] = []
    for name in SOURCES:
        p = ROOT / name
        files.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p])
    return files


def _guarded(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    """Inside try/except ImportError, ``if sys.version_info >= ...`` or ``if TYPE_CHECKING``."""
    child, node = node, parents.get(node)
    while node is not None:
        if isinstance(node, ast.Try) and child in node.body:
            for h in node.handlers:
                names = ([h.type] if not isinstance(h.type, ast.Tuple) else h.type.elts) \
                    if h.type is not None else []
                if h.type is None or any(isinstance(t, ast.Name) and t.id in (
                        "ImportError", "ModuleNotFoundError", "AttributeError", "Exception")
                        for t in names):
                    return True
        if isinstance(node, ast.If) and child in node.body:
            test = ast.unparse(node.test)
            if "version_info" in test or "TYPE_CHECKING" in test:
                return True
        child, node = node, parents.get(node)
    return False


def _offences(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    parents = {c: p for p in ast.walk(tree) for c in ast.iter_child_nodes(p)}
    aliases: dict[str, str] = {}  # local name -> stdlib module it stands for
    found: list[str] = []

    def report(node: ast.AST, what: str, version: str) -> None:
        if not _guarded(node, parents):
            found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {what} needs Python {version}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name in NEW_MODULES:
                    report(node, f"import {a.name}", NEW_MODULES[a.name])
                if a.name in NEW_NAMES:
                    aliases[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module in NEW_MODULES:
                report(node, f"from {node.module} import ...", NEW_MODULES[node.module])
            for a in node.names:
                full = f"{node.module}.{a.name}"
                if full in NEW_MODULES:
                    report(node, f"from {node.module} import {a.name}", NEW_MODULES[full])
                version = NEW_NAMES.get(node.module, {}).get(a.name)
                if version:
                    report(node, f"from {node.module} import {a.name}", version)
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases):
            version = NEW_NAMES[aliases[node.value.id]].get(node.attr)
            if version:
                report(node, f"{aliases[node.value.id]}.{node.attr}", version)
        elif isinstance(node, ast.Name) and node.id in NEW_BUILTINS:
            report(node, node.id, NEW_BUILTINS[node.id])
    return found


def test_the_scan_finds_what_it_looks_for(tmp_path, monkeypatch):
    """The checker itself: unguarded uses are reported, guarded ones are not."""
    bad = tmp_path / "bad.py"
    bad.write_text("import tomllib\nfrom typing import Self\nimport enum\nX = enum.StrEnum\n"
                   "try:\n    raise ExceptionGroup('x', [])\nexcept ValueError:\n    pass\n")
    good = tmp_path / "good.py"
    good.write_text("import sys\ntry:\n    import tomllib\nexcept ModuleNotFoundError:\n"
                    "    import tomli as tomllib\nif sys.version_info >= (3, 11):\n"
                    "    from typing import Self\nfrom typing import TYPE_CHECKING\n"
                    "if TYPE_CHECKING:\n    from typing import Never\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert [line.split(": ", 1)[1] for line in _offences(bad)] == [
        "import tomllib needs Python 3.11", "from typing import Self needs Python 3.11",
        "enum.StrEnum needs Python 3.11", "ExceptionGroup needs Python 3.11"]
    assert _offences(good) == []


def test_no_311_only_stdlib_without_a_fallback():
    files = _python_files()
    assert len(files) > 50 and ROOT / "core" / "robots.py" in files
    offences = [o for f in files for o in _offences(f)]
    assert offences == [], "\n".join(offences)


@functools.lru_cache(maxsize=None)
def _python310() -> str | None:
    """A python3.10 that actually runs (a pyenv shim without that version installed does not)."""
    pyenv = Path.home() / ".pyenv" / "versions"
    cands = [str(p) for p in sorted(pyenv.glob("3.10*/bin/python3.10"))] if pyenv.is_dir() else []
    cands += [c for c in [shutil.which("python3.10")] if c]
    for cand in cands:
        try:
            ok = subprocess.run([cand, "-c", "import sys; assert sys.version_info[:2] == (3, 10)"],
                                capture_output=True, timeout=60).returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            ok = False
        if ok:
            return cand
    return None


@pytest.mark.skipif(_python310() is None, reason="no python3.10 on this machine")
def test_everything_compiles_under_python310(tmp_path):
    """Byte-compile every module with python3.10 (into a scratch dir: the tree stays clean)."""
    script = ("import py_compile, sys, pathlib\n"
              "bad = []\n"
              "for f in sys.argv[2:]:\n"
              "    try:\n"
              "        py_compile.compile(f, cfile=str(pathlib.Path(sys.argv[1]) / 'x.pyc'),"
              " doraise=True)\n"
              "    except py_compile.PyCompileError as e:\n"
              "        bad.append(str(e))\n"
              "print('\\n'.join(bad)); sys.exit(1 if bad else 0)\n")
    files = [str(f) for f in _python_files()]
    run = subprocess.run([_python310(), "-c", script, str(tmp_path), *files],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
