#!/usr/bin/env bash
# Run every `hysid bench ...` command (or only those named as arguments) and store each
# one's JSON as bench/results/<bench>-<YYYY-MM-DD>-<hostname>.json (date and machine inside too).
# Uses the `hysid` on PATH (e.g. of an activated venv), else sets up .venv like scripts/main.sh.
# Run on a quiet machine (the load average is printed).
#   bash bench/run.sh              # all benches
#   bash bench/run.sh objective    # one
#   bash bench/run.sh islands:mixed   # one part of a bench -> bench/results/islands-mixed-<date>-<host>.json
set -euo pipefail
if command -v hysid >/dev/null; then
  cd "$(dirname "${BASH_SOURCE[0]}")/.."
else
  . "$(dirname "${BASH_SOURCE[0]}")/../scripts/venv.sh"
fi
if [ "$#" -gt 0 ]; then
  benches=("$@")
else
  python="$(dirname "$(command -v hysid)")/python"
  names="$("${python}" -c 'from hysid.cli.bench import bench_names; print("\n".join(bench_names()))')"
  mapfile -t benches <<<"${names}"
fi
mkdir -p bench/results
stamp="$(date +%F)-$(hostname)"
status=0
for name in "${benches[@]}"; do
  bench="${name%%:*}"
  part=()
  [ "${name}" != "${bench}" ] && part=("${name#*:}")
  out="bench/results/${bench}${part:+-${part[0]}}-${stamp}.json"
  echo "hysid bench ${bench} ${part[*]} -> ${out} (load average: $(cut -d' ' -f1-3 /proc/loadavg))" >&2
  if hysid bench "${bench}" "${part[@]}" --json >"${out}.part"; then
    mv "${out}.part" "${out}"
  else
    rm -f "${out}.part"
    echo "hysid bench ${name} failed" >&2
    status=1
  fi
done
exit "${status}"
