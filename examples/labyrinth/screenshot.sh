#!/usr/bin/env bash
# Takes the README's screenshot of the game under Xvfb with Mesa's software Vulkan driver
# (Debian: xvfb mesa-vulkan-drivers libvulkan1 libxcursor1 libxrandr2 libxi6
# libxkbcommon-x11-0 x11-apps imagemagick), and prints the frame rate it reached there.
# Usage: examples/labyrinth/screenshot.sh [OUT.png] [SECONDS] [GAME FLAGS…] (default --many)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-$here/../../docs/images/labyrinth.png}"
seconds="${2:-9}"
shift $(( $# < 2 ? $# : 2 ))
flags=("$@")
if [ ${#flags[@]} -eq 0 ]; then flags=(--many); fi
cd "$here"
cargo build --release --ignore-rust-version
runtime="$(mktemp -d)"
trap 'kill "${game:-}" "${xvfb:-}" 2>/dev/null || true; rm -rf "$runtime"' EXIT
Xvfb :99 -screen 0 1280x800x24 >/dev/null 2>&1 &
xvfb=$!
sleep 1
export DISPLAY=:99 XDG_RUNTIME_DIR="$runtime" WINIT_UNIX_BACKEND=x11
target/release/marble-labyrinth "${flags[@]}" --autoplay --exit-after "$seconds" > "$runtime/game.log" 2>&1 &
game=$!
# The autoplay sweeps the tilt from 1 s of game time (300 marbles: --many); software rendering starts slowly, so wait
# for most of the run before the capture.
sleep "$(( seconds - 2 ))"
xwd -root -silent -display :99 > "$runtime/shot.xwd"
convert "$runtime/shot.xwd" "$out"
wait "$game" || true
grep -E "fps on average" "$runtime/game.log" || tail -5 "$runtime/game.log"
echo "screenshot: $out"
