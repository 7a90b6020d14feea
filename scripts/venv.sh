# Sourced by main.sh, test.sh and lint.sh: make .venv (once) and install hysid into it (for the tests, compile its kernels).
# Usage: . scripts/venv.sh EXTRAS   e.g. ". scripts/venv.sh test", or ". scripts/venv.sh \"\"" for none
# (always pass an argument: without one, bash hands the caller's arguments to this script).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="${PYTHON:-python3}"
venv="${HYSID_VENV:-$repo/.venv}"
if [ ! -x "$venv/bin/python" ]; then
  "$python" -m venv "$venv"
fi
spec="$repo"
[ -n "${1:-}" ] && spec="$repo[$1]"
stamp="$venv/.hysid-installed-${1:-main}"
if [ ! -f "$stamp" ] || [ "$repo/pyproject.toml" -nt "$stamp" ]; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$spec"
  # for the tests: hysid's numba kernels compiled once into their cache beside the sources (about 30 s of CPU),
  # so that the test processes do not compile the same kernels side by side (hysid/kernels.py); the main job
  # (the thesis' model, closed form) uses none of them, and a command compiles what it uses on first use
  case ",${1:-}," in *,test,*) "$venv/bin/python" -m hysid.kernels ;; esac
  touch "$stamp"
fi
export PATH="$venv/bin:$PATH"
cd "$repo"
