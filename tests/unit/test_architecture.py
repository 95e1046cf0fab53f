"""The house rules (ARCHITECTURE.md), checked on the source: layers whose imports point down, no
import cycle, modules and functions of a readable size, tests that share code only through
tests/helpers."""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from pathlib import Path, PurePosixPath

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: each repository folder's import name (pyproject.toml's package-dir) and layer: a module may
#: import its own layer and the ones below
PACKAGES = {"gngdt": "gngdt", "gngdt_core": "gngdt.core", "schemas": "gngdt.schemas",
            "gngdt_io": "gngdt.io", "gngdt_eval": "gngdt.eval", "services": "gngdt.services",
            "benchmarks": "benchmarks", "docs": "docs"}
LAYERS = {"gngdt": 0, "gngdt.core": 0, "gngdt.schemas": 1, "gngdt.io": 2, "gngdt.eval": 3,
          "gngdt.services": 4, "benchmarks": 5, "docs": 5}
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80
#: decorators of numba kernels, which are exempt from the function size (one loop each)
KERNEL_DECORATORS = ("njit", "jit", "inlined")
#: modules and subpackages at gngdt_core's top, at most: the rest lives in subpackages by concern
MAX_CORE_TOP = 12


def _module_name(path: Path) -> str:
    folder, *parts = path.relative_to(ROOT).with_suffix("").parts
    if parts and parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([PACKAGES[folder], *parts])


def _modules() -> dict[str, Path]:
    return {_module_name(path): path for top in PACKAGES
            for path in ((ROOT / top).rglob("*.py") if top != "gngdt"
                         else (ROOT / top).glob("*.py"))}


MODULES = _modules()


def _imported(module: str, node: ast.Import | ast.ImportFrom, is_package: bool) -> list[str]:
    """Names of ours that one import statement of ``module`` imports (modules, or the package
    a name is taken from)."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        base = node.module or ""
        if node.level:
            package = module.split(".") if is_package else module.split(".")[:-1]
            package = package[:len(package) - node.level + 1]
            base = ".".join([*package, *([base] if base else [])])
        names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base
                 for alias in node.names]
    return [resolved for name in names if (resolved := _resolve(name)) and resolved != module]


def _resolve(name: str) -> str | None:
    parts = name.split(".")
    while parts:
        if ".".join(parts) in MODULES:
            return ".".join(parts)
        parts.pop()
    return None


def import_graph() -> dict[str, set[str]]:
    """Module -> the modules of ours it imports (anywhere in it: top level, functions,
    TYPE_CHECKING blocks)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom):
                graph[module].update(_imported(module, node, path.name == "__init__.py"))
    return graph


def layer(module: str) -> int:
    return max(level for package, level in LAYERS.items()
               if module == package or module.startswith(f"{package}."))


def test_every_import_points_down_or_across() -> None:
    upward = sorted(f"{module} -> {imported}" for module, imports in import_graph().items()
                    for imported in imports
                    if layer(imported) > layer(module))
    assert not upward, "imports of a higher layer:\n" + "\n".join(upward)


def test_no_import_tests_outside_tests() -> None:
    offenders = sorted(module for module, path in MODULES.items()
                       if any(isinstance(node, ast.ImportFrom | ast.Import) and any(
                           name.split(".")[0] in ("tests", "conftest") or name.startswith("test_")
                           for name in ([node.module or ""] if isinstance(node, ast.ImportFrom)
                                        else [alias.name for alias in node.names]))
                              for node in ast.walk(ast.parse(path.read_text()))))
    assert not offenders, f"modules importing test helpers: {offenders}"


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Import cycles: the strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for node in sorted(graph):
            if node not in index:
                visit(node)
    finally:
        sys.setrecursionlimit(limit)
    return cycles


def test_no_import_cycle() -> None:
    assert strongly_connected(import_graph()) == []


def test_the_cycle_finder_finds_a_cycle() -> None:
    """The check above can fail: a two-module loop and a three-module ring are found."""
    graph = {"a": {"b"}, "b": {"a", "c"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": set()}
    assert sorted(strongly_connected(graph)) == [["a", "b"], ["c", "d", "e"]]


def _test_modules_imported(tree: ast.Module) -> list[str]:
    """What ``tree`` imports that is a test module: a ``test_*`` part of a module's dotted name
    (``import test_x``, ``from tests.unit.test_x import y``, ``from .test_x import y``) or a
    ``test_*`` name taken from a package (``from tests.unit import test_x``)."""
    def is_test(name: str) -> bool:
        return any(part.startswith("test_") for part in name.split("."))

    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.extend(alias.name for alias in node.names if is_test(alias.name))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            found.extend([base] if is_test(base) else
                         [f"{base}.{alias.name}".strip(".") for alias in node.names
                          if is_test(alias.name)])
    return found


def layout_offences(sources: dict[str, str]) -> list[str]:
    """Where test code (``sources``: path under the repository -> text, of tests/**.py) breaks
    the tests' layout: a module that is neither a test (``test_*.py``), a conftest.py nor in
    tests/helpers/ (shared code lives there), and any import of a test module (what two test
    modules need is a helper, never one's code imported by the other)."""
    offences = []
    for name, source in sorted(sources.items()):
        path = PurePosixPath(name)
        if not (path.name.startswith("test_") or path.name == "conftest.py"
                or path.parts[1] == "helpers"):
            offences.append(f"{name}: neither a test, a conftest.py nor in tests/helpers/")
        offences.extend(f"{name}: imports the test module {imported}"
                        for imported in _test_modules_imported(ast.parse(source, name)))
    return offences


def test_tests_share_code_only_through_helpers() -> None:
    sources = {path.relative_to(ROOT).as_posix(): path.read_text()
               for path in (ROOT / "tests").rglob("*.py")}
    offences = layout_offences(sources)
    assert not offences, "move what test modules share to tests/helpers:\n" + "\n".join(offences)


def test_the_layout_check_finds_test_modules_imported_and_loose_helpers() -> None:
    """The check above can fail: every way of importing a test module, and a helper module
    outside tests/helpers, are found; helpers, conftest.py and benchmarks' helpers pass."""
    sources = {
        "tests/unit/test_a.py": "from test_b import helper\n",
        "tests/unit/test_b.py": "def helper() -> None: ...\n",
        "tests/process/test_c.py": "import test_b\nfrom tests.unit.test_b import helper\n",
        "tests/process/test_d.py": "def f() -> None:\n    from tests.unit import test_b\n",
        "tests/process/test_e.py": "from .test_b import helper\n",
        "tests/loose.py": "def helper() -> None: ...\n",
        "tests/helpers/__init__.py": "",
        "tests/helpers/shared.py": "from gngdt.core import GNGDT\n",
        "tests/unit/test_f.py": ("from helpers.shared import GNGDT\nimport conftest\n"
                                 "from hostile_recordings import zstd_bomb\n"),
        "tests/unit/conftest.py": "from helpers.shared import GNGDT\n",
    }
    assert layout_offences(sources) == [
        "tests/loose.py: neither a test, a conftest.py nor in tests/helpers/",
        "tests/process/test_c.py: imports the test module test_b",
        "tests/process/test_c.py: imports the test module tests.unit.test_b",
        "tests/process/test_d.py: imports the test module tests.unit.test_b",
        "tests/process/test_e.py: imports the test module test_b",
        "tests/unit/test_a.py: imports the test module test_b",
    ]


def _python_files() -> list[Path]:
    return sorted([*MODULES.values(), *(ROOT / "tests").rglob("*.py")])


@pytest.mark.parametrize("path", _python_files(), ids=lambda path: str(path.relative_to(ROOT)))
def test_module_and_function_sizes(path: Path) -> None:
    source = path.read_text()
    lines = source.count("\n")
    assert lines <= MAX_MODULE_LINES, f"{lines} lines: split it by responsibility"
    long = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            decorators = " ".join(ast.unparse(decorator) for decorator in node.decorator_list)
            size = node.end_lineno - node.lineno + 1
            if size > MAX_FUNCTION_LINES and not any(name in decorators
                                                     for name in KERNEL_DECORATORS):
                long.append(f"{node.name} ({size} lines)")
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_gngdt_core_keeps_its_top_small() -> None:
    """gngdt_core is split by concern: at most `MAX_CORE_TOP` modules and subpackages at its
    top, each subpackage saying in its docstring what it owns."""
    top = sorted(path.name for path in (ROOT / "gngdt_core").iterdir()
                 if (path.suffix == ".py" and path.name != "__init__.py")
                 or (path / "__init__.py").exists())
    assert len(top) <= MAX_CORE_TOP, f"{len(top)} modules at gngdt_core's top: {top}"
    for package in (ROOT / "gngdt_core").glob("*/__init__.py"):
        assert ast.get_docstring(ast.parse(package.read_text())), f"{package}: say what it owns"


#: the clusterings' and topologies' names, spelled only in their registry
#: (`gngdt.core.clustering`): everything else refers to its constants
REGISTERED_NAMES = {"pos", "col", "nor", "cvx", "col+nor"}
CLUSTERING_REGISTRY = "gngdt.core.clustering"
#: the wire's keys are spelled only in `gngdt.schemas.wire` (by the product: benchmarks and tests
#: are its outside clients)
WIRE = "gngdt.schemas.wire"


def _code_strings(tree: ast.AST) -> list[tuple[int, str]]:
    """The strings of a module's code (docstrings left out), with their lines; an f-string as
    one string, ``{}`` for each of its values."""
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef
                                | ast.AsyncFunctionDef)
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    parts = {id(value) for node in ast.walk(tree) if isinstance(node, ast.JoinedStr)
             for value in node.values}
    strings = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            strings.append((node.lineno, "".join(
                value.value if isinstance(value, ast.Constant) else "{}"
                for value in node.values)))
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and id(node) not in docstrings and id(node) not in parts):
            strings.append((node.lineno, node.value))
    return strings


def spelled_contract_names(module: str, source: str) -> list[str]:
    """Where ``module`` spells a clustering or topology name (`REGISTERED_NAMES`), or a zenoh
    key of gngdt's (``gngdt/...``), outside its registry."""
    found = []
    for line, text in _code_strings(ast.parse(source)):
        if text in REGISTERED_NAMES and module != CLUSTERING_REGISTRY:
            found.append(f"{module}:{line}: {text!r} (use gngdt.core.clustering's constants)")
        if text.startswith("gngdt/") and module != WIRE:
            found.append(f"{module}:{line}: {text!r} (use gngdt.schemas.wire's keys)")
    return found


def test_registry_names_and_wire_keys_are_spelled_once() -> None:
    spelled = [found for module, path in MODULES.items() if module.startswith("gngdt.")
               for found in spelled_contract_names(module, path.read_text())]
    assert not spelled, "\n".join(spelled)


def test_the_spelling_check_finds_literals_and_keys() -> None:
    """The check above can fail: a literal clustering name and a hand-spelled liveliness key
    are found; docstrings and the registries themselves are not."""
    source = ('"""Clusters by "pos"."""\nx = edges("pos")\ny = "col+nor"\n'
              'key = f"gngdt/{cam}/learner/alive"\n')
    assert len(spelled_contract_names("gngdt.io.example", source)) == 3, source
    assert spelled_contract_names(CLUSTERING_REGISTRY, 'x = "pos"\n') == []
    assert spelled_contract_names(WIRE, 'x = "gngdt/logger/alive"\n') == []
