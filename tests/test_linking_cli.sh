#!/usr/bin/env bash
# extras.candela_light_linking's bad input through the CLI: each case is one line naming the
# file, the node and the problem, a non-zero exit and no output file; a null value and an
# empty include list are valid. Scenes are tests/scenes/linking_both.gltf with lamp_a's extras
# replaced (python3).
# usage: test_linking_cli.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }
command -v python3 >/dev/null || { echo "SKIP: no python3"; exit 77; }

# scene NAME JSON: linking_both.gltf with lamp_a's extras.candela_light_linking = JSON
scene() {
  python3 - "$root/tests/scenes/linking_both.gltf" "$tmp/$1.gltf" "$2" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
for n in doc['nodes']:
    if n.get('name') == 'lamp_a':
        n['extras'] = json.loads('{"candela_light_linking": %s}' % sys.argv[3])
json.dump(doc, open(sys.argv[2], 'w'))
PY
}

common=(-o "$tmp/out.exr" --res 8x8 --spp 1 --max-depth 1 --quiet)
expect_error() { # NAME JSON PATTERN
  scene "$1" "$2"
  rm -f "$tmp/out.exr" "$tmp/out.png"
  "$bin" render "$tmp/$1.gltf" "${common[@]}" >"$tmp/stdout" 2>"$tmp/stderr"; local rc=$?
  local lines; lines=$(grep -c . "$tmp/stderr")
  if [ $rc -eq 0 ] || [ $rc -ge 128 ]; then bad "$1: exit code $rc"; return; fi
  if [ "$lines" -ne 1 ]; then bad "$1: expected one error line, got $lines: $(cat "$tmp/stderr")"; return; fi
  for p in "$tmp/$1.gltf" "('lamp_a'): extras.candela_light_linking" "$3"; do
    grep -qF -- "$p" "$tmp/stderr" || { bad "$1: message lacks '$p': $(cat "$tmp/stderr")"; return; }
  done
  if ls "$tmp"/out.* >/dev/null 2>&1; then bad "$1: left an output file"; return; fi
  ok
}
expect_ok() { # NAME JSON [WARNING]
  scene "$1" "$2"
  if ! "$bin" render "$tmp/$1.gltf" "${common[@]}" 2>"$tmp/stderr"; then bad "$1: failed: $(cat "$tmp/stderr")"; return; fi
  if [ $# -ge 3 ] && ! grep -qF -- "$3" "$tmp/stderr"; then bad "$1: no warning '$3': $(cat "$tmp/stderr")"; return; fi
  ok
}

expect_error unknown_name '{"receivers": {"exclude": ["left", "nosuch"]}}' "no node named 'nosuch'"
expect_error both_lists '{"receivers": {"include": ["left"], "exclude": ["plate"]}}' 'both "include" and "exclude"'
expect_error no_list '{"receivers": {}}' 'needs "include" or "exclude"'
expect_error receivers_string '{"receivers": "left"}' 'receivers must be an object'
expect_error list_string '{"receivers": {"exclude": "left"}}' 'receivers.exclude must be an array of node names'
expect_error list_number '{"receivers": {"include": [3]}}' 'must be an array of node names (strings)'
expect_error not_object '["left"]' 'candela_light_linking must be an object'
expect_error blockers_include '{"blockers": {"include": ["plate"]}}' 'blockers must be an object with "exclude"'
expect_error blockers_unknown '{"blockers": {"exclude": ["plate", "ghost"]}}' "no node named 'ghost'"
expect_ok null_value 'null'
expect_ok empty_include '{"receivers": {"include": []}}'
expect_ok unknown_key '{"receivers": {"exclude": ["left"]}, "colour": 1}' "unknown key 'colour' ignored"

echo "linking cli: $pass passed, $fail failed"
[ $fail -eq 0 ]
