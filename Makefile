# glrmon — the one entry point. `make help` lists the targets.
SHELL := /bin/bash
CARGO ?= cargo

.DEFAULT_GOAL := help

.PHONY: help deps deps-zenohd deps-python build install uninstall check-install test fmt fmt-check lint unit doc check-deps check-config fuzz-build fuzz fuzz-all msrv demo bench bench-e2e bench-replay tank-table reproduce

help: ## list the targets
	@grep -E '^[a-zA-Z0-9_-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-11s %s\n", $$1, $$2}'

deps: deps-zenohd deps-python ## the toolchain (rustfmt, clippy), zenohd for the router-mesh test, the Python libraries of the binary-format tests
	@command -v $(CARGO) >/dev/null || { echo "cargo not found: install Rust (rustup)"; exit 1; }
	@$(CARGO) fmt --version >/dev/null 2>&1 || rustup component add rustfmt
	@$(CARGO) clippy --version >/dev/null 2>&1 || rustup component add clippy

ZENOHD_VERSION := 1.10.2
ZENOHD := $(or $(CARGO_HOME),$(HOME)/.cargo)/bin/zenohd
ZENOH_PLUGIN := $(dir $(ZENOHD))libzenoh_plugin_storage_manager.so
deps-zenohd: ## zenohd (the Zenoh router) and its storage plugin from crates.io, built once (about 20 min on 2 cores), then kept in ~/.cargo/bin
	@if $(ZENOHD) --version 2>/dev/null | grep -q "v$(ZENOHD_VERSION)"; then echo "zenohd $(ZENOHD_VERSION): $(ZENOHD)"; \
	else echo "zenohd $(ZENOHD_VERSION) (the Zenoh router the router-mesh test runs) is not installed: building it from crates.io once, about 15 min on 2 cores; it is kept in $(ZENOHD)"; \
	$(CARGO) install zenohd --version $(ZENOHD_VERSION) --locked; fi
	@if [ -f $(ZENOH_PLUGIN) ]; then echo "zenohd storage plugin: $(ZENOH_PLUGIN)"; \
	else echo "zenohd's storage plugin (the alarm-history test's storages) is not installed: building it once, about 5 min on 2 cores; it is kept beside zenohd"; \
	CARGO=$(CARGO) scripts/zenoh-storage-plugin.sh $(ZENOHD_VERSION) $(dir $(ZENOHD)); fi

# The official libraries (mcap, mcap-ros2-support, mcap-protobuf-support, Google's protobuf) that write the
# binary payloads and foreign recordings the integration tests read, in a virtual
# environment beside the build: nothing is installed outside the checkout.
PYENV := $(or $(CARGO_TARGET_DIR),target)/pyenv
deps-python: $(PYENV)/installed ## the Python libraries the binary-format tests encode with, in target/pyenv (tests/python/requirements.txt)
$(PYENV)/installed: tests/python/requirements.txt
	python3 -m venv $(PYENV)
	$(PYENV)/bin/pip install -q --disable-pip-version-check -r tests/python/requirements.txt
	@touch $@

build: deps ## build everything (release)
	$(CARGO) build --release --workspace

test: deps fmt-check lint unit doc check-deps check-config check-install fuzz-build ## everything CI runs: fmt, clippy, all tests, docs, dependency rules, configs, install layout, fuzz targets build; ends with the tests' totals
	@cat $(TEST_TOTALS)

fmt: ## format the code
	$(CARGO) fmt --all

fmt-check:
	$(CARGO) fmt --all -- --check

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

# The tests' output is kept beside the build, and their totals (passed, failed, ignored,
# over every `test result` line) written to TEST_TOTALS, which `make test` prints last.
# WARN lines in the output come from the tests that feed bad input on purpose.
TEST_TOTALS := $(or $(CARGO_TARGET_DIR),target)/test-totals.txt
unit:
	@mkdir -p $(dir $(TEST_TOTALS))
	@set -o pipefail; { \
	  $(CARGO) test --workspace && \
	  echo "# The router-mesh test again on an in-process router session (the first run used zenohd)." && \
	  GLRMON_TEST_ROUTER=session $(CARGO) test -p glrmon-cli --test mesh; \
	} 2>&1 | tee $(TEST_TOTALS).log; status=$$?; \
	awk '/^test result:/ { p += $$4; f += $$6; i += $$8 } \
	  END { printf "tests: %d passed, %d failed, %d ignored (WARN lines above come from the tests that feed bad input on purpose; full output: %s)\n", p, f, i, out }' \
	  out=$(TEST_TOTALS).log $(TEST_TOTALS).log > $(TEST_TOTALS); \
	cat $(TEST_TOTALS); exit $$status

doc:
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --workspace --no-deps

check-deps: ## glrmon-core's and glrmon-ident's normal dependencies are nalgebra, thiserror (and, for glrmon-ident, glrmon-core) only (ARCHITECTURE.md invariant)
	@for c in glrmon-core glrmon-ident; do \
	deps=$$($(CARGO) tree -p $$c -e normal --depth 1 --prefix none | tail -n +2 | awk '{print $$1}' | sort -u | tr '\n' ' '); \
	echo "$$c depends on: $$deps"; \
	for d in $$deps; do case $$c:$$d in *:nalgebra|*:thiserror|glrmon-ident:glrmon-core) ;; *) echo "forbidden dependency of $$c: $$d"; exit 1;; esac; done; \
	done

check-config: ## glrmon validate every file in config/
	@$(CARGO) build -q -p glrmon-cli
	@g=$${CARGO_TARGET_DIR:-target}/debug/glrmon; for f in config/*.toml config/examples/*.toml; do $$g validate --config $$f >/dev/null || { $$g validate --config $$f; exit 1; }; echo "valid: $$f"; done

.PHONY: config-doc
config-doc: ## regenerate docs/CONFIG.md (the configuration reference) from the configuration types
	$(CARGO) run -q -p glrmon-spec --example config_reference > docs/CONFIG.md

fuzz-build: ## build the fuzz targets (fuzz/: sample, binary (CDR, Sparkplug B, raw), tags, monitor, record, status, config, expression, CSV, MCAP and foreign-message (ROS 2 CDR, protobuf) decoders) and run each on its regression inputs (fuzz/regressions/)
	$(CARGO) build --manifest-path fuzz/Cargo.toml --target-dir target
	@for t in $(FUZZ_TARGETS); do \
		if [ -d fuzz/regressions/$$t ]; then \
			target/debug/$$t fuzz/regressions/$$t -runs=0 >/dev/null 2>target/fuzz-$$t.log \
				|| { cat target/fuzz-$$t.log; echo "fuzz target $$t fails on its regression inputs"; exit 1; }; \
		fi; \
	done

FUZZ_TARGETS := samples binary tags monitor records status config expressions csv mcap foreign
FUZZ_TARGET ?= samples
FUZZ_SECONDS ?= 60
fuzz: ## run one fuzz target with cargo-fuzz (nightly), from its corpus and regression inputs: make fuzz FUZZ_TARGET=config FUZZ_SECONDS=600
	@command -v cargo-fuzz >/dev/null || $(CARGO) install cargo-fuzz --locked
	mkdir -p fuzz/corpus/$(FUZZ_TARGET)
	cd fuzz && $(CARGO) +nightly fuzz run $(FUZZ_TARGET) corpus/$(FUZZ_TARGET) $$([ -d regressions/$(FUZZ_TARGET) ] && echo regressions/$(FUZZ_TARGET)) -- -max_total_time=$(FUZZ_SECONDS)

fuzz-all: ## every fuzz target in turn, FUZZ_SECONDS each (make fuzz-all FUZZ_SECONDS=600)
	@for t in $(FUZZ_TARGETS); do $(MAKE) --no-print-directory fuzz FUZZ_TARGET=$$t || exit 1; done

MSRV := $(shell sed -n 's/^rust-version = "\(.*\)"/\1/p' Cargo.toml)
msrv: ## check the workspace on the declared rust-version (installs that toolchain with rustup; std APIs newer than it are already refused by clippy's incompatible_msrv in make lint)
	@rustup run $(MSRV) cargo --version >/dev/null 2>&1 || rustup toolchain install $(MSRV) --profile minimal
	$(CARGO) +$(MSRV) check --workspace --all-targets --locked

# `make install PREFIX=/usr/local`: the binary, its manual pages and shell completions
# (generated by the binary itself), the systemd units (paths rewritten to PREFIX and
# SYSCONFDIR), the documentation, and an example configuration in
# SYSCONFDIR/glrmon/glrmon.toml when none is there. DESTDIR stages a package. The
# binary is installed without its line tables, which go to DEBUGDIR (gnu-debuglink).
PREFIX ?= /usr/local
DEBUGDIR ?= /usr/lib/debug
SYSCONFDIR ?= /etc
SYSTEMDDIR ?= $(PREFIX)/lib/systemd/system
PROFILE ?= release
BIN := $${CARGO_TARGET_DIR:-target}/$(PROFILE)/glrmon
ROOT = $(DESTDIR)$(PREFIX)
DOCS := README.md docs/OPERATIONS.md docs/CONFIG.md docs/CLI.md docs/WIRE.md docs/IDENTIFY.md docs/MODELS.md docs/DETECTORS.md LICENSE-MIT LICENSE-APACHE
install: ## install glrmon (PREFIX=/usr/local SYSCONFDIR=/etc DESTDIR=; PROFILE=debug to skip the release build)
	@if [ "$(PROFILE)" = release ]; then $(CARGO) build --release -q -p glrmon-cli; else $(CARGO) build -q -p glrmon-cli; fi
	@tmp=$$(mktemp -d) && \
	if command -v objcopy >/dev/null; then \
		objcopy --only-keep-debug $(BIN) $$tmp/glrmon.debug && \
		objcopy --strip-debug --add-gnu-debuglink=$$tmp/glrmon.debug $(BIN) $$tmp/glrmon && \
		install -Dm644 $$tmp/glrmon.debug $(DESTDIR)$(DEBUGDIR)$(PREFIX)/bin/glrmon.debug && \
		echo "installed $(DESTDIR)$(DEBUGDIR)$(PREFIX)/bin/glrmon.debug (line tables, for perf and gdb)"; \
	else cp $(BIN) $$tmp/glrmon; echo "objcopy not found: the binary keeps its line tables"; fi && \
	install -Dm755 $$tmp/glrmon $(ROOT)/bin/glrmon && echo "installed $(ROOT)/bin/glrmon" && rm -rf $$tmp
	@tmp=$$(mktemp -d) && $(BIN) man --out-dir $$tmp >/dev/null && \
		install -d $(ROOT)/share/man/man1 && install -m644 $$tmp/*.1 $(ROOT)/share/man/man1/ && rm -rf $$tmp
	install -d $(ROOT)/share/bash-completion/completions $(ROOT)/share/zsh/site-functions $(ROOT)/share/fish/vendor_completions.d
	$(BIN) completions bash > $(ROOT)/share/bash-completion/completions/glrmon
	$(BIN) completions zsh > $(ROOT)/share/zsh/site-functions/_glrmon
	$(BIN) completions fish > $(ROOT)/share/fish/vendor_completions.d/glrmon.fish
	install -d $(ROOT)/share/doc/glrmon $(DESTDIR)$(SYSTEMDDIR)
	install -m644 $(DOCS) $(ROOT)/share/doc/glrmon/
	install -m644 deploy/glrmon.toml $(ROOT)/share/doc/glrmon/glrmon.example.toml
	@for u in glrmon.service glrmon@.service; do \
		sed -e 's|/usr/local/bin/glrmon|$(PREFIX)/bin/glrmon|g' -e 's|/etc/glrmon/|$(SYSCONFDIR)/glrmon/|g' \
			-e 's|/usr/local/share/doc/glrmon|$(PREFIX)/share/doc/glrmon|g' deploy/$$u > $(DESTDIR)$(SYSTEMDDIR)/$$u; \
		echo "installed $(DESTDIR)$(SYSTEMDDIR)/$$u"; done
	@if [ -e $(DESTDIR)$(SYSCONFDIR)/glrmon/glrmon.toml ]; then echo "kept $(DESTDIR)$(SYSCONFDIR)/glrmon/glrmon.toml"; \
	else install -Dm644 deploy/glrmon.toml $(DESTDIR)$(SYSCONFDIR)/glrmon/glrmon.toml; fi

uninstall: ## remove what `make install` installed (the configuration in SYSCONFDIR stays)
	rm -f $(ROOT)/bin/glrmon $(DESTDIR)$(DEBUGDIR)$(PREFIX)/bin/glrmon.debug $(ROOT)/share/man/man1/glrmon.1 $(ROOT)/share/man/man1/glrmon-*.1
	rm -f $(ROOT)/share/bash-completion/completions/glrmon $(ROOT)/share/zsh/site-functions/_glrmon $(ROOT)/share/fish/vendor_completions.d/glrmon.fish
	rm -rf $(ROOT)/share/doc/glrmon
	rm -f $(DESTDIR)$(SYSTEMDDIR)/glrmon.service $(DESTDIR)$(SYSTEMDDIR)/glrmon@.service

check-install: ## install (debug build) into a scratch prefix and check the layout, the installed binary, config and man page
	@d=$$(mktemp -d) && trap 'rm -rf $$d' EXIT && \
	$(MAKE) --no-print-directory -s install PROFILE=debug PREFIX=$$d/usr SYSCONFDIR=$$d/etc DEBUGDIR=$$d/debug >/dev/null && \
	for f in usr/bin/glrmon usr/share/man/man1/glrmon.1 usr/share/man/man1/glrmon-run.1 \
		usr/share/bash-completion/completions/glrmon usr/share/zsh/site-functions/_glrmon \
		usr/share/fish/vendor_completions.d/glrmon.fish usr/share/doc/glrmon/OPERATIONS.md \
		usr/share/doc/glrmon/LICENSE-APACHE usr/lib/systemd/system/glrmon.service etc/glrmon/glrmon.toml; do \
		[ -s $$d/$$f ] || { echo "make install did not write $$f"; exit 1; }; done && \
	grep -q "ExecStart=$$d/usr/bin/glrmon run --config $$d/etc/glrmon/glrmon.toml" $$d/usr/lib/systemd/system/glrmon.service && \
	$$d/usr/bin/glrmon validate --config $$d/etc/glrmon/glrmon.toml >/dev/null && \
	$$d/usr/bin/glrmon --version && echo "make install: layout, units, example configuration checked"

demo: ## the main job on built-in simulated channels with an injected fault (the first release build takes about 18 min on 2 cores)
	@[ -x $${CARGO_TARGET_DIR:-target}/release/glrmon ] || echo "building glrmon (release, about 400 crates): about 18 min on 2 cores the first time, seconds afterwards"
	$(CARGO) build --release -p glrmon-cli
	$${CARGO_TARGET_DIR:-target}/release/glrmon demo

reproduce: ## regenerate the command blocks of docs/REPRODUCTION.md: Zhang 2021 Tables I and II, the 2014 gas-pipeline Monte Carlo, Willsky–Jones (~6 min on 2 cores after the release build)
	bash scripts/reproduce.sh

tank-table: ## the quadruple-tank identify → calibrate → monitor table of docs/IDENTIFY.md (50 runs per fault)
	cargo run --release -q -p glrmon-eval --example quadruple_tank_table

bench: ## every criterion benchmark: the per-sample step and the sparse diagnosis (figures in docs/PERFORMANCE.md)
	$(CARGO) bench --workspace

bench-e2e: ## end-to-end load through Zenoh on loopback beside Zenoh alone: 100 and 1000 channels, and a plant-wide alarm burst with recording (figures in docs/PERFORMANCE.md)
	$(CARGO) run --release -q -p glrmon-zenoh --example bench_e2e -- --channels 100 --samples 5000 --batch 1 --rates 0,500000,700000
	$(CARGO) run --release -q -p glrmon-zenoh --example bench_e2e -- --channels 1000 --samples 1000 --batch 1 --rates 100000
	rm -rf $(BENCH_DIR)/burst
	$(CARGO) run --release -q -p glrmon-zenoh --example bench_e2e -- --channels 1000 --samples 40 --batch 1 --rates 5000 --faulty-every 1 --stat-every 1 --record $(BENCH_DIR)/burst

BENCH_DIR ?= /tmp/glrmon-bench
BENCH_SAMPLES ?= 10000000
bench-replay: ## replay throughput and peak RSS on a 10 M-sample bench-A recording; recording overhead (figures in docs/PERFORMANCE.md)
	$(CARGO) build --release -q -p glrmon-cli
	mkdir -p $(BENCH_DIR)
	./target/release/glrmon simulate --config config/demo.toml --channel lpv --samples $(BENCH_SAMPLES) --output $(BENCH_DIR)/a.csv
	./target/release/glrmon replay --quiet --config config/demo.toml --channel lpv $(BENCH_DIR)/a.csv --output $(BENCH_DIR)/a.mcap
	./target/release/glrmon replay --quiet --stat-every 0 --config config/demo.toml --channel lpv $(BENCH_DIR)/a.csv --output $(BENCH_DIR)/in.mcap
	ls -l $(BENCH_DIR)/a.csv $(BENCH_DIR)/a.mcap $(BENCH_DIR)/in.mcap
	/usr/bin/time -f "replay inputs-only MCAP -> alarms only: %e s wall, %M KiB peak RSS" ./target/release/glrmon replay --quiet --stat-every 0 $(BENCH_DIR)/in.mcap --output /dev/null
	/usr/bin/time -f "replay CSV -> alarms only: %e s wall, %M KiB peak RSS" ./target/release/glrmon replay --quiet --stat-every 0 --config config/demo.toml --channel lpv $(BENCH_DIR)/a.csv --output /dev/null
	/usr/bin/time -f "replay CSV -> JSONL (every stat): %e s wall, %M KiB peak RSS" ./target/release/glrmon replay --quiet --config config/demo.toml --channel lpv $(BENCH_DIR)/a.csv --output /dev/null
	/usr/bin/time -f "replay MCAP -> JSONL (every stat): %e s wall, %M KiB peak RSS" ./target/release/glrmon replay --quiet $(BENCH_DIR)/a.mcap --output /dev/null
	/usr/bin/time -f "replay MCAP -> MCAP: %e s wall, %M KiB peak RSS" ./target/release/glrmon replay --quiet $(BENCH_DIR)/a.mcap --output $(BENCH_DIR)/b.mcap
	$(CARGO) run --release -q -p glrmon-zenoh --example bench_e2e -- --channels 100 --samples 2000 --batch 10
	$(CARGO) run --release -q -p glrmon-zenoh --example bench_e2e -- --channels 100 --samples 2000 --batch 10 --record $(BENCH_DIR)/rec
