# drive-gateway: the two commands are `make run` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test test-web test-opcua test-vcan lint typecheck pytest bench soak clean venv install dist

venv: $(STAMP)

$(STAMP): pyproject.toml setup.py adapters/link/_ring.c
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "drive-gateway needs Python 3.11 or newer; $(PYTHON) is " + sys.version.split()[0] + " (try: make PYTHON=python3.11 ...)")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	@echo "drive-gateway demo: the status page will be at http://127.0.0.1:8080/ ([web] bind of config/demo.toml)"
	@echo "drive-gateway demo: the OPC UA server will be at opc.tcp://127.0.0.1:4840/drive-gateway ([opcua] bind, security none on loopback)"
	$(BIN)/drive-gateway run --config config/demo.toml

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

pytest: $(STAMP)
	$(BIN)/python -m pytest -q

test: lint typecheck pytest

# The status page in a real browser: Debian's Chromium driven by Playwright (tests/web,
# marker `browser`, left out of `make test`). Installs chromium when missing (as root).
CHROMIUM ?= /usr/bin/chromium
test-web: $(STAMP)
	@if [ ! -x "$(CHROMIUM)" ]; then \
		if [ "$$(id -u)" = 0 ]; then \
			apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends chromium; \
		else \
			echo "make test-web needs Debian's chromium at $(CHROMIUM): run 'sudo apt-get install --no-install-recommends chromium' (or make test-web as root), or set CHROMIUM=..." >&2; \
			exit 1; \
		fi; \
	fi
	DRIVE_GATEWAY_CHROMIUM=$(CHROMIUM) $(BIN)/python -m pytest -q -m browser tests/web

# The OPC UA server with a client of another stack: node-opcua's client (npm, the versions of
# tests/opcua_client/package-lock.json) run by Node.js as its own process. Installs Debian's
# nodejs when node is missing (as root); node-opcua goes to tests/opcua_client/node_modules.
NODE ?= node
OPCUA_CLIENT := tests/opcua_client
test-opcua: $(STAMP)
	@if ! command -v $(NODE) >/dev/null 2>&1; then \
		if [ "$$(id -u)" = 0 ]; then \
			apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends nodejs npm; \
		else \
			echo "make test-opcua needs Node.js: run 'sudo apt-get install --no-install-recommends nodejs npm' (or make test-opcua as root), or set NODE=..." >&2; \
			exit 1; \
		fi; \
	fi
	cd $(OPCUA_CLIENT) && npm ci --no-audit --no-fund --loglevel=error
	DRIVE_GATEWAY_OPCUA_NODE=required $(BIN)/python -m pytest -q tests/opcua

# The `vcan` tests in a kernel with SocketCAN: this one's, else a qemu VM (tests/vcan_vm).
test-vcan: $(STAMP)
	$(BIN)/python -m tests.vcan_vm

bench: $(STAMP)
	$(BIN)/python -m bench

# The soak run: minutes, not in CI; SOAK_SECONDS bounds it (docs/reliability.md); then the
# safety model checks (tests/safety) with many more examples (docs/safety.md).
SOAK_SECONDS ?= 180
soak: $(STAMP)
	SOAK_SECONDS=$(SOAK_SECONDS) $(BIN)/python -m pytest -q -m slow tests/reliability
	DRIVE_GATEWAY_SOAK=1 $(BIN)/python -m pytest -q tests/safety

# A production install (as root): PREFIX/venv with the runtime dependencies only, the unit,
# /etc/drive-gateway/site.toml, the user, completions and man page; it prints the next steps
# (docs/operations.md, "Installing on an edge box"). Every path below can be given.
PREFIX      ?= /opt/drive-gateway
SYSCONFDIR  ?= /etc/drive-gateway
UNITDIR     ?= /etc/systemd/system
BINDIR      ?= /usr/local/bin
BASHCOMPDIR ?= /usr/local/share/bash-completion/completions
ZSHCOMPDIR  ?= /usr/local/share/zsh/site-functions
MANDIR      ?= /usr/local/share/man
SERVICE_USER ?= drive-gateway
CREATE_USER ?= yes
WHEEL       ?=
install:
	$(PYTHON) packaging/install.py --prefix "$(PREFIX)" --sysconfdir "$(SYSCONFDIR)" \
	    --unitdir "$(UNITDIR)" --bindir "$(BINDIR)" --bashcompdir "$(BASHCOMPDIR)" \
	    --zshcompdir "$(ZSHCOMPDIR)" --mandir "$(MANDIR)" --user "$(SERVICE_USER)" \
	    --create-user "$(CREATE_USER)" --python "$(PYTHON)" $(if $(WHEEL),--wheel "$(WHEEL)")

# The wheel and the sdist (in dist/), as `pip install` takes them.
dist: $(STAMP)
	$(BIN)/python -m build --outdir dist .

clean:
	rm -rf $(VENV) build dist *.egg-info .mypy_cache .pytest_cache .ruff_cache .vcan-vm
