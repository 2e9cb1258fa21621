# Two commands on a fresh machine (see README.md; `make` alone prints the targets):
#   make reproduce   set up .venv, then run the workflow on the embedded default config
#   make test        set up .venv with test tools, then pytest (with the end-to-end smoke run), lint, dry run
# While developing: make test-fast   the unit tests only (pytest -m "not slow": no workflow runs)
PYTHON ?= python3
# the Pythons tohgs supports (pyproject.toml's requires-python)
SUPPORTED := 3.11 3.12 3.13
# where a pybullet wheel built from source is kept (no PyPI wheel for Python 3.12+): outside the venv, reused
WHEEL_CACHE ?= $(HOME)/.cache/tohgs/wheels
VENV ?= .venv
CORES ?= 2
TARGET ?= all
# config files merged over the default, in order (e.g. make reproduce CONFIG=config/extras.yaml): each is
# checked first (python -m tohgs.config_files), since Snakemake merges them before the workflow's checks run
CONFIG ?=
PY := $(VENV)/bin/python
SNAKEMAKE := $(PY) -m snakemake$(if $(strip $(CONFIG)), --configfile $(CONFIG))
CHECK_CONFIG := $(if $(strip $(CONFIG)),$(PY) -m tohgs.config_files $(CONFIG),@true)
STAMP := $(VENV)/.tohgs-setup
LINT_VENV ?= .venv-lint

# a second interpreter for the unit tests that make test runs after its own (where CI is set: the newest 3.13 or
# 3.12 of the image's pyenv, in .venv-second, pybullet from the wheel cache); empty: none, said so
SECOND_PYTHON ?= $(if $(CI),$(lastword $(sort $(wildcard $(HOME)/.pyenv/versions/3.12.*/bin/python \
	$(HOME)/.pyenv/versions/3.13.*/bin/python))))
# the index torch 2.13.0 comes from: empty, pip's own (PyPI: on most machines the CUDA build, several GB);
# https://download.pytorch.org/whl/cpu for the CPU build (about 200 MB) on a machine without a GPU
TORCH_INDEX ?=
TORCH_SOURCE = $(if $(strip $(TORCH_INDEX)),$(TORCH_INDEX),pip's index (on most machines the CUDA build$(comma) several GB; \
	make TORCH_INDEX=https://download.pytorch.org/whl/cpu takes the CPU build))
comma := ,
# system packages that only the tests need (chromium for the viewer's browser tests; SLURM, MariaDB and munge
# for the real SLURM run), installed by make test as root: yes where CI is set, otherwise no (those tests skip)
SYSTEM_PACKAGES ?= $(if $(CI),yes,no)

.PHONY: help reproduce test test-fast setup browser lint benchmark report clean

help:
	@echo "tohgs: task-oriented human grasp synthesis as a Snakemake workflow (README.md)"
	@echo ""
	@echo "  make reproduce    set up .venv, then run the whole workflow on the embedded default"
	@echo "                    (config/config.yaml): about 235 job-minutes, 2-2.5 h on 2 cores"
	@echo "  make test         set up .venv with the test tools, then pytest with the end-to-end smoke run,"
	@echo "                    snakemake --lint and a dry run: about 25-30 min on 2 cores"
	@echo "  make test-fast    the unit tests only (no workflow runs): about 3 min"
	@echo "  make lint         snakemake --lint in .venv and in a venv of Snakemake alone (.venv-lint), snakefmt"
	@echo "  make setup        only the environment (.venv)"
	@echo "  make report       the HTML report of a finished run (results/report.html)"
	@echo "  make benchmark    the stage benchmarks (benchmarks/results/*.json)"
	@echo "  make clean        remove results/, logs/ and .snakemake/"
	@echo ""
	@echo "Variables: TARGET=<file or rule> (default all), CONFIG=\"FILE...\" (config files over the default,"
	@echo "checked first), CORES=$(CORES), PYTHON=$(PYTHON), TORCH_INDEX=<pip index of torch>,"
	@echo "SYSTEM_PACKAGES=yes|no (make test as root: install chromium and SLURM for their tests; now $(SYSTEM_PACKAGES)),"
	@echo "SECOND_PYTHON=<interpreter> (make test runs the unit tests again with it; now $(or $(SECOND_PYTHON),none))"

reproduce: $(STAMP)
	$(CHECK_CONFIG)
	$(SNAKEMAKE) --cores $(CORES) $(TARGET)

test: $(STAMP) browser
	$(if $(filter yes,$(SYSTEM_PACKAGES)),,TOHGS_SLURM_TEST=0 )$(PY) -m pytest -p no:dash
	$(MAKE) --no-print-directory lint
	$(SNAKEMAKE) --dry-run --quiet rules --cores $(CORES) $(TARGET)
	@if [ -n "$(strip $(SECOND_PYTHON))" ]; then \
	  echo "the unit tests again with a second Python, $(SECOND_PYTHON) (SECOND_PYTHON; in .venv-second)"; \
	  $(MAKE) --no-print-directory test-fast VENV=.venv-second PYTHON=$(SECOND_PYTHON); \
	else \
	  echo "SECOND_PYTHON is empty: the unit tests ran with one Python (make test SECOND_PYTHON=python3.13 adds one)"; \
	fi

# snakemake --lint twice: in .venv, and in .venv-lint, which has nothing but Snakemake (this .venv's version):
# the workflow parses without the project's packages, as the Snakemake workflow catalogue checks it; then snakefmt
lint: $(STAMP)
	$(SNAKEMAKE) --lint
	@v=$$($(PY) -c 'import importlib.metadata as m; print(m.version("snakemake"))'); \
	if ! test -x $(LINT_VENV)/bin/snakemake || [ "$$($(LINT_VENV)/bin/snakemake --version)" != "$$v" ]; then \
	  echo "$(LINT_VENV): a venv with only snakemake $$v, for the lint a bare Snakemake environment gives"; \
	  rm -rf $(LINT_VENV) && $(PY) -m venv $(LINT_VENV) && $(LINT_VENV)/bin/python -m pip install -q "snakemake==$$v"; \
	fi
	$(LINT_VENV)/bin/snakemake --lint
	$(VENV)/bin/snakefmt --check workflow

# the unit tests without the slow ones (the end-to-end workflow runs, marked slow: pyproject.toml)
test-fast: $(STAMP)
	$(PY) -m pytest -p no:dash -m "not slow"

setup: $(STAMP)

# open3d needs the system library libusb-1.0; torch is pinned to the CPU build 2.13.0 (pyproject.toml).
$(STAMP): pyproject.toml
	@if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then \
	  if [ "$$(id -u)" = "0" ]; then \
	    echo "installing libusb-1.0-0 (needed by open3d)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	  else \
	    echo "open3d needs libusb-1.0-0; run: sudo apt-get install -y libusb-1.0-0" >&2; exit 1; \
	  fi; \
	fi
	@if ! test -x $(PY); then \
	  v=$$($(PYTHON) -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null) || { \
	    echo "no Python at PYTHON=$(PYTHON): tohgs needs Python $(SUPPORTED); pick one with make PYTHON=python3.12" >&2; exit 1; }; \
	  case " $(SUPPORTED) " in *" $$v "*) ;; *) \
	    echo "tohgs needs Python $(SUPPORTED), and $(PYTHON) is $$v: pick one with make PYTHON=python3.12 (Debian 13" \
	         "ships 3.13, Ubuntu 24.04 3.12; elsewhere: uv python install 3.12, or pyenv)" >&2; exit 1;; esac; \
	  $(PYTHON) -m venv $(VENV); \
	fi
	$(PY) -m pip install -q --upgrade pip
	@echo "torch 2.13.0 from $(TORCH_SOURCE)"
	$(PY) -m pip install -q $(if $(strip $(TORCH_INDEX)),--index-url $(TORCH_INDEX) )torch==2.13.0
	scripts/pybullet_wheel.sh $(PY) $(WHEEL_CACHE)
	$(PY) -m pip install -q --find-links $(WHEEL_CACHE) -e ".[test,viewer]"
	@$(PY) -c "import tohgs, torch, open3d, pybullet, coacd, snakemake, viser; print('tohgs environment ready: torch', torch.__version__)"
	@touch $@

# The viewer's tests (tests/test_viewer.py) load it in headless Chromium: Debian's package, installed as root
# with SYSTEM_PACKAGES=yes (said before it starts); otherwise those tests skip, saying so. The same variable
# lets tests/test_workflow.py install and start a one-node SLURM cluster (scripts/local_slurm.sh).
browser:
	@if command -v chromium >/dev/null 2>&1; then :; \
	elif [ "$(SYSTEM_PACKAGES)" != "yes" ]; then \
	  echo "no chromium: the viewer's browser tests skip (make test SYSTEM_PACKAGES=yes installs it as root)"; \
	elif [ "$$(id -u)" = "0" ]; then \
	  echo "SYSTEM_PACKAGES=yes: installing chromium (apt-get) for the viewer's browser tests"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	else \
	  echo "the viewer's browser tests need chromium (they skip without it): sudo apt-get install -y chromium" >&2; \
	fi
	@if [ "$(SYSTEM_PACKAGES)" = "yes" ]; then \
	  echo "SYSTEM_PACKAGES=yes: the SLURM test installs (as root, apt-get) and starts slurm-wlm, MariaDB and munge" \
	       "(scripts/local_slurm.sh) and stops them after"; \
	else \
	  echo "SYSTEM_PACKAGES=no: the real SLURM run skips (make test SYSTEM_PACKAGES=yes installs and starts SLURM for it)"; \
	fi

# the HTML report of a finished run: tables and figures with their captions (workflow/report/)
report: $(STAMP)
	$(CHECK_CONFIG)
	$(SNAKEMAKE) --report results/report.html $(TARGET)

benchmark: $(STAMP)
	$(PY) benchmarks/bench_objects.py
	$(PY) benchmarks/bench_hand.py
	$(PY) benchmarks/bench_metrics.py
	$(PY) benchmarks/bench_sdf.py
	$(PY) benchmarks/bench_prior.py
	$(PY) benchmarks/bench_maps.py
	$(PY) benchmarks/bench_contact_diffuser.py

clean:
	rm -rf results logs .snakemake
