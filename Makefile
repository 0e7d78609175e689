# The two commands of the README: `make demo` (main job on the built-in scene) and
# `make test` (every test). Both do all set-up on a fresh machine first.
SHELL := /bin/bash
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.deps-installed
PYDEPS := bpy==5.0.1 "maturin>=1.7,<2" pytest hypothesis matplotlib trimesh

.PHONY: setup build demo test test-rust test-python lint bench accuracy report stiff addon clean

# Mesa's software Vulkan (lavapipe) so the wgpu path runs without a GPU; GPU tests skip
# with their reason where it cannot be installed.
VULKAN_STAMP := $(VENV)/.vulkan-installed

$(VULKAN_STAMP): $(STAMP)
	@if [ -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ] || [ -e /usr/share/vulkan/icd.d/lvp_icd.aarch64.json ]; then \
		echo "lavapipe present"; \
	elif command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mesa-vulkan-drivers >/dev/null) \
			|| echo "warning: could not install mesa-vulkan-drivers; GPU tests will skip"; \
	else \
		echo "warning: not root or no apt-get: install mesa-vulkan-drivers for the wgpu tests"; \
	fi
	touch $(VULKAN_STAMP)

$(STAMP): Makefile
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(PYDEPS)
	touch $(STAMP)

setup: $(STAMP) $(VULKAN_STAMP)

# Release build of the native module, installed (editable) into the venv.
build: setup
	VIRTUAL_ENV=$(VENV) PATH=$(VENV)/bin:$$PATH $(VENV)/bin/maturin develop --release -q

demo: build
	$(PY) blender_scripts/demo.py

lint:
	cargo fmt --all --check
	cargo clippy --workspace --all-targets -q -- -D warnings

test-rust:
	cargo test --workspace --exclude translucent-python -q

test-python: build
	$(PY) -m pytest -q --durations=40 tests

test: lint test-rust test-python

bench: build
	$(PY) blender_scripts/bench_prt.py
	$(PY) blender_scripts/bench_drag.py
	$(PY) blender_scripts/bench_drag.py --no-layers
	$(PY) blender_scripts/bench_drag.py --floor
	$(PY) blender_scripts/bench_hierarchy.py
	$(PY) blender_scripts/bench_hierarchy.py --receivers vertices
	$(PY) blender_scripts/bench_splat.py
	$(PY) blender_scripts/precompute_vs_cycles.py
	$(PY) blender_scripts/flicker_splat.py

# The installable Blender extension (zip with the native wheel) in dist/.
addon: setup
	$(PY) blender_scripts/build_extension.py --out dist

accuracy: build
	$(PY) blender_scripts/accuracy_prt.py

# Error against run time (CSV, PNG, Markdown in out/report); options: make report ARGS="--materials marble".
report: build
	$(PY) blender_scripts/report.py $(ARGS)

# How far fixed knots hold (README table); needs ../shared/models.
stiff: build
	$(PY) blender_scripts/stiff_edits.py $(ARGS)

clean:
	cargo clean
	rm -rf $(VENV) out
