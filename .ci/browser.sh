#!/usr/bin/env bash
# Loads a report.html in headless Chromium (Debian's package): the page must
# load with no console error, and its screenshot must not be blank.
# Usage: .ci/browser.sh REPORT.html SCREENSHOT.png
set -euo pipefail
report="$(realpath "$1")"
shot="$2"
if ! command -v chromium >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends chromium >/dev/null
fi
flags=(--headless --no-sandbox --disable-gpu --hide-scrollbars --no-first-run
  --disable-dev-shm-usage --enable-logging=stderr --v=0)
log="$(mktemp)"
# The DOM after load: the page parsed and every section is there.
timeout 120 chromium "${flags[@]}" --dump-dom "file://$report" > "$shot.dom.html" 2> "$log" || {
  cat "$log"; echo "chromium could not load $report"; exit 1; }
for s in s1 s2 s3 s4 s5 s6 s7; do
  grep -q "<section id=\"$s\"" "$shot.dom.html" || { echo "section $s missing in the loaded page"; exit 1; }
done
timeout 120 chromium "${flags[@]}" --window-size=1280,4000 --screenshot="$shot" "file://$report" >/dev/null 2>> "$log"
# Console messages from the page (errors, failed loads) appear as CONSOLE lines.
if grep -E "CONSOLE|Uncaught|Failed to load resource|net::ERR" "$log"; then
  echo "the report logged errors in the browser"; exit 1
fi
# A blank 1280x4000 page compresses to a few kB; the figures make it hundreds.
size=$(stat -c %s "$shot")
head -c 8 "$shot" | od -An -tx1 | grep -q "89 50 4e 47" || { echo "$shot is not a PNG"; exit 1; }
if [ "$size" -lt 50000 ]; then
  echo "screenshot $shot is $size bytes: blank?"; exit 1
fi
echo "report loaded in Chromium without console errors; screenshot $shot ($size bytes)"
