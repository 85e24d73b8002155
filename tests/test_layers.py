"""The shape of the code (docs/design.md): imports point down the layers, never up or in a
circle; step kinds are named in one place; settings are written once. Read from the import
graph (grimp, import-linter's graph library) and the source, not by running anything."""

from __future__ import annotations

import ast
import functools
import tomllib
from pathlib import Path

import grimp
import pytest

import motorlab
from motorlab.kinds import KINDS

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

PACKAGE = Path(motorlab.__file__).parent


@functools.cache
def contract_layers() -> list[list[str]]:
    """The layers of the import contract in pyproject.toml, top first, each a list of module names."""
    pyproject = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
    (contract,) = pyproject["tool"]["importlinter"]["contracts"]
    return [[name.strip() for name in entry.replace("|", ":").split(":")] for entry in contract["layers"]]


def in_contract(module: str, layers: list[list[str]]) -> int | None:
    """The index of the contract's layer that holds `module` (None: no layer names it)."""
    return next((i for i, names in enumerate(layers)
                 if any(module == name or module.startswith(name + ".") for name in names)), None)


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("motorlab", cache_dir=None)


_GRAPH: list[grimp.ImportGraph] = []


@functools.cache
def layer(module: str) -> int:
    """The module's layer, from the one contract (pyproject.toml): a higher number is a higher layer.
    A module no layer names is the root package's __init__ (the façade of the API's names): it sits at the
    highest layer of what it imports (an empty one at the bottom), so whatever imports it must sit there
    too."""
    layers = contract_layers()
    found = in_contract(module, layers)
    if found is not None:
        return len(layers) - 1 - found
    if not _GRAPH:
        _GRAPH.append(grimp.build_graph("motorlab", cache_dir=None))
    graph = _GRAPH[0]
    imported = graph.find_modules_directly_imported_by(module) if module in graph.modules else set()
    return max((layer(m) for m in imported), default=0)


def test_every_module_is_in_the_graph(graph):
    """Every .py file is a module grimp sees (a folder without __init__.py would hide its modules
    from the checks below, and from setuptools' package list)."""
    files = {".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
             for p in PACKAGE.rglob("*.py")}
    assert files == set(graph.modules)


def test_imports_point_down_the_layers(graph):
    """lint-imports checks the contract's modules; this checks every module's direct imports by the same
    contract, the package __init__s it does not name (façades, re-exports) included."""
    upward = [f"{a} ({layer(a)}) imports {b} ({layer(b)})" for a in graph.modules
              for b in graph.find_modules_directly_imported_by(a) if layer(b) > layer(a)]
    assert not upward, "\n".join(upward)


def test_no_module_imports_another_in_a_circle(graph):
    cycles = []
    for a in graph.modules:
        for b in graph.find_modules_directly_imported_by(a):
            chain = graph.find_shortest_chain(importer=b, imported=a)
            if chain is not None:
                cycles.append(" -> ".join((a, *chain)))
    assert not cycles, "\n".join(sorted(cycles))


def test_the_contract_names_every_module_but_package_inits(graph):
    """Every module but a package's __init__ is in a layer of the contract: a new module cannot slip
    past lint-imports. The contract names packages, so the only unnamed __init__ is the root's, the
    façade at the top beside the API whose names it gives."""
    layers = contract_layers()
    unnamed = sorted(m for m in graph.modules if in_contract(m, layers) is None
                     and not (PACKAGE.parent / m.replace(".", "/") / "__init__.py").is_file())
    assert not unnamed, f"modules no layer of the import contract (pyproject.toml) names: {unnamed}"
    top = layer("motorlab.api")
    assert layer("motorlab") == top
    assert [m for m in graph.modules if in_contract(m, layers) is None] == ["motorlab"]
    assert layer("motorlab.kinds.train") > layer("motorlab.stepkind") > layer("motorlab.rl.train") > layer("motorlab.runs")


def test_the_layer_check_catches_an_upward_import(tmp_path):
    """The two checks above are able to fail: an upward import and a cycle in a small package."""
    pkg = tmp_path / "toy"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "low.py").write_text("import toy.high\n")
    (pkg / "high.py").write_text("import toy.low\n")
    import sys

    sys.path.insert(0, str(tmp_path))
    try:
        toy = grimp.build_graph("toy", cache_dir=None)
    finally:
        sys.path.remove(str(tmp_path))
    assert toy.find_shortest_chain(importer="toy.low", imported="toy.high") == ("toy.low", "toy.high")
    assert toy.find_shortest_chain(importer="toy.high", imported="toy.low") is not None


def _strings(path: Path) -> set[str]:
    """String literals a module's code uses as values: not docstrings, not data keys (dict
    display keys, subscripts such as metadata["vaf"]) and not the Python names in __all__."""
    tree = ast.parse(path.read_text())
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body \
                and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant):
            skip.add(id(node.body[0].value))
        elif isinstance(node, ast.Dict):
            skip.update(id(k) for k in node.keys if k is not None)
        elif isinstance(node, ast.Subscript):
            skip.add(id(node.slice))
        elif isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            skip.update(id(n) for n in ast.walk(node.value))
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip}


def test_each_kind_is_named_in_one_library_file():
    """A kind's name, as a value the code compares, looks up or passes, stands only in its own
    file: the CLI, recipes, studies and sweeps reach kinds through the registry."""
    named: dict[str, list[str]] = {name: [] for name in KINDS}
    for path in PACKAGE.rglob("*.py"):
        strings = _strings(path)
        for name in KINDS:
            if name in strings:
                named[name].append(str(path.relative_to(PACKAGE)))
    assert all(len(files) == 1 for files in named.values()), named
    for name, kind in KINDS.items():
        assert named[name] == [str(Path(type(kind).__module__.replace(".", "/")).relative_to("motorlab"))
                               + ".py"]


def test_kind_settings_are_the_one_source_of_defaults():
    """Every settings field has help text, and the CLI shows the field's own default."""
    from motorlab.settings import help_text

    for kind in KINDS.values():
        for name, info in kind.settings.model_fields.items():
            if name in ("env", "lqr", "hyperparams"):  # nested settings: the env's flags, presets and --set
                continue
            assert info.description, f"{kind.name}.{name} has no description"
            default = info.get_default(call_default_factory=True)
            if isinstance(default, (int, float, str)) and not isinstance(default, bool):
                assert f"(default {default})" in help_text(kind.settings, name), (kind.name, name)


def _module_names_imported_by_text(path: Path) -> list[tuple[int, str]]:
    """Calls that import a motorlab module named in the code's own text (importlib.import_module("motorlab.x"),
    __import__(f"motorlab.{name}")), with their lines: imports the import graph above cannot see."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call) and node.args):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
        if name not in ("import_module", "__import__"):
            continue
        first = node.args[0]
        text = first.value if isinstance(first, ast.Constant) else (
            first.values[0].value if isinstance(first, ast.JoinedStr) and first.values
            and isinstance(first.values[0], ast.Constant) else "")
        if isinstance(text, str) and text.startswith("motorlab"):
            found.append((node.lineno, text.rstrip(".")))
    return found


def test_no_import_by_name_reaches_up_the_layers():
    """An import the graph cannot see (a module named in text: a registry finding its plugins, a lazy
    façade) stays in its own layer or goes down, by the same layers as above: none reaches upward."""
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        importer = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
        upward += [f"{importer}:{line} ({layer(importer)}) imports {named} ({layer(named)}) by name"
                   for line, named in _module_names_imported_by_text(path) if layer(named) > layer(importer)]
    assert not upward, "\n".join(upward)


def test_the_by_name_check_finds_an_import_by_name(tmp_path):
    module = tmp_path / "hidden.py"
    module.write_text('import importlib\n\ndef f(name):\n    return importlib.import_module(f"motorlab.api.{name}")\n')
    (tmp_path / "plain.py").write_text("import importlib\nimportlib.import_module(user_module)\n")
    assert _module_names_imported_by_text(module) == [(4, "motorlab.api")]
    assert layer("motorlab.api") > layer("motorlab.synergies.sar")  # what the test above would refuse
    assert _module_names_imported_by_text(tmp_path / "plain.py") == []


def test_the_design_docs_example_kind_passes_the_checks(tmp_path):
    """docs/design.md's example step kind, written where it says into a copy of the package and registered
    as it says, passes the layer contract (lint-imports), this file's checks, and is a command."""
    import re
    import shutil
    import subprocess
    import sys

    design = (PACKAGE.parent / "docs" / "design.md").read_text()
    (where, code), = re.findall(r"```python\n# (motorlab/kinds/\w+\.py)\n(.*?)```", design, flags=re.S)
    shutil.copytree(PACKAGE, tmp_path / "motorlab", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(PACKAGE.parent / "pyproject.toml", tmp_path)
    (tmp_path / where).write_text(code)
    module = where.removesuffix(".py").replace("/", ".")
    registry = tmp_path / "motorlab" / "kinds" / "registry.py"
    text = registry.read_text()
    text = text.replace("\nKINDS: dict", f"\nfrom {module} import NOISE  # noqa: E402\n\nKINDS: dict", 1)
    registry.write_text(text.replace("    MBRL,\n)}", "    MBRL,\n    NOISE,\n)}", 1))
    env = {**__import__("os").environ, "PYTHONPATH": str(tmp_path)}
    here = str(PACKAGE.parent)

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)

    shown = run(sys.executable, "-c", "import motorlab, sys; print(motorlab.__file__)")
    assert shown.stdout.strip() == str(tmp_path / "motorlab" / "__init__.py"), shown.stderr  # the copy runs
    lint = run(str(Path(sys.executable).parent / "lint-imports"))
    assert lint.returncode == 0, lint.stdout[-2000:]
    checks = run(sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", here,
                 f"{here}/tests/test_layers.py", "-k", "not design_docs_example")
    assert checks.returncode == 0, checks.stdout[-3000:]
    command = run(sys.executable, "-m", "motorlab", "noise", "--help")
    assert command.returncode == 0 and "--std" in command.stdout and "POLICY" in command.stdout, command.stdout


LOGIC = (ast.ClassDef, ast.For, ast.AsyncFor, ast.While, ast.If, ast.With, ast.Try, ast.AsyncFunctionDef)


def init_logic(source: str) -> list[str]:
    """What a package's __init__.py holds beyond re-exports: any class, loop, branch or function at
    module level but a lazy `__getattr__` (a re-export on first use), whose body may branch, import,
    return and raise, nothing more."""
    found = []
    for node in ast.parse(source).body:
        if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
            found += [f"line {n.lineno}: {type(n).__name__} in __getattr__" for n in ast.walk(node)
                      if isinstance(n, (*LOGIC[:-1], ast.Assign, ast.FunctionDef, ast.Lambda)) and n is not node
                      and not isinstance(n, ast.If)]
        elif isinstance(node, (*LOGIC, ast.FunctionDef)):
            found.append(f"line {node.lineno}: {type(node).__name__}")
    return found


def test_package_inits_re_export_and_hold_no_logic():
    """An __init__.py names what its package gives (imports, __all__); the code is in its modules, where a
    reader looks for it (registries: `_registry.py`, `kinds/registry.py`)."""
    held = {str(p.relative_to(PACKAGE.parent)): found for p in sorted(PACKAGE.rglob("__init__.py"))
            if (found := init_logic(p.read_text()))}
    assert not held, held


@pytest.mark.parametrize("statement", ["def names():\n    return ()\n", "class Spec:\n    pass\n",
                                       "for k in ():\n    pass\n", "if True:\n    X = 1\n",
                                       "def __getattr__(name):\n    for k in ():\n        pass\n"])
def test_the_init_check_finds_logic(statement):
    lazy = 'def __getattr__(name):\n    if name == "x":\n        import json\n\n        return json\n    raise AttributeError(name)\n'
    assert init_logic('"""doc"""\nimport os\n\n__all__ = ["x"]\n' + lazy) == []
    assert init_logic('"""doc"""\n' + statement)
