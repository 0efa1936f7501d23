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

# issue 29: small VDBs whose costs followed their bounding box, not their data (the majorant
# grid): two 4^3 blobs 5,100 voxels apart (19 KB; 2.2 GB and 25 s, three such nodes over 6 GB),
# one tile filling 4096^3 voxels (594 bytes; 1.2 GB and 10 s), a voxel of 1e30 (16 s in the
# cache point build); and the blobs 600,000 voxels apart, which a majorant over a dense
# directory of bricks refused (more than 2^28 cells), and emitting blobs 5,100 apart (the
# dense form refused: 9 GB over the default budget). Now the volumes' memory is reported (statistics JSON) in proportion to
# the data, --volume-budget-mb bounds it per scene, and the voxel is refused with one line.
"$py" - "$tmp/v29" <<'PY'
import os, sys, pyopenvdb as vdb
out = sys.argv[1]; os.makedirs(out, exist_ok=True)
def grid(): g = vdb.FloatGrid(); g.name = 'density'; g.transform = vdb.createLinearTransform(voxelSize=0.001); return g
t = grid(); t.fill((0, 0, 0), (4095, 4095, 4095), 0.25, True); vdb.write(out + '/tile.vdb', grids=[t])
b = grid(); a = b.getAccessor()
for base in (0, 5100):
    for i in range(64): a.setValueOn((base + i % 4, base + i // 4 % 4, base + i // 16), 1.0)
vdb.write(out + '/blobs.vdb', grids=[b])
f = grid(); a = f.getAccessor()  # 600,000 voxels apart: past the first sparse form's 2^28 cells
for base in (0, 600000):
    for i in range(64): a.setValueOn((base + i % 4, base + i // 4 % 4, base + i // 16), 1.0)
vdb.write(out + '/blobs_far.vdb', grids=[f])
gs = []  # emitting blobs (density and emission): the dense form needed 9 GB, over the default budget
for name in ('density', 'emission'):
    e = grid(); e.name = name; a = e.getAccessor()
    for base in (0, 5100):
        for i in range(64): a.setValueOn((base + i % 4, base + i // 4 % 4, base + i // 16), 1.0)
    gs.append(e)
vdb.write(out + '/eblobs.vdb', grids=gs)
h = vdb.FloatGrid(); h.name = 'density'; h.getAccessor().setValueOn((0, 0, 0), 1.0)
h.transform = vdb.createLinearTransform(voxelSize=1e30); vdb.write(out + '/huge.vdb', grids=[h])
PY
v29() { # NAME VDB NODES: point_plane.gltf with NODES volume nodes of VDB
  "$py" - "$root/tests/scenes/point_plane.gltf" "$tmp/v29/$1.gltf" "$2" "$3" <<'PY'
import json, sys
src, dst, uri, n = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
d = json.load(open(src))
for i in range(n):
    v = {"uri": uri}
    if uri.startswith("e"): v["emission_grid"] = "emission"
    d["nodes"].append({"name": "vol%d" % i, "translation": [0.1 * i, 0, 0], "extras": {"candela_volume": v}})
    d["scenes"][d.get("scene", 0)]["nodes"].append(len(d["nodes"]) - 1)
json.dump(d, open(dst, "w"))
PY
}
v29 tile tile.vdb 1; v29 blobs blobs.vdb 3; v29 huge huge.vdb 1; v29 blobs_far blobs_far.vdb 3; v29 eblobs eblobs.vdb 1
for s in tile blobs blobs_far eblobs; do
  if timeout 300 "$bin" render "$tmp/v29/$s.gltf" --res 8x8 --spp 1 --quiet --no-png -o "$tmp/v29/$s.exr" --stats-json "$tmp/v29/$s.json" \
       2>"$tmp/v29/$s.err" && "$py" -c 'import json, sys; b = json.load(open(sys.argv[1]))["volumes"]["bytes"]; print(b); sys.exit(0 if 0 < b < 64 << 20 else 1)' \
       "$tmp/v29/$s.json" >"$tmp/v29/$s.bytes"; then ok
  else bad "$s: volume memory $(cat "$tmp/v29/$s.bytes" 2>/dev/null) bytes (limit 64 MiB): $(cat "$tmp/v29/$s.err")"; fi
done
"$bin" render "$tmp/v29/huge.gltf" --res 8x8 --spp 1 --quiet --no-png -o "$tmp/v29/huge.exr" 2>"$tmp/v29/huge.err"; rc=$?
[ $rc -ne 0 ] && [ "$(grep -c . "$tmp/v29/huge.err")" = 1 ] && grep -q "huge.vdb: grid 'density': its voxels reach beyond 1e+12" "$tmp/v29/huge.err" \
  && [ ! -e "$tmp/v29/huge.exr" ] && ok || bad "a 1e30 voxel: exit $rc, $(cat "$tmp/v29/huge.err")"
# the budget: the blobs' three nodes within 1 MiB are refused with one line naming the flag
"$bin" render "$tmp/v29/blobs.gltf" --volume-budget-mb 1 --res 8x8 --spp 1 --quiet --no-png -o "$tmp/v29/b1.exr" 2>"$tmp/v29/b1.err"; rc=$?
[ $rc -ne 0 ] && [ "$(grep -c . "$tmp/v29/b1.err")" = 1 ] && grep -q -- "--volume-budget-mb" "$tmp/v29/b1.err" && [ ! -e "$tmp/v29/b1.exr" ] \
  && ok || bad "a volume budget of 1 MiB: exit $rc, $(cat "$tmp/v29/b1.err")"

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
