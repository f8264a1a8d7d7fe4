#!/usr/bin/env bash
# Draws each pipeline's graph as the editor shows it (the node graph alone, not run) into
# docs/graphs/NAME.png for the book's pipeline pages. Needs what editor/screenshot.sh needs.
#
#   editor/shoot_graphs.sh [GRAPH NAME ...]   (default: the graphs the pipeline pages show)
set -euo pipefail
cd "$(dirname "$0")/.."
names=("$@")
if [ ${#names[@]} -eq 0 ]; then
  names=(reference_cornell pbgi_cornell fpbgi_cornell wpbgi_ring vpbgi_cornell relight_cornell_bunny ptt_envlit refract_glass)
fi
if [ -z "${RELUME_EDITOR:-}" ]; then
  cargo build --release -p relume-editor
  export RELUME_EDITOR=target/release/relume-editor
fi
for name in "${names[@]}"; do
  editor/screenshot.sh "graphs/$name.ron" "docs/graphs/$name.png" --graph-only --window 2400x1300 --no-disk-cache
done
