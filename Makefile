# Two commands for a newcomer: `make demo` and `make test`. Each sets up .venv first.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint venv clean test-bsk demo-bus bench-bus interop openmct browser \
	screenshots

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg rwa_monitor/core/_stepcall.c \
		rwa_monitor/telemetry/_packetwalk.c
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade --quiet pip
	$(PY) -m pip install --quiet -r requirements.txt
	$(PY) -m pip install --quiet --no-deps -e .
	$(PY) -m rwa_monitor.cli.compile_kernels   # once per machine: the first command answers at once
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/rwa-monitor demo

# Readers and clients the project did not write (npm), for the interop tests; skipped
# without npm.
INTEROP := test/interop/node_modules/.installed

# Test files run in parallel, each file whole on one worker (its module fixtures built
# once); ROS tests lease their own domain id (test/ros_harness.py).
TEST_WORKERS ?= 2

# numba keys a cached kernel to its own file only: a kernel compiled inline into another
# module keeps the old code after an edit. Machine code older than the newest source of
# the package is dropped before the tests (compiled again at first use).
test: $(STAMP) interop openmct browser
	@newest=$$(ls -t $$(find rwa_monitor -name '*.py') | head -1); \
	find rwa_monitor -name '*.nb[ic]' ! -newer "$$newest" -delete
	$(PY) -m pytest test -n $(TEST_WORKERS) --dist loadfile

interop:
	@if command -v npm >/dev/null 2>&1; then $(MAKE) --no-print-directory $(INTEROP); \
	else echo 'npm not found: the @mcap/core and @foxglove/ws-protocol interop tests will be skipped'; fi

$(INTEROP): test/interop/package.json test/interop/package-lock.json
	cd test/interop && npm ci --no-audit --no-fund --silent
	touch $(INTEROP)

# The operator's view (rwa-monitor openmct): the Open MCT bundle pinned by its lock file,
# installed from the npm registry into a folder git ignores (rwa_monitor/openmct/bundle.py
# says how the command finds it); skipped without npm (the command then says so).
OPENMCT := rwa_monitor/openmct/npm/node_modules/.installed

openmct:
	@if command -v npm >/dev/null 2>&1; then $(MAKE) --no-print-directory $(OPENMCT); \
	else echo 'npm not found: rwa-monitor openmct and its browser tests need Open MCT (npm)'; fi

$(OPENMCT): rwa_monitor/openmct/npm/package.json rwa_monitor/openmct/npm/package-lock.json
	cd rwa_monitor/openmct/npm && npm ci --no-audit --no-fund --silent
	touch $(OPENMCT)

# The browser tests drive Debian's chromium (playwright, requirements.txt); installed here
# when missing and we are root with apt-get, else those tests skip and say why.
browser:
	@if command -v chromium >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo 'installing chromium (Debian) for the browser tests'; \
	  apt-get -o DPkg::Lock::Timeout=600 update -qq && \
	  DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq \
	    chromium >/dev/null || echo 'chromium could not be installed: browser tests skip'; \
	else echo 'chromium not found and not installable here: the browser tests will skip'; fi

# The screenshots in docs/images: the browser tests, photographing into docs/.
screenshots: $(STAMP) openmct browser
	RWA_MONITOR_SCREENSHOTS=docs/images $(PY) -m pytest test/test_openmct_browser.py -q

bench: $(STAMP)
	$(PY) -m bench

lint: $(STAMP)
	$(PY) -m flake8 rwa_monitor test setup.py launch

clean:
	rm -rf $(VENV) build install log *.egg-info

# The optional spacecraft simulation bus (extra `bsk`) lives in its own environment: the
# simulator pins matplotlib below requirements.txt's version (see requirements-bsk.txt).
BSK_VENV ?= .venv-bsk
BSK_PY := $(BSK_VENV)/bin/python
BSK_STAMP := $(BSK_VENV)/.installed

$(BSK_STAMP): requirements.txt requirements-bsk.txt setup.py setup.cfg rwa_monitor/core/_stepcall.c \
		rwa_monitor/telemetry/_packetwalk.c
	$(PYTHON) -m venv $(BSK_VENV)
	$(BSK_PY) -m pip install --upgrade --quiet pip
	$(BSK_PY) -m pip install --quiet -r requirements.txt
	$(BSK_PY) -m pip install --quiet -r requirements-bsk.txt
	$(BSK_PY) -m pip install --quiet --no-deps -e .
	touch $(BSK_VENV)/COLCON_IGNORE $(BSK_STAMP)

# The same readers, Open MCT bundle and browser as `make test`: the suite is the same.
test-bsk: $(BSK_STAMP) interop openmct browser
	$(BSK_PY) -m pytest test -n $(TEST_WORKERS) --dist loadfile

# The realistic profile (default guidance and null speed: the wheels cross zero speed):
# a fault-free commissioning run, its calibration, then a run with a dry step on rw2 and a
# gyro drift on y, replayed LIVE through llr_detector and vsadc_detector (both with
# calibration_file); the events they publish are counted against the file's truth
# columns. For comparison, `detect` without calibration on the same file.
# detect exits 1 when it finds an anomaly (docs/usage.md): expected here.
DEMO_BUS := data/generated/bus
demo-bus: $(BSK_STAMP)
	mkdir -p data/generated
	$(BSK_VENV)/bin/rwa-monitor simulate basilisk --hours 3 --seed 1 \
	  -o $(DEMO_BUS)-commissioning.csv
	$(BSK_VENV)/bin/rwa-monitor calibrate $(DEMO_BUS)-commissioning.csv -o $(DEMO_BUS)-calibration
	$(BSK_VENV)/bin/rwa-monitor simulate basilisk --hours 3 --seed 2 \
	  --fault friction:rw2:5400:dry=3e-4 --fault gyro:y:7200:drift=1e-6 -o $(DEMO_BUS).csv
	$(BSK_VENV)/bin/rwa-monitor detect $(DEMO_BUS).csv -o $(DEMO_BUS)-events-raw.json; \
	  test $$? -le 1
	@echo '== without calibration (rwa-monitor detect on the file)'; \
	  $(BSK_PY) -m bench.bus_acceptance $(DEMO_BUS).csv $(DEMO_BUS)-events-raw.json
	@echo '== with calibration, live nodes'; \
	  $(BSK_PY) -m bench.bus_acceptance live $(DEMO_BUS).csv \
	  $(DEMO_BUS)-calibration/calibration.yaml $(DEMO_BUS)-events-raw.json

bench-bus: $(BSK_STAMP)
	$(BSK_PY) -m bench bus bus_gyro bus_ramps
