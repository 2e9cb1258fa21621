# Two commands on a fresh machine (see README.md):
#   make reproduce   set up .venv, then run the workflow on the embedded default config
#   make test        set up .venv with test tools, then pytest (with the end-to-end smoke run), lint, dry run
# While developing: make test-fast   the unit tests only (pytest -m "not slow": no workflow runs)
PYTHON ?= python3
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

.PHONY: reproduce test test-fast setup browser lint dryrun benchmark report clean

reproduce: $(STAMP)
	$(CHECK_CONFIG)
	$(SNAKEMAKE) --cores $(CORES) $(TARGET)

test: $(STAMP) browser
	$(PY) -m pytest -p no:dash
	$(SNAKEMAKE) --lint
	$(SNAKEMAKE) --dry-run --quiet rules --cores $(CORES) $(TARGET)

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
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e ".[test,viewer]"
	@$(PY) -c "import tohgs, torch, open3d, pybullet, coacd, snakemake, viser; print('tohgs environment ready: torch', torch.__version__)"
	@touch $@

# The viewer's tests (tests/test_viewer.py) load it in headless Chromium: Debian's package, installed as root;
# otherwise those tests skip, saying so.
browser:
	@if ! command -v chromium >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = "0" ]; then \
	    echo "installing chromium (the viewer's tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else \
	    echo "the viewer's browser tests need chromium (they skip without it): sudo apt-get install -y chromium" >&2; \
	  fi; \
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

clean:
	rm -rf results logs .snakemake
