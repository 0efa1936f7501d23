#!/usr/bin/env bash
# candela compare's index.html in a real headless browser (Chromium): every image and plot on the
# page loads. The page checks itself on load (naturalWidth > 0 for every <img>) and writes
# "IMAGES-OK N" or "IMAGES-FAILED <files>" into #load-check, which --dump-dom prints. A page with
# an image removed must report it (the check can fail). Skips (77) without chromium.
# usage: test_compare_html.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
browser=$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)
if [ -z "$browser" ]; then echo "SKIP: no chromium on this machine (apt-get install chromium; .ci/setup installs it)"; exit 77; fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

dump() {  # the DOM after the page's scripts ran (virtual time: no waiting on the clock)
  HOME=$tmp timeout 120 "$browser" --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --no-first-run \
    --user-data-dir="$tmp/profile" --virtual-time-budget=10000 --dump-dom "file://$1" 2>"$tmp/browser.err"
}

out=$tmp/report
if ! "$bin" compare "$root/scenes/default.gltf" --spp 2 --res 32x24 --ref-spp 8 --out-dir "$out" --quiet \
     --variants "power: --light-sampler power; tree: --light-sampler tree" >/dev/null 2>"$tmp/err"; then
  echo "FAIL: compare: $(cat "$tmp/err")"; exit 1
fi
# the page's images: reference, two per variant, crops, two plots
want=$(grep -o '<img ' "$out/index.html" | wc -l)
[ "$want" -eq 8 ] && ok || bad "index.html has $want images, expected 8"
dom=$(dump "$out/index.html")
if echo "$dom" | grep -q "IMAGES-OK $want<"; then ok
else bad "not every image loaded: $(echo "$dom" | grep -o 'id="load-check">[^<]*') $(tail -3 "$tmp/browser.err")"; fi
# the table is on the page, with a row per variant
echo "$dom" | grep -q "<td>tree</td>" && echo "$dom" | grep -q "<td>power</td>" && ok || bad "table rows missing from the page"

# the check can fail: a missing plot and a corrupt image are reported by name
rm "$out/convergence_time.svg"
echo "not a png" >"$out/tree_error.png"
dom=$(dump "$out/index.html")
echo "$dom" | grep -q "IMAGES-FAILED convergence_time.svg tree_error.png<" && ok \
  || bad "a missing image went unnoticed: $(echo "$dom" | grep -o 'id="load-check">[^<]*')"
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
