"""Import rules (prybm-style): a light top-level import, one-way layering, heavy packages only on use."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "doefab"
HEAVY = {"cadquery", "klayout", "dask", "OCP", "pya", "colour", "skimage", "rawpy", "OpenEXR", "spectral",
         "tifffile", "imageio"}
# a stage may import from the stages listed for it (and itself); lower layers never import upper ones
ALLOWED = {
    "optics": {"optics"},
    "fabrication": {"optics", "fabrication"},
    "tasks": {"optics", "fabrication", "tasks"},
    "design": {"optics", "fabrication", "tasks", "design"},
    "imaging": {"optics", "imaging"},
    "reconstruction": {"optics", "fabrication", "design", "imaging", "reconstruction"},
    "tolerance": {"optics", "fabrication", "design", "tasks", "imaging", "reconstruction", "tolerance"},
    "lab": {"optics", "fabrication", "design", "tasks", "imaging", "reconstruction", "tolerance", "lab"},
    "pipeline": {"optics", "fabrication", "design", "tasks", "imaging", "reconstruction", "tolerance", "lab",
                 "pipeline"},
    "cli": None,  # the command line may use everything
}
# below every stage: each may import these, and they import only one another
BASE = {"errors", "io", "plotting", "applications", "validate", "_devices", "_memory", "diekey"}
# holder_cad is a library beside the stages: it may import doefab's base modules only, but for its command line
# (``python -m holder_cad`` is ``doefab holder``)
HOLDER_CLI = {"cli.py", "__main__.py"}


def _imports(path: Path, text: str | None = None):
    """(module, node) of every import in ``path`` (or in ``text`` as if it were that file), at any level:
    ``from doefab import optics`` names doefab.optics, and a relative import is resolved against the file's
    package."""
    tree = ast.parse(path.read_text() if text is None else text)
    rel = path.resolve().relative_to(PKG.parent).with_suffix("").parts
    package = rel[:-1]  # the package a module (or an __init__) sits in
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, node
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package[:len(package) - node.level + 1]) if node.level else ""
            module = ".".join(p for p in (base, node.module or "") if p)
            yield module, node
            for a in node.names:  # from doefab import optics / from .. import pipeline: the submodules named
                where = PKG.parent.joinpath(*module.split("."), a.name)
                if where.is_dir() or where.with_suffix(".py").is_file():
                    yield f"{module}.{a.name}", node


@pytest.mark.parametrize("what, statement", [
    ("import doefab", "import doefab"),
    # the command line's parser, built for every command (--help, --version, scene new, a bad flag)
    ("doefab --help", "from doefab.cli import build_parser; build_parser().format_help()"),
])
def test_import_doefab_is_light(what, statement):
    """``import doefab`` and the command line's parser load none of the heavy packages (their speed is a
    benchmark's business, not a test's)."""
    code = f"import sys; {statement}; print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in " \
           "{'torch', 'matplotlib', 'cadquery', 'klayout', 'dask', 'gdstk', 'trimesh', 'manifold3d', 'scipy', " \
           "'skimage', 'colour', 'nlopt'})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "", f"{what} loaded {out}"


def test_heavy_packages_only_inside_functions():
    for path in PKG.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in tree.body:  # module level only
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for n in names:
                assert n.split(".")[0] not in HEAVY, f"{path}: module-level import of {n}"


def _doefab_imports(path: Path, text: str | None = None):
    """The doefab modules ``path`` imports (anywhere in its body), as their first component below doefab."""
    for name, _ in _imports(path, text):
        parts = name.split(".")
        if parts[0] == "doefab" and len(parts) > 1:
            yield parts[1]


def test_layering():
    """Every module of every stage imports only the stages listed for it and the base modules; the base modules
    (underscore ones included) import only one another; holder_cad imports only the base; the top-level
    ``doefab/__init__`` and ``__main__`` are the package's doors (lazy re-exports, the command line)."""
    optics = PKG / "optics" / "psf.py"  # planted: every form of import names the stage it reaches
    for text in ("import doefab.pipeline.stages", "from doefab import pipeline", "from ..pipeline import stages",
                 "from .. import pipeline", "def f():\n    from doefab.pipeline.stages import x"):
        assert "pipeline" in set(_doefab_imports(optics, text)), text
    assert set(_doefab_imports(optics, "from doefab import validate as v\nfrom . import camera")) == {"validate",
                                                                                                    "optics"}
    stages = {p.name for p in PKG.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert stages - {"designs", "measured", "weights"} <= set(ALLOWED) | {"cli"}, "a package the test does not know"
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG).parts
        if len(rel) == 1:
            if path.stem in ("__init__", "__main__"):
                continue
            assert path.stem in BASE, f"{path}: a top-level module must be listed in BASE (or moved into a stage)"
            bad = set(_doefab_imports(path)) - BASE
            assert not bad, f"{path}: a base module must not import doefab.{sorted(bad)}"
            continue
        allowed = ALLOWED.get(rel[0])
        if allowed is None:
            continue
        for name in _doefab_imports(path):
            assert name in allowed | BASE, f"{path}: stage '{rel[0]}' must not import doefab.{name}"
    for path in (PKG.parent / "holder_cad").rglob("*.py"):
        if path.name not in HOLDER_CLI:
            bad = set(_doefab_imports(path)) - BASE
            assert not bad, f"{path}: holder_cad must import only doefab's base modules, not doefab.{sorted(bad)}"
    # the application registry sits below every stage: it imports doefab.errors and nothing else of doefab
    own = {n for n, _ in _imports(PKG / "applications.py") if n.startswith("doefab")}
    assert own == {"doefab.errors"}, own


def test_public_api_exports_resolve():
    """Each name ``import doefab`` offers is the public object of that name in the module it comes from (listed in
    that module's ``__all__``; a class or function carries the name, is defined in that module or its package,
    and has the docstring the API pages are built from), and ``dir(doefab)`` lists exactly those names."""
    import importlib
    import inspect

    import doefab

    assert sorted(dir(doefab)) == sorted(doefab.__all__) and "__version__" in doefab.__all__
    for name in (n for n in doefab.__all__ if n != "__version__"):
        home = importlib.import_module(doefab._EXPORTS[name])
        obj = getattr(doefab, name)
        assert name in home.__all__ and obj is getattr(home, name), f"doefab.{name} is not {home.__name__}.{name}"
        if inspect.isclass(obj) or inspect.isfunction(obj):
            assert obj.__name__ == name and obj.__module__.startswith(home.__name__), f"doefab.{name} is {obj!r}"
            assert (obj.__doc__ or "").strip(), f"doefab.{name} has no docstring"
        else:  # a constant: an instance of a public doefab class or a table of them
            assert isinstance(obj, (dict, tuple)) or type(obj).__module__.startswith("doefab."), name


def test_no_function_a_reader_cannot_hold():
    """No function or method in ``doefab/`` or ``holder_cad/`` runs over 80 lines (decorators and docstring
    included)."""
    long = []
    for root in (PKG, PKG.parent / "holder_cad"):
        for path in root.rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                    if node.end_lineno - first + 1 > 80:
                        long.append(f"{path.relative_to(PKG.parent)}:{node.lineno} {node.name} "
                                    f"({node.end_lineno - first + 1} lines)")
    assert not long, "functions over 80 lines: " + "; ".join(long)


# import circles that remain (each a set of modules importing one another, at module or function level): none
KNOWN_CIRCLES: set = set()


def _module_graph() -> dict[str, set[str]]:
    """{module: the doefab / holder_cad modules it imports anywhere in its body}."""
    mods = {}
    for base in (PKG, PKG.parent / "holder_cad"):
        for p in base.rglob("*.py"):
            parts = p.relative_to(PKG.parent).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p

    def owner(name: str) -> str:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name
    graph = {}
    for name, p in mods.items():
        pkg = name if p.name == "__init__.py" else name.rpartition(".")[0]
        out = set()
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Import):
                out |= {owner(a.name) for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                if node.level:
                    up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                    mod = ".".join(up + ([mod] if mod else []))
                out |= {owner(f"{mod}.{a.name}") if f"{mod}.{a.name}" in mods else owner(mod) for a in node.names}
        graph[name] = out - {"", name}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[frozenset]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))
    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_new_import_circle():
    """No import circle beyond the ones listed (function-level imports count: they are a circle all the same);
    the finder finds a circle made on purpose."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]
    found = _circles(_module_graph())
    new = [sorted(c) for c in found if c not in KNOWN_CIRCLES]
    assert not new, f"import circles: {new}"
    assert set(found) == KNOWN_CIRCLES, f"circles broken since: remove them from KNOWN_CIRCLES ({KNOWN_CIRCLES - set(found)})"


def _name_comparisons(tree: ast.AST, names: set) -> list[int]:
    """Lines where a string in ``names`` is compared (==, !=, in, not in) with anything."""
    def named(node):
        if isinstance(node, ast.Constant) and node.value in names:
            return True
        return isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(named(e) for e in node.elts)

    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Compare)
            and any(isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)) for op in n.ops)
            and any(named(side) for side in (n.left, *n.comparators))]


def test_no_application_name_compared_as_a_string():
    """Code asks the application registry (``doefab.applications``: ``has``, ``design_is``, ``application``)
    what an application or its design task is, never compares their names; the finder finds the forms it
    forbids."""
    from doefab.applications import DESIGN_TASKS, NAMES

    names = set(NAMES) | set(DESIGN_TASKS)
    planted = ast.parse('a = t == "hdr"\nb = "half-ring" != t\nc = t in ("x", "depth")\nd = t == "other"\n'
                        'e = {"hdr": 1}["hdr"]\n')
    assert _name_comparisons(planted, names) == [1, 2, 3]
    root = PKG.parent
    found = {str(p.relative_to(root)): lines for p in [*PKG.rglob("*.py"), *(root / "holder_cad").rglob("*.py")]
             if p.name != "applications.py" and (lines := _name_comparisons(ast.parse(p.read_text()), names))}
    assert not found, f"application or design-task names compared as strings (ask doefab.applications): {found}"


PAGE = PKG.parent / "docs" / "guide" / "architecture.md"


def _section(name: str, page: str | None = None) -> str:
    page = PAGE.read_text() if page is None else page
    return page.split(f"<!-- {name}-start -->")[1].split(f"<!-- {name}-end -->")[0]


def _page_layers(page: str) -> dict:
    """{package: what it may import (None: everything)} as the page's layer table states it."""
    rows = {}
    for line in _section("layers", page).strip().splitlines()[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0].strip("`")] = None if cells[2] == "everything" else {c.strip() for c in cells[2].split(",")}
    return rows


def _page_base(page: str) -> set:
    """The base modules the page's paragraph names (``doefab.X``)."""
    para = page.split("Every stage may also import the base modules", 1)[1].split("\n\n", 1)[0]
    return set(re.findall(r"`doefab\.(\w+)`", para))


def _table_modules() -> set:
    """The modules that key a table by two or more application or design-task names."""
    from doefab.applications import DESIGN_TASKS, NAMES

    names = set(NAMES) | set(DESIGN_TASKS)
    keyed = set()
    for path in PKG.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            # a table: two keys or more named after applications or design tasks (one may be a word: "depth")
            if isinstance(node, ast.Dict) and sum(isinstance(k, ast.Constant) and k.value in names
                                                  for k in node.keys) >= 2:
                keyed.add(str(path.relative_to(PKG.parent)))
    return keyed - {"doefab/applications.py"}


def test_the_architecture_page_states_the_rules_the_test_enforces():
    """docs/guide/architecture.md's layer table is ``ALLOWED`` (a planted change is told apart), its base
    modules are ``BASE`` exactly, every module its list of per-application tables names exists, and that list
    names every module that keys a table by two or more application or design-task names."""
    page = PAGE.read_text()
    assert _page_layers(page) == ALLOWED
    assert _page_layers(page.replace("| optics, imaging |", "| optics, imaging, design |")) != ALLOWED
    assert _page_base(page) == BASE
    listed = _section("application-tables", page)
    paths = set(re.findall(r"`(doefab/[\w/]+\.py)`", listed))
    assert paths and all((PKG.parent / f).is_file() for f in paths), sorted(paths)
    missing = sorted(_table_modules() - paths)
    assert not missing, f"modules keying a table by application name, not listed on the architecture page: {missing}"
