"""The layout shows the architecture: the import graph of the project's own modules has no cycle,
and each layer imports only what its package docstring allows.

Every import counts, at module level or inside a function (a lazy import is still a dependency),
read from the source with `ast`, so the test needs nothing compiled.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("isaac", "recorder", "replay")

# third-party libraries that read or write files, streams or screens: never in the engine
IO_LIBRARIES = (
    "mcap",
    "rerun",
    "yaml",
    "google",
    "pyarrow",
    "tqdm",
    "matplotlib",
    "dask",
    "distributed",
    "csv",
    "json",
    "pickle",
    "subprocess",
    "sqlite3",
    "socket",
)
ENGINE_MAY_USE_FOR_COMPILE_AHEAD = {"isaac.engine.compile_ahead": {"pickle", "subprocess"}}


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Every module `name` imports: project modules by full name, others by top-level name."""
    is_package = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = name.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            if target == "__future__":
                continue
            # `from pkg import sub` depends on pkg.sub (and not on pkg's own names) when sub is
            # a module
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES]
            if subs and len(subs) == len(node.names):
                out.update(subs)
            else:
                out.add(target)
                out.update(subs)
    return out


GRAPH = {
    name: {m for m in _imports(name, path) if m in MODULES and m != name}
    for name, path in MODULES.items()
}
EXTERNAL = {
    name: {m.split(".")[0] for m in _imports(name, path) if m not in MODULES}
    for name, path in MODULES.items()
}


def _layer(name: str) -> str:
    parts = name.split(".")
    if name == "isaac.__main__":
        return "app"  # `python -m isaac` is the command line
    if parts[0] == "isaac" and len(parts) > 1 and parts[1] in ("engine", "scene", "app"):
        return parts[1]
    if parts[0] == "isaac":
        return "base"  # isaac, isaac.errors, isaac.tuning, isaac.__main__
    return parts[0]


# what each layer may import from the project (besides itself)
ALLOWED = {
    "base": {"base"},
    "scene": {"base"},
    "engine": {"base", "scene"},
    "recorder": {"base", "scene", "engine"},
    "replay": {"base", "scene", "engine", "recorder"},
    "app": {"base", "scene", "engine", "recorder", "replay"},
}


def _cycle() -> list[str] | None:
    """One import cycle among the project's modules, as a path a -> b -> ... -> a, or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(GRAPH[m]):
            if state.get(n) == 1:
                return stack[stack.index(n) :] + [n]
            if n not in state:
                found = visit(n)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(GRAPH):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


def test_the_walk_sees_every_layer_and_their_imports():
    # guards the test itself: a walk that found nothing would pass every check below
    layers = {_layer(m) for m in MODULES}
    assert layers == set(ALLOWED)
    assert "isaac.engine.world" in GRAPH["isaac.engine.simulation"]
    assert "recorder" in GRAPH["isaac.app.run"]  # a lazy import inside a function
    assert "numba" in EXTERNAL["isaac.engine.broad_phase"]


def test_no_import_cycle_between_modules():
    assert _cycle() is None, " -> ".join(_cycle())


def test_a_cycle_would_be_found():
    GRAPH["isaac.errors"].add("isaac.engine.step")
    try:
        assert _cycle() is not None
    finally:
        GRAPH["isaac.errors"].discard("isaac.engine.step")


@pytest.mark.parametrize("name", sorted(MODULES))
def test_each_module_imports_only_the_layers_below_it(name):
    layer = _layer(name)
    wrong = sorted(m for m in GRAPH[name] if _layer(m) not in ALLOWED[layer] | {layer})
    assert not wrong, f"{name} ({layer}) imports {wrong}"


@pytest.mark.parametrize("name", sorted(m for m in MODULES if _layer(m) == "engine"))
def test_engine_modules_import_no_io_library(name):
    allowed = ENGINE_MAY_USE_FOR_COMPILE_AHEAD.get(name, set())
    wrong = sorted((EXTERNAL[name] & set(IO_LIBRARIES)) - allowed)
    assert not wrong, f"{name} imports {wrong}"


@pytest.mark.parametrize("name", sorted(m for m in MODULES if _layer(m) == "scene"))
def test_scene_modules_compile_nothing(name):
    assert "numba" not in EXTERNAL[name]


def test_every_subpackage_says_what_it_holds_and_may_import():
    for package in ("isaac.scene", "isaac.engine", "isaac.app", "recorder", "replay"):
        doc = ast.get_docstring(ast.parse(MODULES[package].read_text())) or ""
        assert "import" in doc.lower(), f"{package}/__init__.py does not say what it may import"


def test_isaac_check_and_help_load_no_compiled_code():
    # checking a scene is the scene layer's work: numba (and its ~1 s, 330 MB import) stays out
    import subprocess
    import sys

    code = (
        "import sys; from isaac.app.cli import main; "
        "status = main(['check', 'scenes/pile.yaml']); "
        "print('numba' in sys.modules); sys.exit(status)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False"
