#!/usr/bin/env bash
# candela compare's cached reference (OUT/reference.key, issue 27): keyed on the build (version,
# git revision and the binary's size and modification time), the scene file's content and the
# options that change the image.
# - an unchanged rerun reuses reference.exr (stderr: "reference, N spp, from OUT/reference.exr");
# - a rebuilt binary renders it again: simulated on a copy of the binary, once with a byte
#   appended (another size: an ELF runs with trailing bytes) and once touched (another time);
# - a scene whose content changed under the same size and modification time renders it again
#   (the key held the scene's size and time, not its content);
# - another image option (--max-depth) renders it again; --threads (no image change) reuses it.
# usage: test_reference_key.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

cp "$bin" "$tmp/candela"
cp "$root/tests/scenes/point_plane.gltf" "$tmp/scene.gltf"  # self-contained (data: URI)
out=$tmp/report
# run NAME EXPECT [FLAGS...]: a comparison into $out whose reference is EXPECT (rendered|reused)
run() {
  local name=$1 want=$2; shift 2
  if ! "$tmp/candela" compare "$tmp/scene.gltf" --res 16x12 --spp 2 --ref-spp 4 --strategies power --out-dir "$out" \
      "$@" 2>"$tmp/err" >/dev/null; then
    bad "$name: compare failed: $(cat "$tmp/err")"; return
  fi
  local got=rendered
  grep -q "^candela compare: reference, 4 spp, from $out/reference.exr$" "$tmp/err" && got=reused
  grep -q "^candela compare: reference, 4 spp$" "$tmp/err" || [ $got = reused ] || got=unknown
  [ $got = "$want" ] && ok || bad "$name: the reference was $got, expected $want: $(grep reference "$tmp/err")"
}
run "first run" rendered
run "unchanged rerun" reused
run "--threads 1 (no image change)" reused --threads 1
grep -q "^build candela .* (git .*); binary [0-9]* bytes " "$out/reference.key" && ok ||
  bad "reference.key does not name the build: $(head -c 300 "$out/reference.key")"
# a rebuilt binary: another size
printf '\0' >> "$tmp/candela"
run "binary of another size" rendered
run "unchanged rerun after the rebuild" reused
# a rebuilt binary: the same size, another modification time
touch -d '2001-01-01 00:00:00' "$tmp/candela"
run "binary of another time" rendered
run "unchanged rerun after the touch" reused
# the scene's content changed, its size and time kept: rendered again
stamp=$(stat -c %y "$tmp/scene.gltf")
sed -i 's/"intensity": 6.2831853/"intensity": 6.2831854/' "$tmp/scene.gltf"
touch -d "$stamp" "$tmp/scene.gltf"
grep -q '"intensity": 6.2831854' "$tmp/scene.gltf" && ok || bad "the scene edit did not apply"
run "scene content changed, same size and time" rendered
run "another --max-depth" rendered --max-depth 2
run "the same --max-depth again" reused --max-depth 2

echo "reference key tests: $pass passed, $fail failed"
[ $fail -eq 0 ]
