# drillcosim: `make run` and `make test` work on a fresh machine (Python >= 3.10, pip, a C compiler).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# the Python FMUs: the plant and one per registered controller law (fmu_src/build.py REGISTRY)
FMUS := build/fmus/.python-fmus
C_FMUS := build/fmus/StrainControllerC.fmu
SRC := $(shell find plant controller fmu_src -name '*.py' -o -name '*.c' -o -name '*.h' -o -name '*.json' 2>/dev/null)
C_SRC := $(wildcard fmu_src/c_controller/*.c fmu_src/c_controller/*.h fmu_src/c_controller/*.xml fmu_src/wrapper/fmi2/*.h fmu_src/wrapper/dcs_registry.* fmu_src/wrapper/dcs_lock.h) fmu_src/build_c.py

.PHONY: all install fmus run test docs lint bench clean windows-bench

all: install fmus

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# -qq: pip's errors only (setuptools' 10-line notice on every editable install is not for users)
$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install -qq -e '.[test,docs]'
	@touch $(STAMP)

install: $(STAMP)

$(FMUS): $(STAMP) $(SRC) $(wildcard scenes/*.toml)
	$(BIN)/python -m drillcosim.fmu_src.build --out build/fmus
	touch $(FMUS)

$(C_FMUS): $(STAMP) $(C_SRC)
	$(BIN)/python -m drillcosim.fmu_src.build_c --out build/fmus

fmus: $(FMUS) $(C_FMUS)

run: install fmus
	$(BIN)/drillcosim run

test: install fmus
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n auto --dist loadfile --durations=12

# the documentation site (HTML) into build/docs; notebooks executed, cached by their content
# (build/docs_cache); make test builds it too, warnings as errors (tests/test_docs.py)
docs: install fmus
	$(BIN)/python -m sphinx -b html -n -W --keep-going -q docs build/docs
	@echo "build/docs/index.html"

# The Windows bench of the tests (wine + the embeddable CPython for Windows + win_amd64 wheels,
# fetched once into $DRILLCOSIM_WINDOWS_BENCH, default ~/.cache/drillcosim-windows-bench).
windows-bench: install
	$(BIN)/python tests/support/windows_bench.py prepare

bench: install fmus
	$(BIN)/drillcosim bench

clean:
	rm -rf build out .pytest_cache
