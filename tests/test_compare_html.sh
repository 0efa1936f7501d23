#!/usr/bin/env bash
# candela compare's index.html in a real headless browser (Chromium): every image and plot on the
# page loads. The page itself carries no test code: the test adds its own check to a copy
# (check.html, beside it so relative paths resolve) that writes the <img> elements that failed to
# decode (naturalWidth 0) into the DOM, which --dump-dom prints. The HTML is parsed for what it
# must hold: a row per image (reference + variants) with the image, the error map and the crop.
# A page with an image removed must be reported (the check can fail). Skips (77) without chromium.
# usage: test_compare_html.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
browser=$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)
if [ -z "$browser" ]; then echo "SKIP: no chromium on this machine (apt-get install chromium; .ci/setup installs it)"; exit 77; fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

dump() {  # the DOM of a copy of page $1 with the test's load check (virtual time: no waiting on the clock)
  local copy; copy=$(dirname "$1")/check.html
  sed 's|</body>|<script>window.addEventListener("load", function () { var bad = [], imgs = document.images;\
for (var i = 0; i < imgs.length; ++i) if (!imgs[i].complete \|\| imgs[i].naturalWidth === 0) bad.push(imgs[i].getAttribute("src"));\
var p = document.createElement("p"); p.id = "test-result"; p.textContent = "loaded " + (imgs.length - bad.length) + " of " + imgs.length + (bad.length ? " failed " + bad.join(" ") : "");\
document.body.appendChild(p); });</script></body>|' "$1" >"$copy"
  HOME=$tmp timeout 120 "$browser" --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --no-first-run \
    --user-data-dir="$tmp/profile" --virtual-time-budget=10000 --dump-dom "file://$copy" 2>"$tmp/browser.err"
}

out=$tmp/report
if ! "$bin" compare "$root/scenes/default.gltf" --spp 2 --res 32x24 --ref-spp 8 --out-dir "$out" --quiet \
     --variants "power: --light-sampler power; tree: --light-sampler tree" >/dev/null 2>"$tmp/err"; then
  echo "FAIL: compare: $(cat "$tmp/err")"; exit 1
fi
# the page's images: reference and its crop, three per variant (image, error map, crop), crops, two plots
want=$(grep -o '<img ' "$out/index.html" | wc -l)
[ "$want" -eq 11 ] && ok || bad "index.html has $want images, expected 11"
# one row per image, each with what it must show
[ "$(grep -c '<tr class="image-row">' "$out/index.html")" -eq 3 ] && ok || bad "index.html: not 3 image rows"
for v in power tree; do
  row=$(awk -v v="$v" 'index($0, "<tr class=\"image-row\"><th>" v "</th>") { on = 1 } on { print } on && /<\/tr>/ { exit }' "$out/index.html")
  for img in "$v.png" "${v}_error.png" "${v}_crop.png"; do
    echo "$row" | grep -q "src=\"$img\"" && ok || bad "$v's row lacks $img"
  done
  echo "$row" | grep -q 'class="colourbar"' && echo "$row" | grep -q '100 %' && ok || bad "$v's row lacks the colour bar"
done
grep -q 'IMAGES-OK\|<script' "$out/index.html" && bad "index.html holds a test marker or script" || ok
dom=$(dump "$out/index.html")
if echo "$dom" | grep -q "id=\"test-result\">loaded $want of $want<"; then ok
else bad "not every image loaded: $(echo "$dom" | grep -o 'id="test-result">[^<]*') $(tail -3 "$tmp/browser.err")"; fi
# the table is on the page, with a row per variant
echo "$dom" | grep -q "<td>tree</td>" && echo "$dom" | grep -q "<td>power</td>" && ok || bad "table rows missing from the page"

# the check can fail: a missing plot and a corrupt image are reported by name
rm "$out/convergence_time.svg"
echo "not a png" >"$out/tree_error.png"
dom=$(dump "$out/index.html")
echo "$dom" | grep -q "id=\"test-result\">loaded $((want - 2)) of $want failed tree_error.png convergence_time.svg<" && ok \
  || bad "a missing image went unnoticed: $(echo "$dom" | grep -o 'id="test-result">[^<]*')"
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
