# Each target creates .venv and installs the project when it is missing. --no-compile: pip's
# byte-compiling of every installed module took about half of the install (27 -> 14 s here);
# Python compiles what a run imports instead.
PY ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: train test bench clean

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PY) -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip
	$(VENV)/bin/pip install -q --no-compile -e ".[test]"
	touch $(STAMP)

# ROLL from pixels on puck_push at the cpu preset (50k env steps), one seed: segmentation,
# pretraining and training took 15 min on 2 idle cores, 10.3 -> 5.6 cm (docs/training.md).
train: $(STAMP)
	$(VENV)/bin/python train.py --task puck_push --algo roll --preset cpu --seeds 1 --out runs/puck_push_roll_cpu

# Two workers, whole files per worker (module fixtures are built once): XLA compiles on one
# core, so two files compile side by side on a 2-core machine. Files go out in the order
# tests/conftest.py sorts them (the two slowest first, one per worker), not by test count.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=15

# One benchmark of the suite: make bench NAME=chunk ARGS="--seeds 1" (python -m bench lists them).
NAME ?= envs
ARGS ?=
bench: $(STAMP)
	$(VENV)/bin/python -m bench $(NAME) $(ARGS)

clean:
	rm -rf $(VENV) runs .jax_cache
