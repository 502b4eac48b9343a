#!/usr/bin/env bash
# make experiment-paper: both paper scenarios at full size with the paper's presets (courtyard n 17 k 10,
# urban n 25 k 20, s 2 m). Long-running (simulation plus real-time playback per mode); not part of CI.
# Scenarios and tiles go to results/paper_data/ (large, not committed); summary, report and plots to
# results/paper/<scenario>/ (small, committed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="$root/results/paper_data"
gpm=(python3 "$root/scripts/gpm")
for scenario in courtyard urban; do
  if [[ ! -f "$data/$scenario/scenario.yaml" ]]; then
    "${gpm[@]}" simulate "$scenario" -o "$data/$scenario" --force
  fi
  "${gpm[@]}" experiment "$data/$scenario" --preset "$scenario" --tiles "$data/${scenario}_tiles_s2" \
    -o "$root/results/paper/$scenario"
done
