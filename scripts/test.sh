#!/usr/bin/env bash
# The whole test suite on a fresh machine: install hysid with its test extras
# into .venv, then run pytest. Extra arguments go to pytest.
. "$(dirname "${BASH_SOURCE[0]}")/venv.sh" test
exec python -m pytest -q "$@"
