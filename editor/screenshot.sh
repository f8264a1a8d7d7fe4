#!/usr/bin/env bash
# Opens a graph in relume-editor inside a virtual X display (Xvfb, Mesa's software OpenGL),
# runs it, waits until the viewer shows the image, and saves an in-app screenshot.
# Exit status 0 when the viewer shows a picture, 2 when it looks blank.
#
#   editor/screenshot.sh [GRAPH.ron] [OUT.png] [EDITOR OPTIONS]   (defaults: graphs/pbgi_cornell.ron docs/editor.png)
#   editor/screenshot.sh graphs/pbgi_cornell.ron docs/editor.png --select gather
#   editor/screenshot.sh graphs/ptt_envlit.ron docs/graphs/ptt_envlit.png --graph-only --window 2400x1300
#
# Needs Xvfb and Mesa: `apt-get install xvfb xauth libgl1-mesa-dri`. With RELUME_EDITOR set to
# an editor binary (CI passes the one `cargo test --workspace --release` built), that one runs
# and nothing is built.
set -euo pipefail
cd "$(dirname "$0")/.."
graph="${1:-graphs/pbgi_cornell.ron}"
out="${2:-docs/editor.png}"
mkdir -p "$(dirname "$out")"
editor="${RELUME_EDITOR:-}"
if [ -z "$editor" ]; then
  cargo build --release -p relume-editor
  editor=target/release/relume-editor
fi
# Software rendering: there is no GPU under Xvfb.
export LIBGL_ALWAYS_SOFTWARE=1
shift $(( $# > 2 ? 2 : $# ))
# The virtual screen holds the window: 1400 x 900, or larger for --window WxH.
screen=1400x900
prev=
for a in "$@"; do
  if [ "$prev" = --window ]; then screen="${a%x*}x$(( ${a#*x} + 40 ))"; fi
  prev="$a"
done
xvfb-run -a -s "-screen 0 ${screen}x24" "$editor" "$graph" --screenshot "$out" --timeout 900 "$@"
