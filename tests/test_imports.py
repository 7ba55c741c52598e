"""warpgs's import graph, read from the source with ``ast``: every import counts, deferred ones (inside
functions) too, and importing ``a.b.c`` also runs the packages ``a.b`` and ``a`` above it. The graph has no
circle, and no module imports one of a higher layer (kernels at the bottom, runnable pipelines at the top)."""

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "warpgs"

# lower layers may not import higher ones; one layer may import within itself. A package's modules share its
# layer unless one is named on its own ("strategy.compact"): the longest name that matches decides
LAYERS = [
    ["console", "runfolder", "_warp", "kernels", "configio", "registry", "geometry", "guard", "losses", "ply", "viz",
     "wallclock"],
    ["render", "metrics", "farfield"],
    ["model", "data"],
    ["strategy"],  # the package, DefaultStrategy, its ops and the leaf of its stages' settings
    ["pseudo", "densify"],
    ["points", "strategy.clearance", "regularizers", "backgrounds"],
    ["config"],
    ["optim"],
    ["engine", "coreg"],
    ["strategy.compact"],
    ["methods"],
    ["train", "pipelines", "view", "configdoc"],
]
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}


def _modules() -> dict[str, Path]:
    mods = {}
    for p in PKG.rglob("*.py"):
        parts = ("warpgs",) + p.relative_to(PKG).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = p
    return mods


def _with_parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts) + 1)]


def import_graph() -> dict[str, set[str]]:
    mods = _modules()
    graph = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                # ``from m import x``: the submodule m.x when there is one, else m
                found = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
            else:
                continue
            for t in found:
                targets.update(p for p in _with_parents(t) if p in mods)
        own = set(_with_parents(name))  # a module's own packages are running already
        graph[name] = {t for t in targets if t not in own}
    return graph


def _layer_name(name: str) -> str | None:
    """The entry of ``LAYERS`` that places the module ``name`` (warpgs.a.b.c): the longest of a.b.c, a.b, a."""
    parts = name.split(".")[1:]
    return next((".".join(parts[:i]) for i in range(len(parts), 0, -1) if ".".join(parts[:i]) in RANK), None)


def _layer(name: str) -> int:
    if "." not in name:
        return -1  # the package itself (warpgs/__init__.py)
    return RANK[_layer_name(name)]


def test_every_module_has_a_layer():
    missing = sorted(n for n in _modules() if "." in n and _layer_name(n) is None)
    assert not missing, f"add these to LAYERS: {missing}"


def test_a_package_split_across_layers_has_its_package_module_in_the_lowest():
    """Importing ``warpgs.strategy.compact`` runs ``warpgs.strategy`` first: that package module (and what it
    imports) must sit no higher than any of its modules named on their own."""
    mods = _modules()
    for entry in RANK:
        if "." in entry:
            package = "warpgs." + entry.rpartition(".")[0]
            assert "warpgs." + entry in mods and package in mods and _layer(package) <= RANK[entry], entry


def test_no_import_circle():
    graph = import_graph()
    index, low, stack, on, circles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not circles, circles


def test_no_upward_import():
    up = sorted(f"{a} -> {b}" for a, deps in import_graph().items() for b in deps
                if _layer(b) > _layer(a) and b != "warpgs")
    assert not up, up


def test_the_graph_reader_sees_deferred_and_relative_imports():
    g = import_graph()
    assert "warpgs.data.scene" in g["warpgs.data.llff"]  # from .scene import ...
    assert "warpgs.engine.stepguard" in g["warpgs.strategy.compact"]  # deferred, inside a function
    assert "warpgs.densify" in g["warpgs.points.stereo"]  # a submodule runs its package first


def test_the_wheel_lists_every_package_and_carries_the_configs():
    """pyproject's explicit package list (needed to map configs/ into the wheel as warpgs/configs) names
    every package of the tree, and that mapping points at the configs folder."""
    import tomllib

    meta = tomllib.loads((PKG.parent / "pyproject.toml").read_text())["tool"]["setuptools"]
    tree = {".".join(("warpgs",) + p.parent.relative_to(PKG).parts) for p in PKG.rglob("__init__.py")}
    assert set(meta["packages"]) - {"warpgs.configs"} == tree
    assert meta["package-dir"]["warpgs.configs"] == "configs"
    assert (PKG.parent / "configs" / "methods" / "baseline.yaml").is_file()
    folders = {p.parent.name for p in (PKG.parent / "configs").rglob("*.yaml")}
    assert set(meta["package-data"]["warpgs.configs"]) == {f"{f}/*.yaml" for f in folders}


OPTIONAL = ("ray",)  # extras (pyproject's optional-dependencies) a module may import only where it is used


def test_optional_extras_are_imported_only_where_used():
    """No module imports an optional extra when it is imported itself (warpgs.pipelines.batch imports Ray in
    the functions that run a batch, so ``--list`` and the message saying what to install work without it)."""
    top = []
    for name, path in _modules().items():
        for node in ast.parse(path.read_text()).body:
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            top += [f"{name}: {n}" for n in names if n.split(".")[0] in OPTIONAL]
    assert not top, top
