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
# Python's bytecode caches are written (beside the sources, in the __pycache__ folders git ignores) even where
# the environment says not to (PYTHONDONTWRITEBYTECODE, as on the machine these tests were timed on): the suite starts
# hundreds of Python processes (its workers, CLI runs, coordinators and islands), and without the caches each
# compiles hysid's modules again and each worker rewrites the tests' asserts again (the fast lane on 2 cores,
# 3 workers, from no cache: 177-184 CPU-s without writing them, 145-151 s writing them).
unset PYTHONDONTWRITEBYTECODE
workers=$(($(nproc) + 1))
exec python -m pytest -q -n "$((workers < 8 ? workers : 8))" --dist worksteal "$@"
