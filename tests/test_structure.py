"""The code's shape, read from its syntax trees: the packages' layers point one way, no function
outside tests/ and benchmarks/ is longer than 80 lines and no such file longer than 700."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bayesmachine", "hdl", "sim", "host", "fpga")  # bayesmachine.* is mapped onto the last four

# What each layer may import besides itself: the core package (``bayesmachine/`` but its command
# line) under hdl, under sim, under host and fpga, which do not import each other (the board is a
# pixel engine, reached by name through sim.engines' registry; the command line hands host's work
# to fpga). The command line (bayesmachine/cli.py, __main__.py) sees everything.
MAY_IMPORT = {
    "core": set(),
    "hdl": {"core"},
    "sim": {"core", "hdl"},
    "host": {"core", "hdl", "sim"},
    "fpga": {"core", "hdl", "sim"},
    "cli": {"core", "hdl", "sim", "host", "fpga"},
}
# The modules that import by name at run time: the integrator registry (its kinds' tops, models and
# engines, and the pixel engines' registry in sim/engines.py through it) and the optional dependencies.
DYNAMIC_IMPORTS = {"bayesmachine/integrators/__init__.py", "bayesmachine/extras.py"}

MAX_LINES = 80
MAX_FILE_LINES = 700


def _layer(rel: Path) -> str:
    if rel.parts[0] == "bayesmachine":
        return "cli" if rel.name in ("cli.py", "__main__.py") and len(rel.parts) == 2 else "core"
    return rel.parts[0]


def _module_layer(name: str) -> str | None:
    """The layer of an absolute module name, None outside the project."""
    parts = name.split(".")
    if parts[0] != "bayesmachine":
        return None
    if len(parts) == 1:
        return "core"
    if parts[1] in ("hdl", "sim", "host", "fpga"):
        return parts[1]
    return "cli" if parts[1] in ("cli", "__main__") else "core"


def imports(path: Path, package_parts: tuple[str, ...]) -> Iterator[tuple[int, str]]:
    """(line, absolute module) of every import in ``path``, at any depth (function-level ones too);
    ``package_parts``: the file's package as imported (``("bayesmachine", "fpga", "boards")``)."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(package_parts[: len(package_parts) - node.level + 1])
                yield node.lineno, ".".join(base + ([node.module] if node.module else []))
            else:
                yield node.lineno, node.module or ""


def _sources(*skip: str) -> Iterator[tuple[Path, Path]]:
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if not any(part in skip or part.startswith(".") for part in rel.parts):
                yield path, rel


def _package_parts(rel: Path) -> tuple[str, ...]:
    parts = rel.with_suffix("").parts[:-1]
    return parts if parts[0] == "bayesmachine" else ("bayesmachine", *parts)


def test_the_walker_sees_every_import(tmp_path: Path) -> None:
    src = tmp_path / "x.py"
    src.write_text("import os\nfrom . import protocol\n\ndef f():\n    from ..link import run\n"
                   "    import bayesmachine.host.run as r\n")
    got = list(imports(src, ("bayesmachine", "fpga", "boards")))
    assert got == [(1, "os"), (2, "bayesmachine.fpga.boards"), (5, "bayesmachine.fpga.link"),
                   (6, "bayesmachine.host.run")]
    assert _layer(Path("fpga/boards/x.py")) == "fpga" and _layer(Path("bayesmachine/cli.py")) == "cli"
    assert _layer(Path("bayesmachine/sources/cli.py")) == "core"


def test_layers_point_one_way() -> None:
    wrong = []
    for path, rel in _sources("__pycache__"):
        layer = _layer(rel)
        for line, module in imports(path, _package_parts(rel)):
            target = _module_layer(module)
            if target is not None and target != layer and target not in MAY_IMPORT[layer]:
                wrong.append(f"{rel}:{line}: {layer} imports {module}")
    assert not wrong, "imports against the layers:\n" + "\n".join(wrong)


def test_only_the_engine_registry_imports_by_name() -> None:
    found = [f"{rel}:{node.lineno}" for path, rel in _sources("__pycache__")
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Attribute) and node.attr == "import_module"
             and str(rel) not in DYNAMIC_IMPORTS]
    assert not found, f"import_module outside the engine registry: {found}"


def _functions(tree: ast.AST, prefix: str = "") -> Iterator[tuple[str, ast.AST]]:
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node
            yield from _functions(node, f"{prefix}{node.name}.")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, f"{prefix}{node.name}.")


def test_functions_are_at_most_80_lines() -> None:
    long = []
    for path, rel in _sources("__pycache__", "tests", "benchmarks"):
        for name, node in _functions(ast.parse(path.read_text())):
            lines = node.end_lineno - node.lineno + 1  # type: ignore[attr-defined]
            if lines > MAX_LINES:
                long.append(f"{rel}:{node.lineno} {name}: {lines} lines")  # type: ignore[attr-defined]
    assert not long, f"functions over {MAX_LINES} lines:\n" + "\n".join(long)


def test_files_are_at_most_700_lines() -> None:
    long = [f"{rel}: {n} lines" for path, rel in _sources("__pycache__", "tests", "benchmarks")
            if (n := len(path.read_text().splitlines())) > MAX_FILE_LINES]
    assert not long, f"files over {MAX_FILE_LINES} lines:\n" + "\n".join(long)


def test_the_registries_name_classes_that_exist() -> None:
    """The registries' import paths are right (the layering test cannot see them): every kind's top,
    model and engines, and the pixel engines."""
    from bayesmachine.integrators import INTEGRATOR_KINDS, load_named
    from bayesmachine.sim.engines import _PIXEL_ENGINES

    for kind in INTEGRATOR_KINDS.values():
        for target in (kind.top, kind.model, *kind.engines.values()):
            assert isinstance(load_named(target), type), target
    for target in _PIXEL_ENGINES.values():
        assert isinstance(load_named(target), type), target



# Amaranth's undocumented internals the formal wrappers once reached through (the blocks' ``nets`` and
# hooks replace them): a wrapper that needs a block's net asks the block.
INTERNALS = {"statements", "origins", "find_subfragment", "subfragments"}


def _imported_names(tree: ast.AST) -> set[str]:
    return {alias.asname or alias.name.split(".")[0] for node in ast.walk(tree)
            if isinstance(node, (ast.Import, ast.ImportFrom)) for alias in node.names}


def _private_reads(tree: ast.AST) -> Iterator[tuple[int, str]]:
    """(line, what) of every read of another object's private name or of a Fragment internal, and of
    every assignment to an attribute of an imported module or class (a monkeypatch)."""
    imported = _imported_names(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            private = node.attr.startswith("_") and not node.attr.startswith("__")
            own = isinstance(node.value, ast.Name) and node.value.id == "self"
            if (private and not own) or node.attr in INTERNALS:
                yield node.lineno, f".{node.attr}"
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id in imported:
                    yield node.lineno, f"{t.value.id}.{t.attr} ="


def test_the_formal_wrappers_read_no_private_attribute() -> None:
    """hdl/formal uses only documented names: no ``x._name`` but on ``self`` (its own state), no
    Fragment internals, no monkeypatched module or class (a mutant is a subclass using a hook)."""
    found = [f"{rel}:{line} {what}" for path, rel in _sources("__pycache__")
             if rel.parts[:2] == ("hdl", "formal")
             for line, what in _private_reads(ast.parse(path.read_text()))]
    assert not found, f"private or internal reads in hdl/formal: {found}"


def test_the_private_read_check_sees_them() -> None:
    src = ("from bayesmachine.hdl.frontend import stereo as _stereo\n"
           "m._statements\nstmt._lhs_signals()\nfrag.origins\nself._params\n_stereo.FeaturePipeline = 1\n"
           "m.submodules.dut = 1\n")
    assert [what for _, what in sorted(_private_reads(ast.parse(src)))] == [
        "._statements", "._lhs_signals", ".origins", "_stereo.FeaturePipeline ="]


# Where an integrator may be named in a comparison: its registry, and each kind's own modules (its blocks,
# its model).
INTEGRATOR_HOMES = ("bayesmachine/integrators/", "hdl/log/", "sim/log_model.py")


def _names_an_integrator(node: ast.AST, names: frozenset[str]) -> bool:
    """Whether ``node`` is an integrator's name (a string of ``INTEGRATORS``, ``DEFAULT_INTEGRATOR``), a
    kind itself (``LOG``) or reads a machine's ``integrator`` (``p.integrator``, ``d["integrator"]``,
    ``d.get("integrator")``)."""
    named = {"DEFAULT_INTEGRATOR", "integrator", *(n.upper() for n in names)}
    if isinstance(node, ast.Constant):
        return node.value in names
    if isinstance(node, ast.Name):
        return node.id in named
    if isinstance(node, ast.Attribute):
        return node.attr in named
    key = None
    if isinstance(node, ast.Subscript):
        key = node.slice
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get":
        key = node.args[0] if node.args else None
    return isinstance(key, ast.Constant) and key.value == "integrator"


def integrator_branches(tree: ast.AST, names: frozenset[str]) -> Iterator[int]:
    """The lines of ``tree`` that compare with an integrator's name (``==``, ``!=``, ``in``) or key a
    mapping on one: a choice the integrator kind should make."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            if any(_names_an_integrator(n, names) for n in (node.left, *node.comparators)):
                yield node.lineno
        elif isinstance(node, ast.Dict):
            if any(k is not None and isinstance(k, ast.Constant) and k.value in names for k in node.keys):
                yield node.lineno


def test_the_branch_scan_sees_a_branch() -> None:
    names = frozenset(("stochastic", "log"))
    code = ("a = p.integrator == 'log'\nb = d.get('integrator') != x\nc = 'log' in kinds\n"
            "e = {'stochastic': 1}\nf = p.kind is LOG\ng = p.kind.loads == 'codes'\n"
            "h = 'integrator' in axes\n")
    assert list(integrator_branches(ast.parse(code), names)) == [1, 2, 3, 4, 5]


def test_no_branch_on_an_integrator_s_name_outside_its_kind() -> None:
    """Commands, engines, the front end and the host ask the integrator's kind (``MachineParams.kind``),
    never compare its name: a new integrator is its kind's module and its blocks."""
    from bayesmachine.params import INTEGRATORS

    names = frozenset(INTEGRATORS)
    found = [f"{rel}:{line}" for path, rel in _sources("__pycache__", "tests")
             if not str(rel).startswith(INTEGRATOR_HOMES)
             for line in integrator_branches(ast.parse(path.read_text()), names)]
    assert not found, "branches on an integrator's name:\n" + "\n".join(found)
