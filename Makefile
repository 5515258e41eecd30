# winder: the two commands of the README, plus the side jobs.
#   make demo   - create .venv if needed, run the default winding job
#   make test   - create .venv if needed, lint and type-check every package, run the whole test suite
#   make flakes - the node tests FLAKE_ROUNDS times (default 3) beside a busy loop: each failure, counted
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.winder-installed
SETUPS := pyproject.toml src/setup.py winder_interp/setup.py winder_profile/setup.py winder_sim/setup.py \
	  winder_bridge/setup.py

PACKAGES := src winder_interp winder_profile winder_sim winder_bridge
# pytest workers: the node tests mostly wait (discovery, a node's start, a paced run), so
# four share two cores well; each test holds ROS domains of its own (test/support/domains.py)
TEST_WORKERS ?= 4
PYTEST := $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile
FLAKE_ROUNDS ?= 3

.PHONY: demo test flakes bench figures venv bytecode interfaces clean

venv: $(STAMP)

# Every winder process imports some 100 of winder's own modules. An editable
# install has no bytecode for them, and where PYTHONDONTWRITEBYTECODE is set
# Python compiles them again in every process (0.15 s a process here); write
# it as pip does for an installed package (up to date: 0.1 s, nothing done).
bytecode: interfaces
	@$(BIN)/python -m compileall -q $(PACKAGES) > /dev/null

# winder_interfaces (the Wind action, the typed cell state and report): an ament_cmake
# package, generated with the wheels' rosidl and installed into the venv; built again
# only when its definitions change (its stamp; 0.1 s when they did not)
interfaces: $(STAMP)
	@$(BIN)/python winder_interfaces/build_into_venv.py winder_interfaces $(VENV)

$(STAMP): $(SETUPS)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@echo "winder: installing into $(VENV) (ROS 2 Jazzy wheels, numpy, mcap, rosbags, test tools)"
	@$(BIN)/python -m pip install -q --disable-pip-version-check --upgrade pip
	@$(BIN)/python -m pip install -q --disable-pip-version-check -e '.[ros,test]' \
		-e ./winder_interp -e ./winder_profile -e ./winder_sim -e ./winder_bridge
	@touch $(STAMP)

demo: bytecode
	@$(BIN)/winder run

test: bytecode
	$(BIN)/ruff check $(PACKAGES) winder_interfaces test bench
	$(BIN)/mypy
	$(PYTEST)

# the flake finder: the node tests (-m ros) FLAKE_ROUNDS rounds beside a busy loop on one
# core; prints each test that failed and in how many rounds (no retries: a failure counts)
flakes: bytecode
	$(BIN)/python test/flakes.py --rounds $(FLAKE_ROUNDS) --workers $(TEST_WORKERS)

bench: bytecode
	$(BIN)/python bench/run_all.py

figures: $(STAMP)
	$(BIN)/winder figures docs/img

clean:
	rm -rf build install log .pytest_cache .hypothesis
