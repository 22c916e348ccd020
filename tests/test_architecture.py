"""The package's layout holds: layers, no cycles, no private imports, a true map.

A short walk over the source's syntax trees (nothing is imported or run):

* every import of a facewrap module goes to the same layer or a lower one
  (:data:`LAYERS`, lowest first), function-local imports included;
* the module import graph has no cycle;
* no module imports another module's private name (``from x import _y``), a
  private module of another package, or reads a private attribute of an imported
  module (``x._y``); tests follow the same rule;
* every module is named in ``docs/architecture.md`` and every module named there
  exists.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PACKAGE = SRC / "facewrap"
DOC = ROOT / "docs" / "architecture.md"

#: Layers, lowest first.  A module may import its own layer or lower ones; within a
#: layer the cycle test keeps the graph a tree.  A name is a module or a package
#: (then every module inside it).
LAYERS = [
    ["facewrap.errors", "facewrap.params", "facewrap.units", "facewrap.progress",
     "facewrap.version", "facewrap.lazy", "facewrap.parallel"],
    ["facewrap.mesh", "facewrap.geometry", "facewrap.solve"],
    ["facewrap.landmarks"],
    ["facewrap.io"],
    ["facewrap.texture", "facewrap.evaluate", "facewrap.datasets", "facewrap.sample"],
    ["facewrap.wrapping", "facewrap.transfer", "facewrap.report", "facewrap.animation",
     "facewrap.detection"],
    ["facewrap.avatar", "facewrap.rig"],
    ["facewrap.jobs"],
    ["facewrap.batch"],
    ["facewrap.cli"],
    ["facewrap"],  # the package itself: the public API
]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def source_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


MODULES = source_modules()


def layer_of(module: str) -> int:
    best, level = -1, None
    for i, names in enumerate(LAYERS):
        for name in names:
            if (module == name or module.startswith(name + ".")) and len(name) > best:
                best, level = len(name), i
    if level is None:
        raise AssertionError(f"{module} is in no layer of tests/test_architecture.py")
    return level


def _resolve(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = importer.split(".") if is_package else importer.split(".")[:-1]
    if node.level > 1:
        base = base[: -(node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(path: Path):
    """``(line, target module, imported names, module aliases)`` per facewrap import.

    ``from facewrap.x import y`` where ``y`` is a submodule counts as importing
    ``facewrap.x.y``.
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    me = module_name(path) if path.is_relative_to(SRC) else "tests"
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "facewrap":
                    out.append((node.lineno, a.name, [], a.asname or a.name))
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(node, me, is_package)
            if target.split(".")[0] != "facewrap":
                continue
            names = [a.name for a in node.names]
            subs = [n for n in names if f"{target}.{n}" in MODULES]
            for n in subs:
                out.append((node.lineno, f"{target}.{n}", [], n))
            rest = [n for n in names if n not in subs]
            if rest:
                out.append((node.lineno, target, rest, None))
    return tree, out


def test_every_module_sits_in_a_layer():
    for name in MODULES:
        layer_of(name)


def test_no_module_imports_a_higher_layer():
    wrong = []
    for name, path in MODULES.items():
        mine = layer_of(name)
        for line, target, _, _ in imports_of(path)[1]:
            if layer_of(target) > mine:
                wrong.append(f"{path.relative_to(ROOT)}:{line} {name} (layer {mine}) "
                             f"imports {target} (layer {layer_of(target)})")
    assert not wrong, "imports of a higher layer:\n" + "\n".join(wrong)


def _owner(module: str) -> str:
    """The module a private name belongs to: private modules belong to their package."""
    parts = module.split(".")
    while parts and parts[-1].startswith("_") and not parts[-1].startswith("__"):
        parts = parts[:-1]
    return ".".join(parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def _private_uses(path: Path, me: str) -> list[str]:
    tree, found = imports_of(path)
    bad = []
    aliases = {}
    for line, target, names, alias in found:
        where = f"{_shown(path)}:{line}"
        if any(_private(p) for p in target.split(".")) and _owner(target) != _owner(me) \
                and not me.startswith(_owner(target) + "."):
            bad.append(f"{where} imports the private module {target}")
        for n in names:
            if _private(n) and target != me:
                bad.append(f"{where} imports the private name {target}.{n}")
        if alias:
            aliases[alias.split(".")[0] if alias == target else alias] = target
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            base = node.value
            dotted = []
            while isinstance(base, ast.Attribute):
                dotted.append(base.attr)
                base = base.value
            if isinstance(base, ast.Name) and base.id in aliases:
                bad.append(f"{_shown(path)}:{node.lineno} reads "
                           f"{base.id}.{'.'.join(reversed(dotted + [node.attr]))}")
    return bad


def test_no_private_names_across_modules():
    bad = []
    for name, path in MODULES.items():
        bad += _private_uses(path, name)
    for path in sorted((ROOT / "tests").glob("*.py")):
        bad += _private_uses(path, "tests")
    assert not bad, "private names used outside their module:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph = {name: set() for name in MODULES}
    for name, path in MODULES.items():
        for _, target, _, _ in imports_of(path)[1]:
            if target in graph and target != name:
                graph[name].add(target)
    # importing facewrap.a.b runs facewrap.a first, so an edge into a submodule also
    # reaches its packages (not the root package, whose __init__ is the public API,
    # and not the importer's own packages, which are already running)
    for name in list(graph):
        for target in list(graph[name]):
            parent = target.rsplit(".", 1)[0]
            while "." in parent and parent != name and not name.startswith(parent + "."):
                graph[name].add(parent)
                parent = parent.rsplit(".", 1)[0]
    cycles, state = [], {}

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, "import cycles:\n" + "\n".join(cycles[:20])


def _doc_paths() -> set[str]:
    text = DOC.read_text()
    return set(re.findall(r"`([\w/]+\.py)`", text)) | set(re.findall(r"`([\w/]+/)`", text))


def test_architecture_doc_names_every_module():
    named = _doc_paths()
    missing = []
    for name, path in MODULES.items():
        rel = path.relative_to(PACKAGE).as_posix()
        if path.name == "__init__.py":
            rel = rel[: -len("__init__.py")]
            if not rel or rel in named:
                continue
        elif path.name == "__main__.py" or rel in named:
            continue
        missing.append(rel)
    assert not missing, f"docs/architecture.md does not name: {missing}"


def test_architecture_doc_names_only_modules_that_exist():
    gone = [p for p in _doc_paths() if not (PACKAGE / p).exists() and not (ROOT / p).exists()]
    assert not gone, f"docs/architecture.md names what does not exist: {sorted(gone)}"


@pytest.mark.parametrize("text,expected", [
    ("from facewrap.x import _y\n", "private name"),
    ("import facewrap.x as m\nm._z\n", "reads m._z"),
])
def test_the_private_name_check_catches(tmp_path, text, expected):
    path = tmp_path / "probe.py"
    path.write_text(text)
    found = _private_uses(path, "tests")
    assert found and expected in found[0]


#: single-format readers and writers may be long; everything else stays readable
LONG_MODULES_ALLOWED = {"io/ply.py", "io/obj.py"}
MAX_MODULE_LINES = 600
MAX_FUNCTION_CODE_LINES = 80


def code_lines(node: ast.AST, source_lines: list[str]) -> int:
    """Lines of a function that hold code: no docstring, blank or comment-only lines."""
    skip = set()
    body = getattr(node, "body", [])
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        skip |= set(range(body[0].lineno, body[0].end_lineno + 1))
    count = 0
    for i in range(node.lineno, node.end_lineno + 1):
        text = source_lines[i - 1].strip()
        if i in skip or not text or text.startswith("#"):
            continue
        count += 1
    return count


def test_modules_and_functions_stay_short():
    long_modules, long_functions = [], []
    for path in MODULES.values():
        rel = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        lines = text.splitlines()
        if len(lines) > MAX_MODULE_LINES and rel not in LONG_MODULES_ALLOWED:
            long_modules.append(f"{rel} ({len(lines)} lines)")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = code_lines(node, lines)
                if n > MAX_FUNCTION_CODE_LINES:
                    long_functions.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    assert not long_modules and not long_functions, (
        f"modules over {MAX_MODULE_LINES} lines: {long_modules}; "
        f"functions over {MAX_FUNCTION_CODE_LINES} lines of code: {long_functions}")
