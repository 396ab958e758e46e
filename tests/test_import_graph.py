"""The import graph points down the layers: no circles, no upward imports, no private names
imported across modules, and imports inside functions only where a comment says why.

The layers (lowest first) are the ones docs/architecture.md draws.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ingest", "raycast", "rsodb")
# A package may import only from packages before it.
PACKAGE_RANK = {"ingest": 0, "raycast": 1, "rsodb": 2}
# Domains inside a package (its sub-packages and top-level modules): a domain may import only
# from domains of a lower rank; domains of equal rank do not know each other.
DOMAIN_RANK = {
    "raycast": {"geometry": 0, "renderer": 0, "models": 1, "cycles": 1},
    "rsodb": {
        "storage": 0,
        "pool": 0,
        "plotting": 0,
        "periods": 1,
        "fit": 2,
        "archive": 2,
        "rendering": 2,
        "campaign": 3,
        "samples": 3,
        "report": 4,
        "pipeline": 5,
        "cli": 6,
        "__main__": 7,
    },
}
# Front doors: load their names lazily and import nothing of the project at import time.
FRONT_DOORS = {"ingest", "raycast", "rsodb"}
# The top layers reach the library through the lazy front door, so that `rsodb --help` loads
# nothing of it.
FRONT_DOOR_USERS = {"rsodb": ("cli", "__main__")}


def module_files() -> dict[str, Path]:
    files = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            files[name] = path
    return files


MODULES = module_files()


class Import:
    def __init__(
        self, importer: str, target: str, names: tuple[str, ...], line: int, in_function: bool, commented: bool
    ):
        self.importer, self.target, self.names, self.line = importer, target, names, line
        self.in_function, self.commented = in_function, commented

    def __repr__(self):
        return f"{MODULES[self.importer].relative_to(ROOT)}:{self.line}: {self.target}"


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_of(name: str) -> list[Import]:
    """Every import statement of a module (TYPE_CHECKING blocks left out), resolved to modules."""
    path = MODULES[name]
    source = path.read_text()
    lines = source.splitlines()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def commented(node) -> bool:
        above = lines[node.lineno - 2].strip() if node.lineno >= 2 else ""
        return "#" in lines[node.lineno - 1] or above.startswith("#")

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                continue
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    found.append(Import(name, alias.name, (), child.lineno, in_function, commented(child)))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")[: len(package.split(".")) - child.level + 1]
                    module = ".".join(base + ([child.module] if child.module else []))
                else:
                    module = child.module
                names = tuple(alias.name for alias in child.names)
                found.append(Import(name, module, names, child.lineno, in_function, commented(child)))
            visit(child, inner)

    visit(ast.parse(source), False)
    return found


def project_edges() -> list[tuple[str, str, Import]]:
    """(importer, imported module, statement) for every import of a project module."""
    edges = []
    for name in MODULES:
        for statement in imports_of(name):
            if statement.target.split(".")[0] not in PACKAGES:
                continue
            targets = [f"{statement.target}.{n}" for n in statement.names if f"{statement.target}.{n}" in MODULES]
            if len(targets) < len(statement.names) or not statement.names:
                targets.append(statement.target)
            for target in targets:
                edges.append((name, target, statement))
    return edges


EDGES = project_edges()


def domain(name: str) -> tuple[str, str | None]:
    parts = name.split(".")
    return parts[0], (parts[1] if len(parts) > 1 else None)


def test_every_import_names_a_module_that_exists():
    missing = [statement for _, target, statement in EDGES if target not in MODULES]
    assert not missing, f"imports of modules that do not exist: {missing}"


def test_there_are_no_import_circles():
    graph: dict[str, set[str]] = {name: set() for name in MODULES}
    for importer, target, _ in EDGES:
        if importer not in FRONT_DOORS:
            graph[importer].add(target)
    # Tarjan's strongly connected components.
    index, low, stack, on_stack, circles, counter = {}, {}, [], set(), [], [0]

    def connect(node):
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for nxt in graph[node]:
            if nxt not in index:
                connect(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    assert not circles, f"import circles: {circles}"


def test_imports_point_down_the_layers():
    upward = []
    for importer, target, statement in EDGES:
        if importer in FRONT_DOORS:
            continue
        (package, sub), (target_package, target_sub) = domain(importer), domain(target)
        if PACKAGE_RANK[target_package] > PACKAGE_RANK[package]:
            upward.append(statement)
        elif package == target_package and sub != target_sub and package in DOMAIN_RANK:
            ranks = DOMAIN_RANK[package]
            if target_sub is None:
                if sub not in FRONT_DOOR_USERS.get(package, ()):
                    upward.append(statement)  # a domain importing its package's front door
            elif ranks[target_sub] >= ranks[sub]:
                upward.append(statement)
    assert not upward, f"imports that do not point down the layers: {upward}"


def test_every_domain_has_a_rank():
    for package, ranks in DOMAIN_RANK.items():
        domains = {domain(name)[1] for name in MODULES if name.startswith(package + ".")}
        assert domains == set(ranks), f"{package}: domains without a rank or ranks without a domain"


def test_front_doors_import_nothing_of_the_project():
    for name in FRONT_DOORS:
        project = [s for s in imports_of(name) if s.target.split(".")[0] in PACKAGES]
        assert not project, f"{name} must load its names lazily, but imports {project}"


def test_no_private_name_is_imported_from_another_module():
    private = []
    for importer, target, statement in EDGES:
        for imported in statement.names:
            if not imported.startswith("_"):
                continue
            own_package = importer.rpartition(".")[0] if MODULES[importer].name != "__init__.py" else importer
            is_sibling_module = f"{statement.target}.{imported}" in MODULES and statement.target == own_package
            if not is_sibling_module:
                private.append(statement)
    assert not private, f"private names imported across modules: {private}"


def test_imports_inside_functions_say_why():
    silent = [s for name in MODULES for s in imports_of(name) if s.in_function and not s.commented]
    assert not silent, (
        f"imports inside functions are for optional or heavy dependencies only, with a comment saying why: {silent}"
    )


@pytest.mark.parametrize("front_door", sorted(FRONT_DOORS))
def test_every_name_of_a_front_door_resolves(front_door):
    module = __import__(front_door)
    for exported in module.__all__:
        assert getattr(module, exported) is not None, f"{front_door}.{exported}"
