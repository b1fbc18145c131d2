# Two commands for a newcomer: `make demo` and `make test`. Each sets up .venv first.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint venv clean

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade --quiet pip
	$(PY) -m pip install --quiet -r requirements.txt
	$(PY) -m pip install --quiet --no-deps -e .
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/rwa-monitor demo

test: $(STAMP)
	$(PY) -m pytest test

bench: $(STAMP)
	$(VENV)/bin/rwa-monitor bench

lint: $(STAMP)
	$(PY) -m flake8 rwa_monitor test setup.py launch

clean:
	rm -rf $(VENV) build install log *.egg-info
