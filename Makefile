# colonbench: `make demo` runs the main job, `make test` the test suite.
# Both build the virtual environment .venv from nothing on first use.

PYTHON ?= python3
TORCH  ?= torch==2.13.0
# the recorded environment (package versions of the shipped results and published signatures); empty: unpinned
CONSTRAINTS ?= constraints.txt
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install test demo bench cards clean

$(STAMP): pyproject.toml scripts/system-deps.sh $(CONSTRAINTS)
	./scripts/system-deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	# PyTorch first, as TORCH says (it may carry pip options: PyPI's Linux wheel brings the CUDA libraries, the
	# CPU-only index's does not; README.md, Set up)
	$(BIN)/python -m pip install -q $(TORCH)
	$(BIN)/python -m pip install -q $(if $(CONSTRAINTS),-c $(CONSTRAINTS)) -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

demo: $(STAMP)
	$(BIN)/colonbench demo --out out/demo --workers 2

bench: $(STAMP)
	$(BIN)/python scripts/bench_datagen.py
	$(BIN)/python scripts/bench_shards.py --manifest data_manifests/paper.yaml --shards 2

# every suite's dataset card and Croissant metadata in docs/suites/ (tests/test_cards.py checks they are current)
cards: $(STAMP)
	$(BIN)/python scripts/suite_cards.py

clean:
	rm -rf $(VENV) out .pytest_cache *.egg-info
