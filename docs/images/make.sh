#!/usr/bin/env bash
# Remakes the README's pictures from the default job: a screenshot of the replay page half
# a second in, and the top view and plots. Needs Debian's chromium (apt-get install chromium).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$here/../.."
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
(cd "$root" && cargo build --release --bin marble)
(cd "$tmp" && "$root/target/release/marble" > /dev/null)
shot() { # URL OUT WIDTH HEIGHT
  chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --hide-scrollbars --user-data-dir="$tmp/profile" --virtual-time-budget=3000 \
    --window-size="$3,$4" --screenshot="$2" "$1" 2> /dev/null
}
shot "file://$tmp/marble-out/default.html#t=0.6" "$here/replay.png" 1300 860
shot "file://$tmp/marble-out/default.svg" "$here/plot.png" 1400 720
ls -l "$here"/*.png
