# evloc: top-level commands. See README.md.
#   make test   install missing packages, configure (Release with assertions), build, run every test
#   make build  configure and build only
#   make demo   end to end on built-in data (see docs/demo.md)
#   make demo-site  a small geo-referenced site of tiles end to end (docs/demo.md, "A site")
#   make python build, then install the Python package evloc into .venv (see docs/python.md)
#   make bench  build and run the benchmarks
#   make fuzz   build the libFuzzer targets with clang (see docs/reliability.md)
#   make clean  remove build outputs

BUILD_DIR ?= build
JOBS ?= $(shell nproc)
# The generator is chosen when the recipe runs (ninja may have just been installed) and only for a
# new build folder: an existing one keeps the generator it was configured with.
CMAKE_GENERATOR_FLAG = $$(test -f $(1)/CMakeCache.txt || \
  { command -v ninja >/dev/null 2>&1 && echo "-G Ninja"; })
CMAKE_FLAGS := -DCMAKE_BUILD_TYPE=Release -DEVLOC_ASSERTIONS=ON
# ccache is looked up when the recipe runs, after install-deps.sh has installed it (a fresh
# machine has no ccache when make parses this file).
CCACHE_FLAGS = $$(command -v ccache >/dev/null 2>&1 && \
  echo -DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)

.PHONY: deps configure build test test-long bench fuzz demo demo-site python clean format

deps:
	@scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD_DIR) $(call CMAKE_GENERATOR_FLAG,$(BUILD_DIR)) $(CMAKE_FLAGS) $(CCACHE_FLAGS) >/dev/null || \
	  { echo "make: cmake configure failed; rerun 'cmake -S . -B $(BUILD_DIR)' to see why" >&2; exit 1; }

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	@cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) -LE long

test-long: build
	@cd $(BUILD_DIR) && ctest --output-on-failure -L long

bench: build
	@scripts/run-benchmarks.sh $(BUILD_DIR)

fuzz: deps
	@cmake -S . -B build-fuzz $(call CMAKE_GENERATOR_FLAG,build-fuzz) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DEVLOC_FUZZ=ON \
	  $(CCACHE_FLAGS) >/dev/null
	@cmake --build build-fuzz -j $(JOBS) --target evloc_fuzzers

demo: build
	@BUILD_DIR=$(BUILD_DIR) scripts/demo.sh

demo-site: build
	@BUILD_DIR=$(BUILD_DIR) scripts/demo-site.sh

# The Python package (docs/python.md): a venv that sees Debian's numpy, grpcio and protobuf, and
# pip without build isolation (offline: setuptools and wheel are Debian's too).
VENV ?= .venv
python: build
	@test -x $(VENV)/bin/python || /usr/bin/python3 -m venv --system-site-packages $(VENV)
	@EVLOC_BUILD_DIR=$(abspath $(BUILD_DIR)) $(VENV)/bin/pip install --quiet --no-build-isolation \
	  --no-index --force-reinstall --no-deps ./python
	@echo "make python: the evloc package is installed in $(VENV); run $(VENV)/bin/python"

clean:
	rm -rf $(BUILD_DIR) build-fuzz

format:
	@git ls-files '*.h' '*.cc' | xargs clang-format -i
