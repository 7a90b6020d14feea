#!/usr/bin/env bash
# The whole test suite on a fresh machine: install hysid with its test extras
# into .venv, then run pytest on one worker per core and one more (pytest-xdist;
# at most 8), each taking the next test as it frees: a third of the suite's time
# is campaigns of island processes, whose tests wait on sockets, processes and
# the campaign's clock, and the extra worker runs another test meanwhile (on
# 2 cores, the campaign, fault and attack tests: 367 s with 2 workers, 313 s
# with 3). Extra arguments go to pytest, and win: `bash scripts/test.sh -n 0`
# runs in one process.
. "$(dirname "${BASH_SOURCE[0]}")/venv.sh" test,lint  # lint: the checkers of scripts/lint.sh, one install for both
workers=$(($(nproc) + 1))
exec python -m pytest -q -n "$((workers < 8 ? workers : 8))" --dist worksteal "$@"
