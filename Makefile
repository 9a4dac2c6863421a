# facette: the front door. `make scan` runs the one-button scan on the simulated rig,
# `make test` runs every test. Both set everything up themselves on a fresh machine.
SHELL    := /bin/bash
VENV     := .venv
PY       := $(VENV)/bin/python
FACETTE  := $(VENV)/bin/facette
BUILD    := build
SIM_DEVICE := $(BUILD)/posix/facette-device
FUZZ_SECONDS ?= 300
FUZZ_RUNS ?= 0
SCAN_OUT ?= out/scan-demo
# RAW size of the demo: 512x384 px normal maps (the fossil's ribs visible), about half a minute
SCAN_SIZE ?= 1024x768
GLTF_VALIDATOR := tools/gltf-validator

.PHONY: lock setup deps venv firmware-posix generate check-generated check-layers test c-test fuzz fuzz-smoke \
        pytest firmware qemu-test check-fw-layers scan calibrate bench clean help node-deps docs docs-check warmup

help:
	@echo "make scan             one-button scan on the simulated rig, then processing"
	@echo "make test             every test (installs what it needs)"
	@echo "make setup            .venv with facette (editable), Debian packages, simulated device"
	@echo "make calibrate        the calibration wizard, unattended, on the simulated rig"
	@echo "make firmware         STM32F405 build (size printed)"
	@echo "make qemu-test        boot the STM32 build in QEMU and talk Modbus to it"
	@echo "make fuzz             libFuzzer on frames/registers and on the sequencer/safety, both at once ($(FUZZ_SECONDS) s each)"
	@echo "make bench            benchmarks: error and run time side by side (writes docs/benchmarks.md)"
	@echo "make docs             the documentation site into site/ (its pictures made by running the tutorials)"
	@echo "make lock             requirements.lock anew from pyproject.toml (pip-compile)"
	@echo "make generate         regenerate protocol files from protocol/registers.toml"
	@echo "make check-layers     host imports only go down the layers of docs/ARCHITECTURE.md"

setup: deps venv node-deps firmware-posix warmup

# every numba kernel compiled once and cached (host/facette/__pycache__/kernels-DIGEST, git-ignored), so
# that the first `facette process` does not compile them (a fresh clone's first run: see
# facette/pipeline/_warmup.py). Again after each change of the kernels' files.
warmup: $(VENV)/.warmed

$(VENV)/.warmed: $(VENV)/.installed $(wildcard host/facette/*_jit.py host/facette/*/*_jit.py)
	$(PY) -m facette.pipeline._warmup
	touch $@

deps:
	@tools/install-debian-deps.sh

# Every Python package at the version in requirements.lock (pip-compile's output; `make lock`
# writes it anew from pyproject.toml), then facette itself, editable, with no other resolution.
$(VENV)/.installed: pyproject.toml requirements.lock
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.lock
	$(PY) -m pip install -q --no-deps -e .
	touch $@

lock:
	python3 -m venv $(BUILD)/pip-tools
	$(BUILD)/pip-tools/bin/pip install -q pip-tools
	$(BUILD)/pip-tools/bin/pip-compile -q --extra dev --strip-extras -o requirements.lock pyproject.toml
	sed -i '/^--find-links/d' requirements.lock

venv: $(VENV)/.installed

# the Khronos glTF validator (npm), pinned by its lock file, for the .glb export's tests
$(GLTF_VALIDATOR)/node_modules/.installed: $(GLTF_VALIDATOR)/package-lock.json | deps
	npm ci --prefix $(GLTF_VALIDATOR) --no-audit --no-fund --loglevel=error
	touch $@

node-deps: $(GLTF_VALIDATOR)/node_modules/.installed

generate:
	python3 tools/gen_protocol.py

check-generated:
	python3 tools/gen_protocol.py --check

# import-linter's layers contract in pyproject.toml (docs/ARCHITECTURE.md); the figures of the
# import graph (modules per layer, cycles, imports inside functions): python3 tools/import_graph.py
check-layers: venv
	$(VENV)/bin/lint-imports --no-cache

firmware-posix: deps
	$(MAKE) -C firmware posix BUILD=$(abspath $(BUILD))

firmware: deps
	$(MAKE) -C firmware stm32 BUILD=$(abspath $(BUILD))

c-test: deps
	$(MAKE) -C firmware test BUILD=$(abspath $(BUILD))

check-fw-layers: deps
	$(MAKE) -C firmware check-layers BUILD=$(abspath $(BUILD))

fuzz: deps
	$(MAKE) -C firmware fuzz BUILD=$(abspath $(BUILD)) FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_RUNS=$(FUZZ_RUNS)

fuzz-smoke: deps
	$(MAKE) -C firmware fuzz-smoke BUILD=$(abspath $(BUILD))

qemu-test: setup firmware
	$(VENV)/bin/pytest -q hil_tests/test_qemu_board.py --qemu-elf $(abspath $(BUILD))/stm32f4/facette-stm32f4.elf

pytest: setup
	$(VENV)/bin/pytest -q

test: check-generated check-layers setup c-test check-fw-layers fuzz-smoke pytest qemu-test docs-check

scan: setup
	$(FACETTE) scan --sim --press-button --raw-size $(SCAN_SIZE) $(SCAN_OUT)

# A fresh profile beside the committed one (calibration/profiles/sim-default is replaced only on purpose).
calibrate: setup
	$(FACETTE) calibrate --rig sim --yes -o out/calibration/sim

# The documentation site (mkdocs.yml; tools/docs/hooks.py generates the command reference, the
# register map and the messages page at each build). `make docs` first makes the tutorials'
# pictures by running their steps (tools/docs/figures.py, cached in build/docs/: delete it to redo
# them); `make docs-check` (part of `make test`) builds with warnings as errors, pictures not made
# yet standing in as placeholders.
DOCS_ENV := NO_MKDOCS_2_WARNING=1 PYTHONPATH=$(CURDIR)/host
docs: setup
	$(DOCS_ENV) $(PY) tools/docs/figures.py
	$(DOCS_ENV) $(VENV)/bin/mkdocs build --strict --site-dir site

docs-check: venv
	$(DOCS_ENV) $(VENV)/bin/mkdocs build --strict --quiet --site-dir $(BUILD)/docs/site-check

bench: setup
	$(FACETTE) bench all

clean:
	rm -rf $(BUILD)
