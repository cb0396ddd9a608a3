#!/usr/bin/env bash
# snapshot.sh MONOLITH OUT [FRAMES] [THREADS]
# Runs every built-in scene of `MONOLITH list` (not the `-paper` grids, too large for a routine
# check) for FRAMES frames (default 3) on THREADS threads (default 2) into OUT/<scene>; the 2D
# scenes also on the explicit back end (OUT/<scene>--explicit). OUT/rc.txt gets one exit code per run and OUT/DONE
# marks a finished snapshot; a restarted snapshot skips the runs that already exited 0.
# Two snapshots are compared with tests/tools/compare_snapshots.py (docs/validation.md,
# "Bit-for-bit snapshots").
set -u
if [ $# -lt 2 ]; then echo "usage: snapshot.sh MONOLITH OUT [FRAMES] [THREADS]" >&2; exit 2; fi
monolith=$1; out=$2; frames=${3:-3}; threads=${4:-2}
mkdir -p "$out"
"$monolith" list | awk '{print $1, $2}' > "$out/scenes.txt" || { echo "snapshot.sh: '$monolith list' failed" >&2; exit 2; }
run() {  # scene folder [flags...]
  local scene=$1 folder=$2; shift 2
  grep -qx "$folder rc 0" "$out/rc.txt" 2>/dev/null && return 0
  "$monolith" run "$scene" --frames "$frames" --threads "$threads" --quiet --out "$out/$folder" "$@" \
    > "$out/$folder.stdout" 2> "$out/$folder.stderr"
  echo "$folder rc $?" >> "$out/rc.txt"
}
while read -r scene dim; do
  case "$scene" in *-paper) continue ;; esac
  run "$scene" "$scene"
  if [ "$dim" = "2D" ]; then run "$scene" "$scene--explicit" --backend explicit; fi
done < "$out/scenes.txt"
touch "$out/DONE"
