#!/usr/bin/env bash
# A hysid campaign as separate processes on this machine: one coordinator
# (Zenoh router on 127.0.0.1) and N islands connecting to it, exactly the
# commands a cluster runs, each process with its own log. Use it to rehearse a
# multi-machine campaign (same configs, same key space) before going to
# several machines. (`hysid campaign` does the same in one command.) The
# coordinator writes a member secret for each island beside its database
# (--member island-K); each island reads its own there (--secret-file, waiting
# for it while the coordinator starts), so that each is a member of its own.
#
# usage: run-campaign.sh [-n ISLANDS] [-p PORT] [-c CAMPAIGN] [-o DIR] [-z ZENOH_DIR] [DATASET] [-- COORDINATOR_OPTION...]
#
#   -n ISLANDS    island processes (default 4; GA and PSO alternate)
#   -p PORT       coordinator port on 127.0.0.1 (default 7447)
#   -c CAMPAIGN   campaign name (default local)
#   -o DIR        logs, campaign.sqlite and report (default ./hysid-local-<time>)
#   -z ZENOH_DIR  directory with coordinator.json5 and island.json5 (default
#                 deploy/zenoh next to this script)
#   DATASET       measured loops, or synth (default)
#   -- ...        more `hysid coordinator` options, e.g. -- --time-limit 60 --iterations 200
#
# Ctrl-C stops every process it started. Exit status: the coordinator's, or the
# first failing island's.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
die() { echo "run-campaign.sh: error: $*" >&2; exit 2; }
islands=4
port=7447
campaign=local
outdir=./hysid-local-$(date +%Y%m%d-%H%M%S)
zenoh_dir=$here/../zenoh
while getopts ":n:p:c:o:z:h" opt; do
  case "$opt" in
    n) [[ $OPTARG =~ ^[1-9][0-9]*$ ]] || die "-n needs a positive number of islands, got '$OPTARG'"; islands=$OPTARG ;;
    p) [[ $OPTARG =~ ^[0-9]+$ ]] && (( OPTARG > 0 && OPTARG < 65536 )) || die "-p needs a TCP port (1-65535), got '$OPTARG'"; port=$OPTARG ;;
    c) campaign=$OPTARG ;;
    o) outdir=$OPTARG ;;
    z) zenoh_dir=$OPTARG ;;
    h) sed -n '/^# usage:/,/^# Ctrl-C/p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    :) die "option -$OPTARG needs a value" ;;
    *) die "unknown option -$OPTARG (see -h)" ;;
  esac
done
# getopts itself consumes a "--" that directly follows the options
last=$((OPTIND - 1))
options_ended=no
(( last > 0 )) && [[ ${!last} == -- ]] && options_ended=yes
shift $((OPTIND - 1))
dataset=synth
if [[ $options_ended == no && $# -gt 0 ]]; then
  [[ $1 == -- ]] || { dataset=$1; shift; }
  [[ $# -eq 0 || $1 == -- ]] || die "unexpected argument '$1' (coordinator options go after --)"
  [[ $# -gt 0 ]] && shift
fi
for f in coordinator.json5 island.json5; do [[ -r $zenoh_dir/$f ]] || die "no $zenoh_dir/$f"; done
hysid=${HYSID:-hysid}
command -v "$hysid" >/dev/null || die "'$hysid' not found: activate the venv where hysid is installed, or set HYSID"

mkdir -p "$outdir"
endpoint=tcp/127.0.0.1:$port
members=()
for ((k = 1; k <= islands; k++)); do members+=(--member "island-$k"); done
pids=()
stop_all() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; }
trap 'stop_all; exit 130' INT TERM

"$hysid" coordinator --config "$zenoh_dir/coordinator.json5" --listen "$endpoint" --campaign "$campaign" \
  --min-islands "$islands" --db "$outdir/campaign.sqlite" --out "$outdir/report" "${members[@]}" "$@" "$dataset" \
  > "$outdir/coordinator.log" 2>&1 &
coordinator=$!
pids+=("$coordinator")
for ((k = 1; k <= islands; k++)); do
  algo=ga; (( k % 2 )) || algo=pso
  "$hysid" island --config "$zenoh_dir/island.json5" --connect "$endpoint" --campaign "$campaign" \
    --secret-file "$outdir/campaign.sqlite-$campaign+island-$k.secret" \
    --id "island-$k" --seed "$k" --algo "$algo" > "$outdir/island-$k.log" 2>&1 &
  pids+=("$!")
done
echo "campaign $campaign: coordinator on $endpoint (pid $coordinator), $islands islands; logs in $outdir"

status=0
for pid in "${pids[@]:1}"; do wait "$pid" || { s=$?; (( status )) || status=$s; }; done
wait "$coordinator" || status=$?
trap - INT TERM
tail -n 3 "$outdir/coordinator.log"
echo "report: $outdir/report (exit status $status)"
exit "$status"
