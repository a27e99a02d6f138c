"""The house rules: imports run one way along the data flow, no private name crosses a package, modules stay small."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Folders in data-flow order: a package may import its own layer and the layers before it, never after.
#: The methods (completion, baselines) and the whole-colon map sit side by side; the command line, the pipelines
#: that span the layers (colonbench.pipeline) and the package's facade (colonbench/__init__.py) sit on top; the
#: evaluation server (server/) is the last room, over the benchmark and its reports.
LAYERS = {"colonbench": 0, "datagen": 1, "video": 2, "shards": 3, "completion": 4, "baselines": 4, "mapping": 5,
          "benchmark": 6, "reports": 7, "server": 8}
TOP = ("colonbench.cli", "colonbench.commands", "colonbench.pipeline")
FOLDER = {"colonbench": "colonbench", **{k: k for k in LAYERS if k != "colonbench"}}
MAX_LINES = 500


def _modules():
    for pkg, folder in FOLDER.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            name = ".".join(["colonbench"] + ([] if pkg == "colonbench" else [pkg]) + list(rel.parts))
            yield pkg, name.removesuffix(".__init__"), path


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("colonbench"):
            yield node.module, [a.name for a in node.names], node.lineno
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("colonbench"):
                    yield a.name, [], node.lineno


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else "colonbench"


def test_imports_run_one_way():
    wrong = []
    for pkg, name, path in _modules():
        if name.startswith(TOP) or name == "colonbench":
            continue
        for module, names, line in _imports(path):
            target = _package(module)
            if module.startswith(TOP) or LAYERS[target] > LAYERS[pkg]:
                wrong.append(f"{path.relative_to(ROOT)}:{line} ({pkg}) imports {module}")
    assert not wrong, "imports against the data flow:\n" + "\n".join(wrong)


def test_no_private_name_crosses_a_package():
    wrong = []
    for pkg, name, path in _modules():
        for module, names, line in _imports(path):
            if _package(module) != pkg and not name.startswith(TOP):
                wrong += [f"{path.relative_to(ROOT)}:{line} imports {module}.{n}" for n in names if n.startswith("_")
                          and n != "__version__"]
    assert not wrong, "private names imported across packages:\n" + "\n".join(wrong)


def test_modules_stay_under_500_lines():
    files = [p for _, _, p in _modules()] + sorted((ROOT / "tests").glob("*.py")) + sorted(
        (ROOT / "scripts").glob("*.py"))
    long = [f"{p.relative_to(ROOT)}: {n}" for p in files if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, "modules over 500 lines:\n" + "\n".join(long)
