# slamd: the two commands that do everything on a fresh Debian 12 machine are
#   make run    (installs dependencies, builds, runs slamd on a built-in synthetic world)
#   make test   (installs dependencies, builds, runs every test, then the concurrency tests
#                under ThreadSanitizer and every test under AddressSanitizer + UBSan)
# Other targets: deps, build, bench, bench-corridors, bench-corridors-plain, soak, tsan, asan,
# ubsan, asan-ubsan, fuzz, clean.

BUILD_DIR ?= build
JOBS ?= 2
CMAKE_ARGS ?=
# WERROR=ON: compiler warnings fail the main build (CI sets it; see .ci/run).
WERROR ?= OFF
CTEST_ARGS ?=

.PHONY: all deps build test unit-test run bench bench-corridors bench-corridors-plain soak tsan asan ubsan asan-ubsan fuzz clean

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD_DIR)/CMakeCache.txt:
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release -DSLAMD_WERROR=$(WERROR) $(CMAKE_ARGS)

build: deps $(BUILD_DIR)/CMakeCache.txt
	cmake --build $(BUILD_DIR) -j$(JOBS)

unit-test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j$(JOBS) $(CTEST_ARGS)

test: unit-test tsan asan-ubsan

run: build
	@bash scripts/run-default.sh $(BUILD_DIR)

bench: build
	@bash scripts/run-bench.sh $(BUILD_DIR)

# Full SLAM on textured corridors drawn from the evaluation seeds (issue 22's suite): ATE, frames
# posed, keyframes per metre, worst per-frame rotation (out/bench/corridors/results.md).
bench-corridors: build
	@bash scripts/bench-corridors.sh $(BUILD_DIR)

# Issue 23's plain corridors (texture density 0.04, no posters, zigzag walks) on the evaluation
# seeds 9301-9306: ATE, end yaw, worst rotation (out/bench/corridors-plain/results.md).
bench-corridors-plain: build
	@CORRIDOR_SUITE=plain bash scripts/bench-corridors.sh $(BUILD_DIR)

# fr1/xyz played forward and backward 10 times in real time (4.4 min): memory, keyframes, map
# size and latency over time (out/soak/soak.json, soak.svg).
soak: build
	@bash scripts/bench-soak.sh $(BUILD_DIR)

# Sanitizer builds live in their own trees. TSan covers the tests labelled "concurrency"
# (queues, pipeline, daemon threads); ASan and UBSan cover all tests.
tsan: deps
	cmake -S . -B build-tsan -DSLAMD_SANITIZE=thread -DSLAMD_BUILD_BENCH=OFF $(CMAKE_ARGS)
	cmake --build build-tsan -j$(JOBS) --target concurrency_tests
	cd build-tsan && TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" \
	  ctest --output-on-failure -j$(JOBS) -L concurrency $(CTEST_ARGS)

asan: deps
	cmake -S . -B build-asan -DSLAMD_SANITIZE=address -DSLAMD_BUILD_BENCH=OFF $(CMAKE_ARGS)
	cmake --build build-asan -j$(JOBS)
	cd build-asan && ASAN_OPTIONS="detect_leaks=1" ctest --output-on-failure -j$(JOBS) $(CTEST_ARGS)

ubsan: deps
	cmake -S . -B build-ubsan -DSLAMD_SANITIZE=undefined -DSLAMD_BUILD_BENCH=OFF $(CMAKE_ARGS)
	cmake --build build-ubsan -j$(JOBS)
	cd build-ubsan && UBSAN_OPTIONS="print_stacktrace=1" ctest --output-on-failure -j$(JOBS) $(CTEST_ARGS)

# AddressSanitizer and UndefinedBehaviorSanitizer in one build, over every test.
asan-ubsan: deps
	cmake -S . -B build-asan-ubsan -DSLAMD_SANITIZE=address+undefined -DSLAMD_BUILD_BENCH=OFF $(CMAKE_ARGS)
	cmake --build build-asan-ubsan -j$(JOBS)
	cd build-asan-ubsan && ASAN_OPTIONS="detect_leaks=1" UBSAN_OPTIONS="print_stacktrace=1" \
	  ctest --output-on-failure -j$(JOBS) $(CTEST_ARGS)

# libFuzzer over everything slamd reads from outside (tests/fuzz): FUZZ_SECONDS per target (or
# FUZZ_RUNS executions, when given and reached first).
FUZZ_SECONDS ?= 60
FUZZ_RUNS ?= -1
fuzz:
	@bash scripts/install-deps.sh fuzz
	FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_RUNS=$(FUZZ_RUNS) BUILD_JOBS=$(JOBS) \
	  bash scripts/run-fuzz.sh build-fuzz

clean:
	rm -rf $(BUILD_DIR) build-tsan build-asan build-ubsan build-asan-ubsan build-fuzz
