# hiros: `make demo` and `make test` are the two commands; both set up the venv first.
SHELL := /bin/bash
.SHELLFLAGS := -o pipefail -c
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.hiros-setup
SETUP_INPUTS := requirements.txt constraints.txt setup.py setup.cfg package.xml \
	tools/build_interfaces.sh tools/install_ament_layout.sh \
	$(wildcard hiros_skeleton_msgs/msg/*.msg hiros_skeleton_msgs/srv/*.srv) \
	hiros_skeleton_msgs/CMakeLists.txt third_party/tf2_msgs/CMakeLists.txt

.PHONY: setup test test-fast lint demo bench clean

setup: $(STAMP)

$(STAMP): $(SETUP_INPUTS)
	@test -x $(PY) || python3 -m venv $(VENV)
	@# (pip's notes about local index folders this machine lacks are filtered out)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt -c constraints.txt \
		2>&1 | { grep -v "^WARNING: Location" || true; }
	tools/build_interfaces.sh $(VENV) hiros_skeleton_msgs
	@$(PY) -c "import tf2_msgs.msg" 2>/dev/null || tools/build_interfaces.sh $(VENV) third_party/tf2_msgs
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation --config-settings editable_mode=compat -e .
	tools/install_ament_layout.sh $(VENV)
	@# compile the numba kernels now (cached on disk), not during the first demo or node start
	$(PY) tools/warm_kernels.py
	@touch $(STAMP)
	@echo "hiros is set up in $(VENV)"

# ruff's lint and layout (`ruff format FILE` fixes the second; the kernels' hand-laid calls
# keep `# fmt: skip`), then the packages' layer contracts (.importlinter; docs/architecture.md)
lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports --no-cache

# The whole suite runs in a private network namespace holding only loopback, so that DDS
# traffic of the ROS tests never leaves the machine (fallback: localhost-only discovery).
# (Foxglove's npm libraries are installed first: the namespace cannot reach the registry.)
test: lint
	tools/install_npm_test_deps.sh
	tools/netns.sh $(VENV)/bin/pytest -q

test-fast: lint
	tools/install_npm_test_deps.sh
	tools/netns.sh $(VENV)/bin/pytest -q -m "not slow"

demo: setup
	$(VENV)/bin/hiros demo

bench: setup
	$(VENV)/bin/hiros bench

clean:
	rm -rf $(VENV) build install log
