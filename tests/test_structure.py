"""The code's shape, as the design card fixes it: modules of at most about 500 lines, kernels launched with at most
about 8 arguments, no import circles among the project's modules."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"tbd_taichi": ROOT / "tbd_taichi", "tbd_taichi.kernels": ROOT / "kernels"}
MAX_MODULE_LINES = 500
MAX_KERNEL_ARGUMENTS = 9  # "about 8": a pair step takes its second pool besides the eight of a single step

pytestmark = pytest.mark.skipif(not (ROOT / "kernels").is_dir(), reason="needs the source tree")


def project_modules() -> dict:
    """{dotted module name: path} of every module of the package and of its kernels."""
    out = {}
    for package, folder in PACKAGES.items():
        for path in sorted(folder.rglob("*.py")):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def imported_modules(name: str, path: Path, modules: dict) -> set:
    """The project modules that module ``name`` imports when it is imported (top-level statements only: an import
    inside a function runs later, so it cannot close a circle)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if is_package(path) else name.rpartition(".")[0]
    found = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in modules else base)
    return {m for m in found if m in modules and m != name}


def test_no_module_over_about_500_lines():
    long = {name: n for name, path in project_modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def kernel_arguments(path: Path) -> dict:
    """{kernel name: its argument names, ``self`` left out} of the ``@ti.kernel`` functions in ``path``."""
    out = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.FunctionDef) and any(ast.unparse(d) == "ti.kernel" for d in node.decorator_list):
            out[node.name] = [a.arg for a in node.args.args if a.arg != "self"]
    return out


def test_kernels_are_launched_with_few_arguments():
    kernels = {f"{name}.{k}": args for name, path in project_modules().items()
               for k, args in kernel_arguments(path).items()}
    assert len(kernels) > 20, "the kernels were not found"
    wide = {k: len(args) for k, args in kernels.items() if len(args) > MAX_KERNEL_ARGUMENTS}
    assert not wide, f"kernels with more than {MAX_KERNEL_ARGUMENTS} arguments: {wide}"


def test_the_test_finds_a_wide_kernel(tmp_path):
    path = tmp_path / "wide.py"
    path.write_text("import taichi as ti\n@ti.kernel\ndef k(" + ", ".join(f"a{i}: ti.i32" for i in range(12))
                    + "):\n    pass\n")
    assert len(kernel_arguments(path)["k"]) == 12


def import_circle(graph: dict):
    """One circle of ``graph`` {module: imported modules} as a list of modules, or None."""
    state = {}

    def visit(node, trail):
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return trail[trail.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt, trail + [nxt])
                if found:
                    return found
        state[node] = "done"
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start, [start])
            if found:
                return found
    return None


def test_no_import_circles():
    modules = project_modules()
    graph = {name: imported_modules(name, path, modules) for name, path in modules.items()}
    assert sum(map(len, graph.values())) > 50, "the imports were not found"
    circle = import_circle(graph)
    assert circle is None, "import circle: " + " → ".join(circle)


def test_the_circle_check_finds_a_circle():
    assert import_circle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert import_circle({"a": {"b"}, "b": set()}) is None
