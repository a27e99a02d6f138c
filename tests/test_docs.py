"""The docs' configuration tables are the code's."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_config_tables_in_docs_are_current():
    import importlib.util

    spec = importlib.util.spec_from_file_location("config_table", ROOT / "scripts" / "config_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    doc = (ROOT / "docs" / "datagen.md").read_text()
    if not doc.strip():
        pytest.fail("docs/datagen.md is empty")
    assert mod.tables().strip() in doc, "regenerate with: python scripts/config_table.py"
