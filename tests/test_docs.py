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
