"""The docs' reference tables are the code's."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("script, doc", [("config_table.py", "datagen.md"), ("schema_table.py", "shards.md")])
def test_reference_tables_in_docs_are_current(script, doc):
    spec = importlib.util.spec_from_file_location(script[:-3], ROOT / "scripts" / script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    text = (ROOT / "docs" / doc).read_text()
    assert mod.tables().strip() in text, f"regenerate docs/{doc}'s tables with: python scripts/{script}"


def test_the_plugin_example_in_the_docs_runs_through_evaluate(smoke_dataset, tmp_path, monkeypatch):
    import re
    import sys

    from colonbench.benchmark.evaluate import evaluate, load_results

    text = (ROOT / "docs" / "benchmark.md").read_text()
    code = re.search(r"<!-- example: my_methods.py -->\n```python\n(.*?)```", text, re.S).group(1)
    (tmp_path / "my_methods.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("my_methods", None)
    data, _ = smoke_dataset
    run = evaluate(data, ["my_methods:CoarseUnwrap"], tmp_path / "run", noise=(0,), progress=False)
    meta, res = load_results(run)
    assert meta["methods"]["coarse-unwrap"]["version"] == "0.1"
    assert (res["error"] == "").all() and res["coverage"].between(0, 1).all()


def test_the_results_tables_are_the_shipped_results():
    spec = importlib.util.spec_from_file_location("results_table", ROOT / "scripts" / "results_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.tables().strip() in (ROOT / "README.md").read_text(), \
        "regenerate README.md's results table with: python scripts/results_table.py"
    assert mod.interval_table().strip() in (ROOT / "docs" / "method.md").read_text(), \
        "regenerate docs/method.md's intervals table with: python scripts/results_table.py --intervals"
    assert mod.accuracy_table().strip() in (ROOT / "docs" / "method.md").read_text(), \
        "regenerate docs/method.md's accuracy table with: python scripts/results_table.py --accuracy"


def test_what_the_docs_python_examples_import_exists():
    """Every import line of a Python example in README.md and docs/*.md (decision records aside) imports."""
    import re

    lines = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for block in re.findall(r"```python\n(.*?)```", doc.read_text(), re.S):
            lines += [(doc.name, x.strip()) for x in block.splitlines()
                      if re.match(r"\s*(from colonbench[\w.]* import [\w, ]+|import colonbench[\w.]*( as \w+)?)\s*$", x)]
    assert len(lines) >= 10, lines
    for doc, line in lines:
        try:
            exec(line, {})
        except ImportError as exc:
            pytest.fail(f"{doc}: {line}: {exc}")


def test_the_readme_stays_a_front_door():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines; move the detail into docs/"
    assert max(len(x) for x in lines) <= 400
