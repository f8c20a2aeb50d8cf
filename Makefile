# fr5_rl: every target sets itself up first (tools/setup.sh is idempotent and fast when
# nothing changed). `make demo` and `make test` are the two commands a new user needs.
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
ENV := set +u; source env.sh; set -u;
TASK ?= reach
ALGO ?= ppo
ROBOT ?= fr5
EPISODES ?= 5
SCENE ?=

.PHONY: setup demo test test-fast bench bench-grasp bench-vision bench-ray train models meshes lint clean help

help:
	@echo "make demo   - set up, then run the closed loop (simulator + policy) with the shipped model"
	@echo "              SCENE=clear: clear a table of several objects through camera, detector and driver (models/place)"
	@echo "make test   - set up, then run the whole test suite (pytest + rostest)"
	@echo "make test-fast - set up, then only the pure-logic tests (no training, Ray, roscore, lint or command lines; < 60 s)"
	@echo "make lint   - set up, then catkin_lint, ruff (config: ruff.toml), and the URDF, launch-file and command-line checks"
	@echo "make bench  - set up, then run the benchmarks; figures printed and written to bench/results/"
	@echo "make bench-ray - set up, then the Ray Tune bench (1 vs 2 nodes, ASHA vs full); BENCH_ARGS=--quick"
	@echo "make train  - set up, then train (TASK=reach|grasp|place ALGO=ppo|sac|td3|tqc ROBOT=fr3|fr5|fr10|fr16|fr20|fr30)"
	@echo "make models - set up, then make an arm's whole model set (reach, grasp, place) with cards: ROBOT=fr10; resumes after a kill"
	@echo "make meshes - set up, then regenerate urdf/ and meshes/ for every arm from config/robots/ and config/gripper.yaml"
	@echo "make setup  - only the set-up"

setup:
	@bash tools/setup.sh

demo: setup
	@$(ENV) SCENE="$(SCENE)" bash tools/demo.sh $(EPISODES)

test: setup
	@$(ENV) bash tools/run_tests.sh

# The inner loop, pure logic: tests marked `slow` (training runs, model sweeps, Ray clusters,
# roscore) or `integration` (lint, URDF checks, launch parsing, command lines) are left out;
# `make lint` runs the latter, `make test` runs them all.
test-fast: setup
	@$(ENV) python -m pytest -q -m "not slow and not integration" test/

# Env speed + inference latency, the ROS loop (timing, sim-to-ROS parity, one core busy), the
# FAIRINO driver's timing emulated over 200 episodes, lockstep
# against gym over 200 seeds per model, time to solve reach; env speed and time to solve also
# against the previous release's code (tools/bench/reference_release.yaml), in the same run.
# BENCH_ARGS=--quick for a smoke run; `make bench-grasp` adds the grasp times to solve: DAgger's,
# and PPO's from reward against the release on the same seed (~50 min on 2 cores).
bench: setup
	@$(ENV) python tools/bench/ros_loop.py
	@$(ENV) python tools/bench/ros_loop.py --busy-cores 1
	@$(ENV) python tools/bench/timing.py --model models/reach --profile fairino
	@$(ENV) python tools/bench/lockstep.py --model models/reach --real-time
	@$(ENV) python tools/bench/lockstep.py --model models/grasp
	@$(ENV) python tools/bench/time_to_solve.py --task reach
	@$(ENV) python tools/bench/env_and_inference.py $(BENCH_ARGS)

# Ray Tune: training throughput on 1 vs 2 local nodes, and the compute ASHA needs to find a
# config that solves reach (95 %) against running every trial to the end. BENCH_ARGS=--quick
# for a smoke run (minutes); the full run takes about an hour on 2 cores.
bench-ray: setup
	@$(ENV) python tools/bench/tune.py $(BENCH_ARGS)

bench-grasp: setup
	@$(ENV) python tools/bench/time_to_solve.py --task grasp
	@$(ENV) python tools/bench/time_to_solve.py --task grasp-from-reward --max-timesteps 1200000
	@$(ENV) python tools/bench/ros_loop.py --model models/grasp --episodes 20
	@$(ENV) python tools/bench/env_and_inference.py --skip-env --model models/grasp --results bench/results/grasp

# Vision in the loop: renderer speed, detection error (200 placements), camera and loop rates,
# image-to-command latency, reach and grasp through the simulated camera (~10 min); then every
# object of 80 scenes of several (~1 min).
bench-vision: setup
	@$(ENV) python tools/bench/vision.py $(BENCH_ARGS)
	@$(ENV) python tools/bench/scene_detection.py --scenes 80 --seed 5430000

train: setup
	@$(ENV) rosrun fr5_rl train.py --task $(TASK) --algo $(ALGO) --robot $(ROBOT)

# One arm's whole model set (config/recipes/model_set.yaml): models/<arm>/{reach,grasp,place} with
# cards and held-out figures; runs in runs/models_<arm>/, and a second call resumes a killed one.
models: setup
	@$(ENV) rosrun fr5_rl make_models.py --robot $(ROBOT)

meshes: setup
	@$(ENV) python tools/generate_description.py

lint: setup
	@$(ENV) catkin_lint -W1 . && ruff check . && python -m pytest -q -m integration test/

clean:
	@bash tools/setup.sh --clean
	rm -rf runs bench/results
