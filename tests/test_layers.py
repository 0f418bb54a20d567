"""Imports point down the layers of the design (docs/api.md, "Layers"), with no cycles.

Every module's imports are read from its source (module level and inside
functions alike).  An import of a higher layer, or a cycle between modules,
fails with the importing module, the imported one and their layers.
"""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "clusterdyn"

#: ground up; a module may import its own layer (without cycles) and the layers below
LAYERS = [
    ("ground", ("clusterdyn", "clusterdyn.units", "clusterdyn.errors", "clusterdyn.parallel",
                "clusterdyn._openmp", "clusterdyn.fma")),
    ("materials", ("clusterdyn.materials",)),
    ("potentials", ("clusterdyn.potentials",)),
    ("build", ("clusterdyn.build",)),
    ("neighbors", ("clusterdyn.neighbors",)),
    ("engine", ("clusterdyn.engine",)),
    ("calculators", ("clusterdyn.calculators",)),
    ("md", ("clusterdyn.md",)),
    ("mca", ("clusterdyn.mca",)),
    ("io", ("clusterdyn.io",)),
    ("analysis", ("clusterdyn.analysis",)),
    ("scenes", ("clusterdyn.scenes",)),
    ("studies", ("clusterdyn.studies",)),
    ("cli", ("clusterdyn.cli",)),
]


def module_name(path, root=PKG):
    rel = path.relative_to(root.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def all_modules(root=PKG):
    return {module_name(p, root): p for p in sorted(root.rglob("*.py"))}


def layer_of(mod):
    best = None
    for k, (_, prefixes) in enumerate(LAYERS):
        for pre in prefixes:
            if (mod == pre or mod.startswith(pre + ".")) and (best is None or len(pre) > best[1]):
                best = (k, len(pre))
    if best is None:
        raise AssertionError(f"module {mod} belongs to no layer: add it to LAYERS")
    return best[0]


def imports_of(mod, path, modules):
    """(imported clusterdyn module, line) for every import statement in ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "clusterdyn":
                    out.append((_existing(a.name, modules), node.lineno))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "clusterdyn":
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                out.append((sub if sub in modules else _existing(target, modules), node.lineno))
    return out


def _existing(name, modules):
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name


def check_layers(root=PKG):
    """Problems (text lines): imports of higher layers and import cycles between modules."""
    modules = all_modules(root)
    graph = {m: set() for m in modules}
    problems = []
    for mod, path in modules.items():
        for target, line in imports_of(mod, path, modules):
            if not target or target == mod:
                continue
            graph[mod].add(target)
            lm, lt = layer_of(mod), layer_of(target)
            if lt > lm:
                problems.append(f"{path.relative_to(root.parent)}:{line}: {mod} ({LAYERS[lm][0]}) imports "
                                f"{target} ({LAYERS[lt][0]}), a higher layer")
    # cycles (Tarjan's strongly connected components)
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    for c in comps:
        problems.append("import cycle: " + " <-> ".join(c))
    return problems


def test_imports_point_down_without_cycles():
    problems = check_layers()
    assert not problems, "\n".join(problems)


def test_the_check_sees_an_upward_import_inside_a_function(tmp_path):
    root = tmp_path / "clusterdyn"
    (root / "md").mkdir(parents=True)
    (root / "io").mkdir()
    (root / "__init__.py").write_text("")
    (root / "md" / "__init__.py").write_text("")
    (root / "io" / "__init__.py").write_text("from ..md import damped\n")
    (root / "md" / "damped.py").write_text("def save():\n    from ..io import write\n")
    (root / "io" / "write.py").write_text("")
    problems = check_layers(root)
    assert any("clusterdyn.md.damped (md) imports clusterdyn.io.write (io), a higher layer" in p
               for p in problems), problems
    assert any(p.startswith("import cycle") for p in problems) is False


def test_the_check_sees_a_cycle(tmp_path):
    root = tmp_path / "clusterdyn"
    (root / "analysis").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "analysis" / "__init__.py").write_text("")
    (root / "analysis" / "a.py").write_text("from . import b\n")
    (root / "analysis" / "b.py").write_text("def f():\n    from .a import g\n")
    problems = check_layers(root)
    assert problems == ["import cycle: clusterdyn.analysis.a <-> clusterdyn.analysis.b"]


@pytest.mark.parametrize("mod,layer", [("clusterdyn.units", "ground"), ("clusterdyn.mca.state", "mca"),
                                       ("clusterdyn.scenes.mca", "scenes"), ("clusterdyn.cli", "cli")])
def test_layer_names(mod, layer):
    assert LAYERS[layer_of(mod)][0] == layer
