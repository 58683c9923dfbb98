# One command each: `make demo` (install + main job) and `make test` (install + tests) work from a fresh clone.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.installed

.PHONY: install demo test test-slow lint format type bench bench-envs results clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

# torch first, pinned to the CPU wheel, so that the project's unpinned `torch>=2.3` never pulls a CUDA build.
$(STAMP): $(PY) pyproject.toml
	$(PY) -c "import torch" 2>/dev/null || $(PIP) install --quiet "torch==2.13.0" || $(PIP) install --quiet torch --index-url https://download.pytorch.org/whl/cpu
	$(PIP) install --quiet -e ".[dev,ray]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/ebm-eval --baseline ppo
	$(VENV)/bin/ebm-eval -c maze_demo --preset fast

test: $(STAMP)
	$(PY) -m pytest -m "not slow" -n 2 -q

test-slow: $(STAMP)
	$(PY) -m pytest -m slow -q -o addopts=""

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy ebm_agent envs baselines eval benchmarks

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

bench-envs: $(STAMP)
	$(PY) -m benchmarks.envs

# The plan grid (quick), then learn(50,000) of the EBM agent and Action FF (fast preset; --learn-preset '' for the
# defaults) and PPO on the particle, Reacher and the Sawyer with their time ratios against PPO (about an hour on 2 cores; BENCH_ARGS="--learn-steps 5000" is quicker).
BENCH_ARGS ?= --quick --learn-steps 50000 --threads 1 --learn-preset fast
bench: $(STAMP)
	$(PY) -m benchmarks $(BENCH_ARGS)

# The paper's tables and figures at the paper's budgets (days of CPU time; resumable: rerun to continue, finished
# runs are skipped), then docs/results.md. `make results RESULTS_JOBS=4` runs 4 at a time. The document is
# regenerated even when a run failed (it says which), and the target then fails.
RESULTS_DIR  ?= runs/results
RESULTS_JOBS ?= 1
results: $(STAMP)
	$(VENV)/bin/ebm-eval --experiment all --scale paper -f $(RESULTS_DIR) --jobs $(RESULTS_JOBS) --no-progress; \
	status=$$?; \
	$(PY) -m eval.paper.results_doc -f $(RESULTS_DIR) --docs docs/results.md && exit $$status

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
