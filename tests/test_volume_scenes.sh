#!/usr/bin/env bash
# scenes/make_volumes.py: the generator runs, is deterministic (twice into two folders: the
# .gltf and .exr files byte-identical, each .vdb pair differing only inside the 36-byte UUID
# of the file header), stays small, and every scene it writes loads and renders through the
# CLI (8x8, 1 spp: the loader accepts every candela_volume / candela_medium it wrote).
# Skips (exit 77) when no python3 can import pyopenvdb and numpy.
# usage: test_volume_scenes.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
py=""
for c in python3 /usr/bin/python3; do
  if command -v "$c" >/dev/null 2>&1 && "$c" -c "import pyopenvdb, numpy" >/dev/null 2>&1; then py=$c; break; fi
done
if [ -z "$py" ]; then
  echo "SKIP: no python3 with pyopenvdb and numpy (apt-get install python3-openvdb python3-numpy)"
  exit 77
fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

for run in a b; do
  if "$py" "$root/scenes/make_volumes.py" "$tmp/$run" >"$tmp/gen_$run.log" 2>&1; then ok
  else bad "make_volumes.py run $run: $(tail -n 5 "$tmp/gen_$run.log")"; fi
done

expected="smoke_plume.vdb fireball.vdb mist.vdb dense_cloud.vdb fig9_thin.gltf fig9_thick.gltf torch_mist.gltf
          spots_atmosphere.gltf cloud_point_env.gltf sky_constant.exr glass_absorb.gltf camera_in_fog.gltf"
for f in $expected; do
  [ -s "$tmp/a/$f" ] && ok || bad "$f not written"
done

# determinism: OpenVDB writes a fresh UUID at bytes 22..57 (1-based) of every .vdb
for a in "$tmp"/a/*; do
  f=$(basename "$a"); b=$tmp/b/$f
  if [ ! -e "$b" ]; then bad "$f: only in the first run"; continue; fi
  if [ "$(stat -c %s "$a")" != "$(stat -c %s "$b")" ]; then bad "$f: sizes differ between runs"; continue; fi
  case $f in
    *.vdb) cmp -l "$a" "$b" | awk '$1 < 22 || $1 > 57 { bad = 1 } END { exit bad }' \
             && ok || bad "$f: voxel data differ between runs" ;;
    *) cmp -s "$a" "$b" && ok || bad "$f: differs between runs" ;;
  esac
done

total=$(du -sb "$tmp/a" | cut -f1)
[ "$total" -lt 30000000 ] && ok || bad "output is $total bytes (limit 30 MB)"

# every scene loads (volumes, media, environment) and renders a tiny image
for g in "$tmp"/a/*.gltf; do
  name=$(basename "$g" .gltf)
  rm -f "$tmp/out.exr"
  if "$bin" render "$g" --res 8x8 --spp 1 --quiet --no-png -o "$tmp/out.exr" >"$tmp/$name.log" 2>&1 \
      && [ -s "$tmp/out.exr" ]; then ok
  else bad "$name: $(head -c 600 "$tmp/$name.log")"; fi
done

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
