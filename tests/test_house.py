"""The house rules of the library (``ks_jax`` and ``fit``), read from its source with ``ast``:

- no function or method longer than ``LONGEST`` lines (its ``def`` to its last line, decorators left out): a
  longer one is several steps that want names of their own;
- no private name (one ``_underscore``) of one module used by another: neither ``from .x import _name`` nor
  ``x._name`` on an imported module (a module's private names are its own; the public face of a package is what
  its ``__init__`` exports);
- no import cycle between the library's modules (the ``import`` and ``from ... import`` statements a module runs
  when it is imported: those of its body, outside functions and ``if TYPE_CHECKING:``).

Each rule holds everywhere but in the exceptions listed below, each with why; an exception that no longer
occurs fails ``test_every_exception_still_occurs``, so that the list only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ks_jax", "fit")
LONGEST = 120  # lines of one function or method

# "path::qualified name" -> why it is still longer than LONGEST
LONG_FUNCTIONS = {
}
# "importing module -> imported module.name" -> why a module still uses another's private name
PRIVATE_IMPORTS = {
}
# "a -> b -> a" (a cycle's modules in import order, from the alphabetically first) -> why it is still there
CYCLES = {
}


def is_private(name):
    """A name its module keeps to itself: one leading underscore (``__all__``, ``__version__`` are not)."""
    return name.startswith("_") and not name.startswith("__")


def library_files():
    """{module name: path} of every module of the library (``ks_jax.sweeps.engine``; a package by its own name)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


MODULES = library_files()
TREES = {name: ast.parse(path.read_text(encoding="utf-8"), str(path)) for name, path in MODULES.items()}


def where(module):
    """A module's file as the exceptions name it: ``ks_jax/sweeps/engine.py``."""
    return MODULES[module].relative_to(ROOT).as_posix()


def functions(tree, prefix=""):
    """(qualified name, node) of every function and method in ``tree``, nested ones included
    (``Class.method``, ``outer.inner``)."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node
            yield from functions(node, f"{prefix}{node.name}.")
        elif isinstance(node, ast.ClassDef):
            yield from functions(node, f"{prefix}{node.name}.")
        else:
            yield from functions(node, prefix)


def function_lengths():
    """{"path::qualified name": lines} of every function and method of the library."""
    return {f"{where(module)}::{name}": node.end_lineno - node.lineno + 1
            for module, tree in TREES.items() for name, node in functions(tree)}


def long_functions():
    """{"path::qualified name": lines} of those longer than ``LONGEST``."""
    return {key: lines for key, lines in function_lengths().items() if lines > LONGEST}


def absolute(module, node):
    """The module a ``from ... import`` in ``module`` names, its relative dots resolved (None for ``from . import``
    past the top)."""
    if not node.level:
        return node.module
    package = module.split(".") if MODULES[module].name == "__init__.py" else module.split(".")[:-1]
    if node.level - 1 > len(package):
        return None
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def in_library(name):
    return name is not None and name.split(".")[0] in PACKAGES


def imports(module, tree, top_only):
    """(node, [(imported module, name or None)]) of each import statement of ``module``: the module a name is
    taken from, and the name (None for ``import a.b``; for ``from a import b``, b's module where b is one).
    ``top_only``: the statements run when the module is imported (its body, its ``if`` and ``try`` blocks,
    not functions, classes or ``if TYPE_CHECKING:``)."""
    def walk(body):
        for node in body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                yield node
            elif not top_only:
                yield from (n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom)))
            elif isinstance(node, ast.If):
                if "TYPE_CHECKING" not in ast.unparse(node.test):
                    yield from walk(node.body)
                yield from walk(node.orelse)
            elif isinstance(node, ast.Try):
                for block in (node.body, node.orelse, node.finalbody, *(h.body for h in node.handlers)):
                    yield from walk(block)

    for node in walk(tree.body):
        if isinstance(node, ast.Import):
            yield node, [(alias.name, None) for alias in node.names]
        else:
            source = absolute(module, node)
            yield node, [(source, alias.name) for alias in node.names]


def module_of(source, name):
    """The library module ``from source import name`` imports: ``source.name`` where that is a module, else
    ``source``; None outside the library."""
    if not in_library(source):
        return None
    if name is not None and f"{source}.{name}" in MODULES:
        return f"{source}.{name}"
    return source if source in MODULES else None


def module_names(module, tree):
    """{name bound in ``module``: library module} of the modules it imports under a name (``import a.b as c``,
    ``from . import engine``, ``import ks_jax``: ``ks_jax``), anywhere in it."""
    bound = {}
    for node, pairs in imports(module, tree, top_only=False):
        for alias, (source, name) in zip(node.names, pairs):
            if isinstance(node, ast.Import):
                if in_library(source):
                    bound[alias.asname or source.split(".")[0]] = source if alias.asname else source.split(".")[0]
            elif name is not None and f"{source}.{name}" in MODULES:
                bound[alias.asname or name] = f"{source}.{name}"
    return bound


def dotted(node):
    """``a.b.c`` of an attribute chain on a plain name, as its parts; None for anything else."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return [node.id, *reversed(parts)] if isinstance(node, ast.Name) else None


def private_imports():
    """{"importing module -> imported module.name": "path:line"} of every private name one library module takes
    from another: ``from x import _name`` and ``x._name`` on a module ``x`` it imported."""
    found = {}
    for module, tree in TREES.items():
        for node, pairs in imports(module, tree, top_only=False):
            for source, name in pairs:
                target = module_of(source, name)
                if (isinstance(node, ast.ImportFrom) and is_private(name) and target == source
                        and target is not None and target != module):
                    found[f"{module} -> {source}.{name}"] = f"{where(module)}:{node.lineno}"
        bound = module_names(module, tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and is_private(node.attr)):
                continue
            parts = dotted(node.value)
            if not parts or parts[0] not in bound:
                continue
            owner = ".".join([bound[parts[0]], *parts[1:]])
            if owner in MODULES and owner != module:
                found[f"{module} -> {owner}.{node.attr}"] = f"{where(module)}:{node.lineno}"
    return found


def import_graph():
    """{module: {library modules its import statements run (``top_only``)}}."""
    graph = {}
    for module, tree in TREES.items():
        targets = set()
        for _, pairs in imports(module, tree, top_only=True):
            for source, name in pairs:
                target = module_of(source, name)
                if target is not None and target != module:
                    targets.add(target)
        graph[module] = targets
    return graph


def cycles(graph):
    """Every cycle of ``graph`` found by a depth-first search, each once, as "a -> b -> a" from its
    alphabetically first module."""
    found, state = set(), {}

    def visit(node, stack):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                loop = stack[stack.index(nxt):]
                first = loop.index(min(loop))
                loop = loop[first:] + loop[:first]
                found.add(" -> ".join([*loop, loop[0]]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return found


def test_no_function_is_longer_than_the_limit():
    new = {key: lines for key, lines in long_functions().items() if key not in LONG_FUNCTIONS}
    assert not new, f"longer than {LONGEST} lines (split them into named steps): {new}"


def test_no_module_uses_another_modules_private_names():
    new = {key: line for key, line in private_imports().items() if key not in PRIVATE_IMPORTS}
    assert not new, f"private names used across modules (make them public, or move the code): {new}"


def test_the_modules_import_each_other_without_a_cycle():
    new = cycles(import_graph()) - set(CYCLES)
    assert not new, f"import cycles: {sorted(new)}"


def test_every_exception_still_occurs():
    """An exception fixed is taken off its list, so that the rule holds there from then on."""
    gone = {**{k: "LONG_FUNCTIONS" for k in set(LONG_FUNCTIONS) - set(long_functions())},
            **{k: "PRIVATE_IMPORTS" for k in set(PRIVATE_IMPORTS) - set(private_imports())},
            **{k: "CYCLES" for k in set(CYCLES) - cycles(import_graph())}}
    assert not gone, f"no longer occur; take them off their lists: {gone}"


def violations(planted=None):
    """{"long", "private", "cycle": what each check finds}, with ``planted`` (source text) read as a module of
    the library, ks_jax/sweeps/planted.py, imported by its package's __init__ (read, not written)."""
    name = "ks_jax.sweeps.planted"
    if planted is not None:
        MODULES[name], TREES[name] = ROOT / "ks_jax" / "sweeps" / "planted.py", ast.parse(planted)
    try:
        graph = import_graph()
        if planted is not None:
            graph["ks_jax.sweeps"].add(name)
        return {"long": set(long_functions()), "private": set(private_imports()), "cycle": cycles(graph)}
    finally:
        MODULES.pop(name, None)
        TREES.pop(name, None)


@pytest.mark.parametrize("planted, broken", [
    ("def f():\n" + "    x = 1\n" * LONGEST + "    return x\n", "long"),
    ("class A:\n    def f(self):\n" + "        x = 1\n" * LONGEST + "        return x\n", "long"),
    ("from .engine import _bucket\n", "private"),
    ("def f():\n    from ..model.contact.overlap import _first_two\n    return _first_two\n", "private"),
    ("from . import engine\n\n\ndef f():\n    return engine._bucket(3)\n", "private"),
    ("import ks_jax.sweeps.engine\n\n\ndef f():\n    return ks_jax.sweeps.engine._bucket(3)\n", "private"),
    ("from .. import sweeps\n", "cycle"),
    ("from .engine import sweep\n", None),  # a public name, of a module that does not import this one
])
@pytest.mark.slow
def test_the_checks_see_a_planted_violation(planted, broken):
    """Each check finds a violation planted in a module of the library, and only that: a function or a method
    of ``LONGEST`` + 2 lines, a private name taken from another module by ``from ... import`` (at the top or
    in a function) or as a module's attribute, and a cycle through the package that imports the module."""
    before, after = violations(), violations(planted)
    assert {kind for kind in before if after[kind] != before[kind]} == ({broken} if broken else set()), after
