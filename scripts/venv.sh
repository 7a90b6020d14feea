# Sourced by main.sh and test.sh: make .venv (once) and install hysid into it.
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
  touch "$stamp"
fi
export PATH="$venv/bin:$PATH"
cd "$repo"
