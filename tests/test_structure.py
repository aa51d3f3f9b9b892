"""The package's import graph has no cycle (issue 17, item 8): every ``from .x import`` /
``from . import x`` / ``import jaxrod.x``, at module level or inside a function, is an edge; a cycle
through function-level imports still ties the modules together."""
import ast
import pathlib

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "jaxrod"


def _module_name(path):
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path, name):
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("jaxrod"):
                continue
            if node.module is None or node.level and not node.module:
                for alias in node.names:  # from . import x: the submodule x
                    out.add(f"{target}.{alias.name}")
            else:
                out.add(target)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("jaxrod"))
    return out


def _graph():
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        edges = set()
        for target in _imports(path, name):
            while target and target not in modules:  # jaxrod.x.Name -> jaxrod.x
                target = target.rsplit(".", 1)[0] if "." in target else ""
            if target and target != name and not name.startswith(target + "."):
                edges.add(target)
        graph[name] = edges
    return graph


def _cycle(graph):
    colour, stack = {}, []

    def visit(n):
        colour[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if m.startswith(n + "."):  # a package importing its own submodules
                continue
            if colour.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if not colour.get(m):
                found = visit(m)
                if found:
                    return found
        stack.pop()
        colour[n] = 2
        return None

    for n in sorted(graph):
        if not colour.get(n):
            found = visit(n)
            if found:
                return found
    return None


def test_the_import_graph_is_read():
    graph = _graph()
    assert "jaxrod.solve.equilibrium" in graph["jaxrod.continuation.engine"]
    assert "jaxrod.linalg.stability" in graph["jaxrod.solve.equilibrium"]


def test_no_import_cycle():
    cycle = _cycle(_graph())
    assert cycle is None, " -> ".join(cycle)


# The layers, lowest first: a module imports only from its own layer and the layers before it.
# ``aot`` (the compile cache) and ``validation`` (argument checks) serve every layer.
LAYERS = ("base", "model", "measure", "linalg", "solve", "continuation", "io", "studies", "cli")
BASE = ("jaxrod.aot", "jaxrod.validation")
TOP = ("jaxrod.api",)


def _layer(module):
    if module in BASE:
        return 0
    parts = module.split(".")
    if len(parts) == 1 or module in TOP:  # the package and its public API, above everything
        return len(LAYERS)
    return LAYERS.index(parts[1])


def test_every_module_is_in_a_layer():
    names = list(_graph())
    assert len(names) > 40 and all(_layer(name) is not None for name in names)  # ValueError outside the layers


def test_layers_import_only_downward():
    upward = sorted(f"{name} -> {target}" for name, targets in _graph().items() for target in targets
                    if _layer(target) > _layer(name))
    assert not upward, upward


def test_the_layer_check_sees_an_upward_import():
    assert _layer("jaxrod.model.scenes") < _layer("jaxrod.linalg.stability") < _layer("jaxrod.cli.trefoil")


# Size: no library file over MAX_FILE_LINES lines, no function over MAX_FUNCTION_LINES (from its
# ``def`` to its last line, docstring included).
MAX_FILE_LINES, MAX_FUNCTION_LINES = 600, 80


def _oversized():
    out = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(PACKAGE.parent).as_posix()
        if text.count("\n") > MAX_FILE_LINES:
            out.add(rel)
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES:
                    out.add(f"{rel}:{node.name}")
    return out


def test_no_file_or_function_over_the_size_limits():
    over = _oversized()
    assert not over, sorted(over)


def _private_uses(text):
    """Underscore names of jaxrod that a test file imports (an underscore name from a jaxrod module,
    or an underscore module of jaxrod) or reaches as an attribute of a jaxrod name it imported."""
    tree = ast.parse(text)
    modules, out = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("jaxrod"):
            out |= {f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_") and not a.name.startswith("__")}
            out |= {node.module + "." + part for part in node.module.split(".") if part.startswith("_")}
            modules |= {a.asname or a.name for a in node.names}
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("jaxrod"):
                    out |= {a.name for part in a.name.split(".") if part.startswith("_") and not part.startswith("__")}
                    modules.add(a.asname or a.name.split(".")[0])
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                and isinstance(node.value, ast.Name) and node.value.id in modules):
            out.add(f"{node.value.id}.{node.attr}")
    return out


def test_no_test_reaches_a_private_name_of_jaxrod():
    tests = pathlib.Path(__file__).resolve().parent
    found = {f"{p.name}: {use}" for p in sorted(tests.glob("*.py")) for use in _private_uses(p.read_text(encoding="utf-8"))}
    assert not found, sorted(found)


def test_the_private_name_check_sees_one():
    pkg, private = "jaxrod", "_x"  # kept apart so that this file does not read as a private import itself
    sample = f"from {pkg}.studies.twist import {private}\nimport {pkg}.aot as aot\naot._y()\n"
    assert _private_uses(sample) == {f"{pkg}.studies.twist.{private}", "aot._y"}
    public = f"import numpy as np\nnp.{private}\nfrom {pkg}.api import stability\nstability.__doc__\n"
    assert _private_uses(public) == set()


_CHECKS = {"raises", "warns", "approx", "assert_allclose", "assert_array_equal", "assert_equal", "fail", "skip"}


def _tests_that_check_nothing(text):
    """Test functions in ``text`` with no assert, no pytest.raises/warns/approx/fail/skip, no
    numpy.testing check and no call of a function of the same file that asserts."""
    tree = ast.parse(text)
    functions = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)]
    asserting = {n.name for n in functions if any(isinstance(x, ast.Assert) for x in ast.walk(n))}
    imported = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}

    def checks(node):
        return any(isinstance(x, ast.Assert)
                   or (isinstance(x, ast.Attribute) and x.attr in _CHECKS)
                   or (isinstance(x, ast.Call) and isinstance(x.func, ast.Name)
                       and (x.func.id in asserting or (x.func.id in imported and x.func.id.startswith("check"))))
                   for x in ast.walk(node))
    return [n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test") and not checks(n)]


def test_every_test_asserts_something():
    tests = pathlib.Path(__file__).resolve().parent
    empty = {f"{p.name}::{name}" for p in sorted(tests.glob("test_*.py"))
             for name in _tests_that_check_nothing(p.read_text(encoding="utf-8"))}
    assert not empty, sorted(empty)
    assert _tests_that_check_nothing("def test_a():\n    x = 1\n\ndef test_b():\n    assert 1\n") == ["test_a"]
