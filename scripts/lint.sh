#!/usr/bin/env bash
# The checks .ci/run makes before the tests, each of which fails CI on any finding (configured in pyproject.toml):
#   ruff check .            lint (pyflakes, pycodestyle, isort, bugbear, pyupgrade, simplify, ruff's own rules)
#   ruff format --check .   the formatter's style
#   mypy                    types over hysid, hysid_model, island and coordinator
#   lint-imports            the import contracts: layers, optimizers free of Zenoh and msgpack, wire format below
#                           the node and transports, no import circles within a package
#   scripts/imports.py --check   docs/ARCHITECTURE.md's figure of the rooms and their imports is the code's
# `bash scripts/lint.sh --fix` first applies ruff's safe fixes and its formatter to the tree, then checks;
# what is left needs a hand (see the list each tool prints).
. "$(dirname "${BASH_SOURCE[0]}")/venv.sh" test,lint
if [ "${1:-}" = "--fix" ]; then
  ruff check --fix --quiet . || true  # non-zero while findings it cannot fix remain; the check below lists them
  ruff format --quiet .
  python scripts/imports.py --write
fi
status=0
check() {
  echo "== $*"
  "$@" || status=1
}
check ruff check .
check ruff format --check .
check mypy
check lint-imports
check python scripts/imports.py --check
exit "$status"
