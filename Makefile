# grasplan: two commands set everything up on a fresh machine.
#   make demo   - create .venv, install grasplan (runtime only, numba kernels compiled), run the main job on examples/parts/bracket.stl
#   make test   - also install the test tools (pytest, hypothesis, mypy, Ray, build), run the whole test suite
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test
OUT    ?= out
#: what `make install` puts in .venv: grasplan, its dependencies and the HTTP service (grasplan serve)
RUNTIME_EXTRAS := serve
#: what `make test` adds: the test extra (pytest, hypothesis, mypy, Ray, build)
TEST_EXTRAS    := test,serve

.PHONY: install install-test demo test typecheck bench parts wheel fuzz clean

install: $(STAMP)

install-test: $(TEST_STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[$(RUNTIME_EXTRAS)]'
	@# compiles the numba kernels into numba's cache now rather than in the first plan; never fails the install
	-$(PY) -m grasplan.cli.warmup || echo "grasplan: numba kernels not cached; the first plan or pick compiles them"
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[$(TEST_EXTRAS)]'
	touch $(TEST_STAMP)

parts: install
	$(PY) examples/make_parts.py

demo: install
	@mkdir -p $(OUT)
	$(VENV)/bin/grasplan plan examples/parts/bracket.stl --robot ur5 --units mm -o $(OUT)/bracket_plan.json
	$(VENV)/bin/grasplan export $(OUT)/bracket_plan.json --format urscript -o $(OUT)/bracket_grasp.script
	$(VENV)/bin/grasplan view $(OUT)/bracket_plan.json -o $(OUT)/bracket_view.html
	@echo "Viewer: $(abspath $(OUT)/bracket_view.html)"

test: install-test
	$(VENV)/bin/mypy
	$(PY) -m pytest -n 2 -q

typecheck: install-test
	$(VENV)/bin/mypy

wheel: install-test
	$(PY) -m build --wheel --outdir dist .
	@rm -rf build
	@ls -1 dist/*.whl

bench: install
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .hypothesis build dist
