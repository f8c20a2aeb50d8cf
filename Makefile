# fr5_rl: every target sets itself up first (tools/setup.sh is idempotent and fast when
# nothing changed). `make demo` and `make test` are the two commands a new user needs.
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
ENV := set +u; source env.sh; set -u;
TASK ?= reach
ALGO ?= ppo
EPISODES ?= 5

.PHONY: setup demo test bench bench-grasp bench-vision bench-ray train meshes lint clean help

help:
	@echo "make demo   - set up, then run the closed loop (simulator + policy) with the shipped model"
	@echo "make test   - set up, then run the whole test suite (pytest + rostest)"
	@echo "make bench  - set up, then run the benchmarks; figures printed and written to bench/results/"
	@echo "make bench-ray - set up, then the Ray Tune bench (1 vs 2 nodes, ASHA vs full); BENCH_ARGS=--quick"
	@echo "make train  - set up, then train (TASK=reach|grasp ALGO=ppo|sac|td3|tqc)"
	@echo "make setup  - only the set-up"

setup:
	@bash tools/setup.sh

demo: setup
	@$(ENV) bash tools/demo.sh $(EPISODES)

test: setup
	@$(ENV) bash tools/run_tests.sh

# Env speed + inference latency, the ROS loop (timing, sim-to-ROS parity, one core busy), the
# FAIRINO driver's timing emulated over 200 episodes, lockstep
# against gym over 200 seeds per model, time to solve reach.
# BENCH_ARGS=--quick for a smoke run; `make bench-grasp` adds the grasp time to solve (~15 min).
bench: setup
	@$(ENV) python tools/bench_ros.py
	@$(ENV) python tools/bench_ros.py --busy-cores 1
	@$(ENV) python tools/bench_timing.py --model models/reach --profile fairino
	@$(ENV) python tools/bench_lockstep.py --model models/reach --real-time
	@$(ENV) python tools/bench_lockstep.py --model models/grasp
	@$(ENV) python tools/bench_train.py --task reach
	@$(ENV) python tools/bench.py $(BENCH_ARGS)

# Ray Tune: training throughput on 1 vs 2 local nodes, and the compute ASHA needs to find a
# config that solves reach (95 %) against running every trial to the end. BENCH_ARGS=--quick
# for a smoke run (minutes); the full run takes about an hour on 2 cores.
bench-ray: setup
	@$(ENV) python tools/bench_tune.py $(BENCH_ARGS)

bench-grasp: setup
	@$(ENV) python tools/bench_train.py --task grasp
	@$(ENV) python tools/bench_ros.py --model models/grasp --episodes 20
	@$(ENV) python tools/bench.py --skip-env --model models/grasp --results bench/results/grasp

# Vision in the loop: renderer speed, detection error (200 placements), camera and loop rates,
# image-to-command latency, reach and grasp through the simulated camera (~10 min).
bench-vision: setup
	@$(ENV) python tools/bench_vision.py $(BENCH_ARGS)

train: setup
	@$(ENV) rosrun fr5_rl train.py --task $(TASK) --algo $(ALGO)

meshes: setup
	@$(ENV) python tools/generate_description.py

lint: setup
	@$(ENV) catkin_lint -W1 .

clean:
	@bash tools/setup.sh --clean
	rm -rf runs bench/results
