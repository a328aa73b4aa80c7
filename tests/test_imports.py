"""The import structure: no cycle, a numpy-only core, and what imports without pyyaml or the
compiled kernels (a source tree never installed, a firmware author's machine)."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import irring
from _parsed import parsed

PACKAGE = Path(irring.__file__).parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _targets(node: ast.Import | ast.ImportFrom, package: str, modules: set[str]) -> set[str]:
    """What one import statement names: irring modules, and other packages by top-level name."""
    if isinstance(node, ast.Import):
        return {a.name if a.name.split(".")[0] == "irring" else a.name.split(".")[0]
                for a in node.names}
    if node.level:
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if target.split(".")[0] != "irring":
        return {target.split(".")[0]}
    out = set()
    for alias in node.names:  # `from pkg import submodule` imports the submodule
        sub = f"{target}.{alias.name}"
        out.add(sub if sub in modules else target)
    return out


def _module_level(tree: ast.Module) -> list[ast.stmt]:
    """Statements run when the module is imported (try/if blocks too, not def or class)."""
    out, nodes = [], list(tree.body)
    while nodes:
        node = nodes.pop()
        if isinstance(node, (ast.Try, ast.If)):
            nodes += node.body + node.orelse + getattr(node, "handlers", []) + \
                getattr(node, "finalbody", [])
        elif isinstance(node, ast.ExceptHandler):
            nodes += node.body
        else:
            out.append(node)
    return out


def _package_of(path: Path) -> str:
    name = _module_name(path)
    return name if path.name == "__init__.py" else name.rsplit(".", 1)[0]


def _imports(path: Path, modules: set[str], *, nested: bool) -> set[str]:
    """What a file imports when it is imported, or (``nested``) anywhere, inside functions
    too: irring modules by full name, other packages by top-level name."""
    tree = parsed(path)
    out = set()
    for node in ast.walk(tree) if nested else _module_level(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= _targets(node, _package_of(path), modules)
    return out - {_module_name(path)}


def _paths() -> list[Path]:
    return [p for p in PACKAGE.rglob("*.py") if "_data" not in p.parts]


def _modules() -> set[str]:
    return ({_module_name(p) for p in _paths()}
            | {_module_name(p) for p in PACKAGE.rglob("*.pyx")})   # the compiled kernels


def _graph(*, nested: bool = False) -> dict[str, set[str]]:
    """Module → the irring modules it imports (``nested``: inside functions too)."""
    modules = _modules()
    return {_module_name(p): _imports(p, modules, nested=nested) & modules for p in _paths()}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` as a path that ends where it starts, or None."""
    state: dict[str, int] = {}   # 1: on the current path, 2: done

    def visit(node: str, trail: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                path = trail + [node]
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt, trail + [node])):
                return found
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node, [])):
            return found
    return None


def test_the_import_graph_has_no_cycle():
    graph = _graph()
    assert graph["irring.scenario"] >= {"irring.core", "irring.designs"}  # the parser sees edges
    assert _cycle({"a": {"b"}, "b": {"c", "d"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_cycle_hides_in_an_import_inside_a_function():
    """A cycle dodged by importing inside a function is still two modules that need each
    other; it breaks as soon as someone hoists the import."""
    graph = _graph(nested=True)
    assert "irring.simulation.sim" in graph["irring.pipeline"]  # the parser sees nested edges
    cycle = _cycle(graph)
    assert cycle is None, "import cycle through a function-level import: " + " -> ".join(cycle)


def test_errors_imports_nothing_of_irring_so_every_module_can_raise_its_errors():
    assert _graph(nested=True)["irring.errors"] == set()


def test_core_imports_numpy_and_nothing_else_of_irring():
    assert _graph()["irring.core"] == set()
    tree = parsed(PACKAGE / "core.py")
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import)
                for a in n.names}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree)
                 if isinstance(n, ast.ImportFrom) and n.module and not n.level}
    assert not any(isinstance(n, ast.ImportFrom) and n.level for n in ast.walk(tree))
    assert imported - set(sys.stdlib_module_names) == {"numpy"}


# Refuses the compiled kernels (and pyyaml unless allowed), as on a machine without them.
_BLOCKER = textwrap.dedent("""
    import sys

    class Block:
        def find_spec(self, name, path=None, target=None):
            if (BLOCK_YAML and name.split(".")[0] == "yaml") or name.rsplit(".", 1)[-1] in (
                    "_iterate", "_lines", "_traverse"):
                raise ImportError(f"blocked: {name}")
            return None

    sys.meta_path.insert(0, Block())
""")


def _run_blocked(code: str, *, block_yaml: bool = True) -> subprocess.CompletedProcess:
    script = f"BLOCK_YAML = {block_yaml}\n" + _BLOCKER + textwrap.dedent(code)
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)


def test_protocol_core_and_data_classes_import_without_pyyaml_or_kernels():
    done = _run_blocked("""
        import irring, irring.core, irring.hardware.protocol
        from irring import Points, Reason, Sweep, Truth
        from irring.hardware.protocol import Hello
        assert "yaml" not in sys.modules
        assert not [m for m in sys.modules if m.endswith(("_iterate", "_lines", "_traverse"))]
        print(sorted(m for m in sys.modules if m.startswith("irring")))
    """)
    assert done.returncode == 0, done.stderr
    assert "irring.scenario" not in done.stdout and "irring.core" in done.stdout


def test_without_kernels_the_estimator_fails_only_when_used_and_names_the_fix():
    done = _run_blocked("""
        import numpy as np
        from irring import load_scenario, pipeline          # imports fine without kernels
        from irring.estimation.calibration import Calibration
        from irring.estimation.estimate import estimate
        from irring.simulation.sim import SimRing
        sweep = SimRing(load_scenario("t_room")).sweep(0)   # the simulator needs none
        try:
            estimate(sweep, Calibration.nominal())
        except ImportError as exc:
            print(exc)
    """, block_yaml=False)
    assert done.returncode == 0, done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith("irring's compiled kernel estimation.") and "is not built" in last
    assert "pip install ." in last and "C compiler" in last


# What a function may import instead of its module: a package that is slow to load, needs a
# display or hardware library, or is optional (by dotted-name prefix), and an irring module
# only when it loads one of them. Anything else belongs at the top of the file.
DEFERRABLE = ("mujoco", "matplotlib", "PIL", "imageio", "dask", "distributed", "mcap",
              "mcap_ros2", "tqdm", "serial", "pyarrow", "importlib.metadata", "glfw",
              "hashlib", "setuptools")


def _external(node: ast.Import | ast.ImportFrom) -> set[str]:
    """The other packages one statement imports, by dotted name (`import a.b` → a.b)."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names if a.name.split(".")[0] != "irring"}
    if node.level or (node.module or "").split(".")[0] == "irring":
        return set()
    return {node.module} | {f"{node.module}.{a.name}" for a in node.names}


def _deferrable(names: set[str]) -> set[str]:
    return {n for n in names if any(n == d or n.startswith(d + ".") for d in DEFERRABLE)}


def _function_level_imports() -> list[tuple[str, int, bool, set[str]]]:
    """Every import inside a function or class of irring: (module, line, whether a
    ``# deferred:`` comment explains it, the slow or optional packages it alone loads)."""
    modules = _modules()
    paths = {_module_name(p): p for p in _paths()}
    trees = {m: parsed(p) for m, p in paths.items()}
    top = {m: [n for n in _module_level(t) if isinstance(n, (ast.Import, ast.ImportFrom))]
           for m, t in trees.items()}

    def loads(module: str, seen: set[str]) -> set[str]:   # other packages, transitively
        if module in seen or module not in top:
            return set()
        seen.add(module)
        out = set()
        for node in top[module]:
            out |= _external(node)
            for target in _targets(node, _package_of(paths[module]), modules) & modules:
                out |= loads(target, seen)
        return out

    found = []
    for module, tree in trees.items():
        lines = paths[module].read_text().splitlines()
        at_top = loads(module, set())
        module_level = set(map(id, top[module]))
        bodies = [getattr(n, f) for n in ast.walk(tree) for f in ("body", "orelse", "finalbody")
                  if isinstance(getattr(n, f, None), list)]
        for body in bodies:
            group: list[ast.stmt] = []
            for stmt in [*body, None]:   # runs of consecutive imports share one comment
                if isinstance(stmt, (ast.Import, ast.ImportFrom)) and id(stmt) not in module_level:
                    group.append(stmt)
                    continue
                if group:
                    first, last = group[0].lineno, group[-1].end_lineno
                    said = any("# deferred:" in line for line in lines[first - 2:last])
                    for node in group:
                        brought = _external(node)
                        for target in _targets(node, _package_of(paths[module]), modules):
                            brought |= loads(target, set()) if target in modules else set()
                        found.append((module, node.lineno, said,
                                      _deferrable(brought) - _deferrable(at_top)))
                group = []
    return found


def test_an_import_inside_a_function_defers_a_slow_or_optional_package_and_says_so():
    """Function-level imports stay the exception: each one loads something slow, optional
    or display-bound that its module does not already load, and a `# deferred:` comment
    says why. Anything else is hoisted, so the dodges cannot silently grow back."""
    found = _function_level_imports()
    by_place = {(m, min(d) if d else None) for m, _, _, d in found}
    assert ("irring.pipeline", "tqdm.auto") in by_place           # the parser sees them, and
    assert ("irring.studies.executor", "dask.distributed") in by_place   # what each loads
    needless = [f"{m}:{line}" for m, line, _, brings in found if not brings]
    unexplained = [f"{m}:{line}" for m, line, said, _ in found if not said]
    assert needless == [], "import these at the top of the file (nothing slow or optional)"
    assert unexplained == [], "say why with a '# deferred: …' comment on or above the import"


def test_no_module_imports_another_modules_private_name():
    """A name two modules share is public in its home (the numpy oracle and the estimator
    share constants and helpers); a leading underscore means "this module only"."""
    modules = _modules()
    private = []
    for path in _paths():
        for node in ast.walk(parsed(path)):
            if isinstance(node, ast.ImportFrom) and node.names:
                targets = _targets(node, _package_of(path), modules)
                if not any(t.split(".")[0] == "irring" for t in targets):
                    continue
                private += [f"{_module_name(path)}:{node.lineno} {a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.startswith("__")
                            and not any(t.endswith("." + a.name) for t in targets)]  # a kernel
    assert private == []
