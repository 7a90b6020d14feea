#!/usr/bin/env bash
# The whole test suite on a fresh machine: install hysid with its test extras
# into .venv, then run pytest on one worker per core (pytest-xdist; at most 8),
# each taking the next test as it frees. Extra arguments go to pytest, and win:
# `bash scripts/test.sh -n 0` runs in one process.
. "$(dirname "${BASH_SOURCE[0]}")/venv.sh" test,lint  # lint: the checkers of scripts/lint.sh, one install for both
exec python -m pytest -q -n auto --maxprocesses 8 --dist worksteal "$@"
