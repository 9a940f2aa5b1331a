#!/usr/bin/env bash
# Generates motion with the shipped generator on a human, a quadruped and a zero-shot skeleton,
# imports each BVH with Blender's own importer and checks anymo's forward kinematics against
# Blender's bone positions (tests/blender_fk.rs over the generated files).
# Usage: bash tools/blender_generated.sh [OUT_DIR]   (needs blender on PATH and ../shared/data)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/anymo-generated}
data=../shared/data
rm -rf "$out" && mkdir -p "$out/files" "$out/refs"
: > "$out/files/manifest.tsv"
anymo=./target/release/anymo
[ -x "$anymo" ] || cargo build --release -p anymo-cli
declare -A skeletons=(
  [human]=bandai/dataset-1/dataset-1_walk_normal_001.bvh.gz
  [horse]=quaternius/bvh/animals_pack/Horse__Walk.bvh.gz
  [spider]=quaternius/bvh/easy_enemies_pack/Spider__Spider_Walk.bvh.gz
)
declare -A prompts=([human]="a person walks forward" [horse]="a horse gallops" [spider]="a spider crawls forward")
for name in human horse spider; do
  "$anymo" generate "${prompts[$name]}" --skeleton "$data/${skeletons[$name]}" --seconds 4 --seed 1 -o "$out/files/$name.bvh"
  echo "$name.bvh" >> "$out/list.txt"
done
blender -b --factory-startup --python-exit-code 1 --python tools/blender_fk_batch.py -- "$out/files" "$out/list.txt" "$out/refs"
ANYMO_DATA="$out/files" ANYMO_BLENDER_REFS="$out/refs" cargo test --release -p anymo-tests --test blender_fk -- --nocapture
