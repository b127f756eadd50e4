# stringcast: `make demo` runs the demo campaign, `make test` the tests.
# Both create (or reuse) the virtual environment .venv and install the project.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast test-core bench bench-quick lint clean venv browser slurm lock

venv: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[lab,test]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/stringcast campaign demo --string 1 --target 1

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile -q

test-fast: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile -q -m "not slow"

# The pipeline as a lab with a real arm installs it (no lab extra: no MuJoCo, PyElastica or PyAV), in
# its own venv: the test modules that do not use the virtual lab (tests/conftest.py leaves the others
# out), and `stringcast next` on the field recording (tests/test_next_core.py).
VENV_CORE := .venv-core
test-core:
	test -x $(VENV_CORE)/bin/python || $(PYTHON) -m venv $(VENV_CORE)
	$(VENV_CORE)/bin/python -m pip install --quiet --upgrade pip
	$(VENV_CORE)/bin/python -m pip install --quiet -c constraints.txt -e ".[test]"
	! $(VENV_CORE)/bin/python -c "import mujoco" 2>/dev/null
	$(VENV_CORE)/bin/python -m pytest -n 2 --dist loadfile -q -m "not slow" tests

bench: $(STAMP)
	$(PY) -m benchmarks.run

bench-quick: $(STAMP)
	$(PY) -m benchmarks.run --quick

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/snakemake --lint
	$(VENV)/bin/snakefmt --check Snakefile workflow/

# Headless Chromium for the report tests (Debian's package; needs root, else install it yourself).
browser:
	@command -v chromium-headless-shell >/dev/null || command -v chromium >/dev/null || \
	  { if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	      apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium-headless-shell >/dev/null; \
	    else echo "make browser: install Debian's chromium-headless-shell (or chromium) as root"; exit 1; fi; }

# A real one-node Slurm cluster with accounting, for the Slurm test (tests/workflow/test_slurm.py):
# Debian's slurmctld, slurmd, slurmdbd, MariaDB and munge, installed and started by .ci/slurm/setup.sh
# (needs root and apt-get; quick and harmless on a running cluster). docs/slurm.md explains it.
slurm:
	.ci/slurm/setup.sh

# Re-pin constraints.txt to what .venv holds now (after a deliberate upgrade; then re-run the benchmarks).
lock: $(STAMP)
	{ sed -n '/^#/p' constraints.txt; $(PY) -m pip freeze --exclude-editable; } > constraints.txt.tmp && mv constraints.txt.tmp constraints.txt

clean:
	rm -rf results .snakemake
