# InterMask framework: every target that needs Python depends on `install`, so a fresh clone
# needs nothing but `make <target>`.
SHELL := /bin/bash
.DEFAULT_GOAL := help

VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-from-lock
UV_VERSION := 0.13.8

# DATA picks the dataset config (synthetic, synthetic_interx, interhuman, interx); empty = the job's
# default (synthetic) or the dataset an experiment file selects (experiment=vq_interhuman).
DATA ?=
DATA_ARG = $(if $(DATA),data=$(DATA))
# PRECISION overrides trainer.precision in every training job (train-*, demo, demo-momask); empty =
# the configs' `auto`: bf16-mixed on CUDA with bf16 and on CPUs with native bf16 (AVX512-BF16, AMX),
# 32-true elsewhere. `make demo PRECISION=32-true` times a bf16 CPU as an AVX2 CPU runs.
PRECISION ?=
PRECISION_ARG = $(if $(PRECISION),trainer.precision=$(PRECISION))
CLIPS ?= 1000
SEED ?= 0
ARGS ?=
DATA_DIR ?= data

.PHONY: help install test test-slow test-gpu test-slurm test-all lint format data data-check data-stats train-vq train-evaluator train-gen train-arflow eval demo demo-momask overfit overfit-momask bench tb clean checkpoints parity-env parity

help: ## list the targets
	@grep -E '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-14s %s\n", $$1, $$2}'

install: $(STAMP) ## create .venv from uv.lock (fast no-op when up to date)

$(STAMP): pyproject.toml uv.lock
	@command -v uv >/dev/null 2>&1 || python3 -m uv --version >/dev/null 2>&1 \
		|| python3 -m pip install --quiet "uv==$(UV_VERSION)"
	@# --compile-bytecode: byte-compile the environment once (~30 s on 2 cores). Where Python may
	@# not write .pyc files (PYTHONDONTWRITEBYTECODE, read-only trees), every process would compile
	@# torch and Lightning again: `import intermask.train` 23.7 s without, 9.2 s with
	@# (docs/decisions.md: make install).
	@uv_cmd=$$(command -v uv || echo "python3 -m uv"); $$uv_cmd sync --frozen --compile-bytecode
	@touch $@

test: install ## fast test suite (no `slow`, no `gpu`, no `slurm`)
	$(VENV)/bin/pytest $(ARGS)

test-slow: install ## only the slow tests (training runs, 1000-clip synthesis)
	$(VENV)/bin/pytest -m slow $(ARGS)

test-gpu: install ## GPU tests (skip without CUDA)
	$(VENV)/bin/pytest -m gpu $(ARGS)

test-slurm: install ## real Slurm jobs on a one-node cluster the tests start (root; installs Debian's Slurm; skip otherwise)
	$(VENV)/bin/pytest -m slurm $(ARGS)

test-all: install ## every test
	$(VENV)/bin/pytest -m "" $(ARGS)

lint: install ## ruff lint + format check
	$(VENV)/bin/ruff check intermask callbacks tests
	$(VENV)/bin/ruff format --check intermask callbacks tests

format: install ## apply ruff fixes and formatting
	$(VENV)/bin/ruff check --fix intermask callbacks tests
	$(VENV)/bin/ruff format intermask callbacks tests

data: install ## write the embedded synthetic datasets (InterHuman and Inter-X layouts) under data/synthetic/
	$(VENV)/bin/intermask data synth --out $(DATA_DIR)/synthetic/interhuman --format interhuman --clips $(CLIPS) --seed $(SEED)
	$(VENV)/bin/intermask data synth --out $(DATA_DIR)/synthetic/interx --format interx --clips $(CLIPS) --seed $(SEED)

data-check: install ## validate a dataset folder: make data-check ROOT=data/InterHuman
	$(VENV)/bin/intermask data check $(or $(ROOT),$(DATA_DIR)/synthetic/interhuman)

data-stats: install ## compute normalization statistics: make data-stats ROOT=data/InterHuman
	$(VENV)/bin/intermask data stats $(or $(ROOT),$(DATA_DIR)/synthetic/interhuman)

train-vq: install ## train the VQ-VAE: make train-vq [DATA=synthetic|synthetic_interx|interhuman|interx] [ARGS="trainer.max_epochs=3"]
	$(PY) -m intermask.train --config-name train_vq $(DATA_ARG) $(PRECISION_ARG) $(ARGS)

train-evaluator: install ## train the text-motion evaluator of the metrics: make train-evaluator [DATA=...] [ARGS="experiment=evaluator_demo"]
	$(PY) -m intermask.train --config-name train_evaluator $(DATA_ARG) $(PRECISION_ARG) $(ARGS)

# the newest VQ run's last.ckpt unless VQ_CKPT is given
VQ_CKPT ?= $(shell ls -t outputs/train_vq/runs/*/checkpoints/last.ckpt 2>/dev/null | head -n 1)

train-gen: install ## train Inter-M on frozen VQ tokens: make train-gen [VQ_CKPT=.../last.ckpt] [DATA=...] [ARGS="..."]
	@test -n "$(VQ_CKPT)" || { echo "train-gen: no VQ checkpoint; run make train-vq or pass VQ_CKPT=<run>/checkpoints/last.ckpt" >&2; exit 2; }
	$(PY) -m intermask.train --config-name train_gen $(DATA_ARG) vq_ckpt=$(VQ_CKPT) $(PRECISION_ARG) $(ARGS)

train-arflow: install ## train ARFlow reactions: make train-arflow [DATA=...] [ARGS="experiment=arflow_demo"]
	$(PY) -m intermask.train --config-name train_arflow $(DATA_ARG) $(PRECISION_ARG) $(ARGS)

# the newest generator run with a checkpoint (a run that died before its first checkpoint is
# never picked) and the newest evaluator's best checkpoint unless given
GEN_CKPT ?= $(shell ls -t outputs/train_gen/runs/*/checkpoints/last.ckpt 2>/dev/null | head -n 1)
EVAL_CKPT ?= $(shell ls -t outputs/train_evaluator/runs/*/checkpoints/best*.ckpt 2>/dev/null | head -n 1)
MODE ?= interaction
# reaction mode adds ARFlow's rows from the newest train_arflow run unless ARFLOW_CKPT is given (or empty)
ARFLOW_CKPT ?= $(shell ls -t outputs/train_arflow/runs/*/checkpoints/last.ckpt 2>/dev/null | head -n 1)

checkpoints: ## print the checkpoints make train-gen / make eval would use (override any of them)
	@echo "VQ_CKPT=$(VQ_CKPT)"; echo "GEN_CKPT=$(GEN_CKPT)"; echo "EVAL_CKPT=$(EVAL_CKPT)"; \
		echo "ARFLOW_CKPT=$(ARFLOW_CKPT)"

eval: install ## the 20-replication protocol: make eval [GEN_CKPT=run] [EVAL_CKPT=ckpt] [DATA=...] [MODE=interaction|reaction|reconstruction] [ARFLOW_CKPT=run] [ARGS="fast=true"]
	@test -n "$(EVAL_CKPT)" || { echo "eval: no evaluator; run make train-evaluator or pass EVAL_CKPT=<ckpt>" >&2; exit 2; }
	$(PY) -m intermask.evaluate $(DATA_ARG) mode=$(MODE) eval_ckpt=$(EVAL_CKPT) \
		$(if $(filter reconstruction,$(MODE)),vq_ckpt=$(VQ_CKPT),gen_ckpt=$(GEN_CKPT)) \
		$(if $(and $(filter reaction,$(MODE)),$(ARFLOW_CKPT)),arflow_ckpt=$(ARFLOW_CKPT)) $(ARGS)

DEMO_DIR ?= outputs/demo
# Captions in the dataset's own phrasing: the demo's text tower is random, so a caption worded
# unlike the training captions ("two people shake hands") is an unseen input, and its samples
# put both persons on one spot (docs/decisions.md: DEMO_PROMPTS).
DEMO_PROMPTS := --text "One person reaches out their right hand and the other person shakes it." \
	--text "With both hands, someone pushes another person, who stumbles back."
# the table's decoding (configs/experiment/eval_demo.yaml), at the length gen_demo trains on (96
# frames): 4 s would ask it to extrapolate
DEMO_DECODING := --seconds 3.2 --persons in_turn --revisits 2 --iterations 5 --cfg-scale 1.5 --remask-noise 2

demo: install ## the whole pipeline on the synthetic data, CPU-sized: evaluator, VQ-VAE, generator, protocol, samples (replaces DEMO_DIR) [PRECISION=32-true]
	rm -rf $(DEMO_DIR)
	$(PY) -m intermask.train --config-name train_evaluator experiment=evaluator_demo hydra.run.dir=$(DEMO_DIR)/evaluator $(PRECISION_ARG)
	$(PY) -m intermask.train --config-name train_vq experiment=vq_demo hydra.run.dir=$(DEMO_DIR)/vq $(PRECISION_ARG)
	$(PY) -m intermask.train --config-name train_gen experiment=gen_demo hydra.run.dir=$(DEMO_DIR)/gen \
		vq_ckpt=$(DEMO_DIR)/vq/checkpoints/last.ckpt $(PRECISION_ARG)
	$(PY) -m intermask.evaluate experiment=eval_demo hydra.run.dir=$(DEMO_DIR)/eval gen_ckpt=$(DEMO_DIR)/gen \
		eval_ckpt=$$(ls $(DEMO_DIR)/evaluator/checkpoints/best*.ckpt | head -n 1)
	$(VENV)/bin/intermask generate --checkpoint $(DEMO_DIR)/gen $(DEMO_PROMPTS) $(DEMO_DECODING) --samples 2 \
		--out $(DEMO_DIR)/samples
	@echo; cat $(DEMO_DIR)/eval/results.md
	@echo; echo "demo done: table $(DEMO_DIR)/eval/results.md; checkpoints $(DEMO_DIR)/{evaluator,vq,gen}/checkpoints;" \
		"samples $(DEMO_DIR)/samples/*/{animation.gif,viewer.html}; logs: make tb LOGDIR=$(DEMO_DIR)"

MOMASK_DIR ?= outputs/demo_momask

demo-momask: install ## MoMask on the synthetic HumanML3D-layout data, CPU-sized: evaluator, RVQ, masked + residual transformers, protocol, samples
	rm -rf $(MOMASK_DIR)
	$(PY) -m intermask.train --config-name train_evaluator experiment=evaluator_humanml3d_demo hydra.run.dir=$(MOMASK_DIR)/evaluator $(PRECISION_ARG)
	$(PY) -m intermask.train --config-name train_vq data=synthetic_humanml3d experiment=momask_rvq_demo hydra.run.dir=$(MOMASK_DIR)/rvq $(PRECISION_ARG)
	$(PY) -m intermask.train --config-name train_gen experiment=momask_mask_demo hydra.run.dir=$(MOMASK_DIR)/mask \
		vq_ckpt=$(MOMASK_DIR)/rvq/checkpoints/last.ckpt $(PRECISION_ARG)
	$(PY) -m intermask.train --config-name train_gen experiment=momask_residual_demo hydra.run.dir=$(MOMASK_DIR)/residual \
		vq_ckpt=$(MOMASK_DIR)/rvq/checkpoints/last.ckpt $(PRECISION_ARG)
	$(PY) -m intermask.evaluate data=synthetic_humanml3d mode=text_to_motion reconstruction_row=true \
		hydra.run.dir=$(MOMASK_DIR)/eval mask_ckpt=$(MOMASK_DIR)/mask residual_ckpt=$(MOMASK_DIR)/residual \
		eval_ckpt=$$(ls $(MOMASK_DIR)/evaluator/checkpoints/best*.ckpt | head -n 1)
	$(VENV)/bin/intermask generate --checkpoint $(MOMASK_DIR)/mask --residual $(MOMASK_DIR)/residual \
		--text "a person walks forward" --text "a person waves" --seconds 4 --samples 1 --out $(MOMASK_DIR)/samples
	@echo; cat $(MOMASK_DIR)/eval/results.md

OVERFIT_DIR ?= outputs/overfit

overfit: install ## memorisation check: VQ-VAE + Inter-M on 14 clips (one per action), then all 14 captions must succeed
	$(PY) -m intermask.overfit --out $(OVERFIT_DIR) $(ARGS)

OVERFIT_MOMASK_DIR ?= outputs/overfit_momask

overfit-momask: install ## MoMask memorisation check: RVQ + masked + residual transformers on 8 clips; every layer memorised, residual layers closer than the base
	$(PY) -m intermask.overfit_momask --out $(OVERFIT_MOMASK_DIR) $(ARGS)

# The authors' checkouts for `make parity` (tools/parity/README.md); none is needed by any other target.
REFERENCE_INTERMASK ?= ../InterMask
REFERENCE_MOMASK ?= ../momask-codes
REFERENCE_INTERGEN ?= ../InterGen
PARITY_PY := .venv-parity/bin/python

parity-env: ## .venv-parity: this package plus what the authors' modules import (tools/parity/README.md)
	@command -v uv >/dev/null 2>&1 || python3 -m pip install --quiet "uv==$(UV_VERSION)"
	@uv_cmd=$$(command -v uv || echo "python3 -m uv"); $$uv_cmd venv -q --allow-existing .venv-parity \
		&& $$uv_cmd pip install -q --python $(PARITY_PY) -e . torch_geometric positional-encodings einops tqdm matplotlib

parity: ## run the parity scripts against the authors' code: make parity REFERENCE_INTERMASK=../InterMask REFERENCE_MOMASK=../momask-codes REFERENCE_INTERGEN=../InterGen [ARGS=--write-fixture]
	@test -x $(PARITY_PY) || $(MAKE) parity-env
	$(PARITY_PY) tools/parity/intermask_models.py --reference $(REFERENCE_INTERMASK) $(ARGS)
	$(PARITY_PY) tools/parity/momask.py --reference $(REFERENCE_MOMASK) $(ARGS)
	$(PARITY_PY) tools/parity/evaluators.py --reference-intermask $(REFERENCE_INTERMASK) \
		--reference-momask $(REFERENCE_MOMASK) --reference-intergen $(REFERENCE_INTERGEN) $(ARGS)
	$(PARITY_PY) tools/parity/eval_loop.py --reference $(REFERENCE_INTERMASK)

bench: install ## speed of the hot paths against this machine's measured peak: make bench [ARGS="--threads 1 --size demo"]
	$(PY) -m intermask.bench $(ARGS)

tb: install ## TensorBoard over all runs: make tb [LOGDIR=outputs]
	$(VENV)/bin/tensorboard --logdir $(or $(LOGDIR),outputs) --bind_all

clean: ## remove caches and run outputs (keeps .venv and data/)
	rm -rf .pytest_cache .ruff_cache outputs multirun lightning_logs
	find . -name __pycache__ -type d -prune -not -path './.venv/*' -exec rm -rf {} +
