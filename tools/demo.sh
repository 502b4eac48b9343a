#!/usr/bin/env bash
# make demo: simulate the full-size courtyard world, 100 s of walking (cached in results/demo/scenario), then
# run the experiment in its default modes: global, grid_puzzle (the provider nodelet in the localizer's manager,
# what a user gets) and grid_puzzle_rospy (the paper's setup, a rospy provider process). Prints the grid puzzle
# modes against the global map (nodelet first) and writes the report and plots to results/demo/.
# Runs from a shell that sourced the devel space (the Makefile does that).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/results/demo"
scenario="$out/scenario"
# 100 s covers the first turn of the route (the map covers the whole route); the Livox-like sensor as in the paper.
sim_args=(courtyard --scale 1.0 --duration 100 --seed 1)
stamp="$scenario/.demo-args"
if [[ ! -f "$scenario/scenario.yaml" || "$(cat "$stamp" 2>/dev/null)" != "${sim_args[*]}" ]]; then
  echo "demo: simulating ${sim_args[*]} into $scenario"
  mkdir -p "$out"
  python3 "$root/scripts/gpm" simulate "${sim_args[@]}" -o "$scenario" --force --quiet
  echo "${sim_args[*]}" >"$stamp"
else
  echo "demo: reusing the scenario in $scenario"
fi
python3 "$root/scripts/gpm" experiment "$scenario" -o "$out" --preset demo --ndt-threads 2
