#!/usr/bin/env bash
# The main job on a fresh machine: install hysid into .venv, then run a campaign
# on the built-in Synth set. Extra arguments go to `hysid campaign`.
. "$(dirname "${BASH_SOURCE[0]}")/venv.sh" ""  # "": no extras (an empty argument keeps "$@" for hysid)
exec hysid campaign "$@"
