#!/usr/bin/env bash
# Start-up loads only what a run needs (io/io_module.h): `candela --version` and a render of
# scenes/default.gltf (no textures, no volumes; PNG written too) open neither io module nor
# OpenImageIO / OpenVDB; a scene with a volume loads candela_io_vdb.so (and not the image
# module) and renders; a textured scene loads candela_io_image.so; the program and its modules
# copied into one folder still work; a missing module is one error line naming the module file
# and what needs it, exit non-zero.
# usage: test_modules.sh CANDELA_BINARY SOURCE_ROOT
set -u
bin=$1; root=$2
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

# the shared objects a command opens (LD_DEBUG=files), one name a line; $? is the command's
opened() {
  local log=$tmp/ld.log
  LD_DEBUG=files LD_DEBUG_OUTPUT=$log "$@" >"$tmp/out.log" 2>&1
  local rc=$?
  cat "$log".* 2>/dev/null | sed -n 's/.*file=\([^ ]*\) .*/\1/p' | sort -u > "$tmp/opened.txt"
  rm -f "$log".*
  return $rc
}
# has NAME: the last command opened a file whose name contains NAME
has() { grep -q -- "$1" "$tmp/opened.txt"; }
# (TBB is Embree's: every render has it)
heavy="libOpenImageIO libopenvdb libboost candela_io_image.so candela_io_vdb.so"

opened "$bin" --version && ok || bad "--version failed: $(cat "$tmp/out.log")"
for lib in $heavy; do has "$lib" && bad "--version opened $lib" || ok; done
n=$(wc -l < "$tmp/opened.txt")
[ "$n" -le 20 ] && ok || bad "--version opened $n shared objects (expected at most 20)"

opened "$bin" render "$root/scenes/default.gltf" --res 16x16 --spp 1 -o "$tmp/plain.exr" \
  && ok || bad "plain render failed: $(cat "$tmp/out.log")"
[ -s "$tmp/plain.exr" ] && [ -s "$tmp/plain.png" ] && ok || bad "plain render: no EXR or PNG"
for lib in $heavy; do has "$lib" && bad "plain render opened $lib" || ok; done

# a volume: default.gltf plus a node holding a VDB from the fuzz corpus
python3 - "$root/scenes/default.gltf" "$root/tests/fuzz/corpus/vdb/fog_zip.vdb" "$tmp/volume.gltf" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["nodes"].append({"name": "vol", "extras": {"candela_volume": {"uri": sys.argv[2]}}})
d["scenes"][d.get("scene", 0)]["nodes"].append(len(d["nodes"]) - 1)
json.dump(d, open(sys.argv[3], "w"))
PY
opened "$bin" render "$tmp/volume.gltf" --res 16x16 --spp 1 -o "$tmp/volume.exr" --no-png \
  && ok || bad "volume render failed: $(cat "$tmp/out.log")"
[ -s "$tmp/volume.exr" ] && ok || bad "volume render: no EXR"
has candela_io_vdb.so && ok || bad "volume render did not load candela_io_vdb.so"
has libopenvdb && ok || bad "volume render did not load OpenVDB"
has candela_io_image.so && bad "volume render loaded candela_io_image.so" || ok
has libOpenImageIO && bad "volume render loaded OpenImageIO" || ok

# a texture (an EXR normal map): the image module, not the VDB one
opened "$bin" render "$root/tests/scenes/normalmap_grazing.gltf" --res 16x16 --spp 1 -o "$tmp/tex.exr" --no-png \
  && ok || bad "texture render failed: $(cat "$tmp/out.log")"
has candela_io_image.so && ok || bad "texture render did not load candela_io_image.so"
has candela_io_vdb.so && bad "texture render loaded candela_io_vdb.so" || ok

# the program and its modules copied into one folder (the modules beside the program)
moddir=$(dirname "$bin")/../io
mkdir -p "$tmp/bin"
cp "$bin" "$moddir/candela_io_image.so" "$moddir/candela_io_vdb.so" "$tmp/bin/"
"$tmp/bin/candela" render "$tmp/volume.gltf" --res 8x8 --spp 1 -o "$tmp/copy.exr" --no-png >"$tmp/out.log" 2>&1 \
  && ok || bad "copied program + modules: $(cat "$tmp/out.log")"

# a missing module: one line naming the file and what needs it, exit non-zero
rm "$tmp/bin/candela_io_vdb.so"
env CANDELA_MODULE_DIR="$tmp/bin" "$bin" render "$tmp/volume.gltf" --res 8x8 --spp 1 -o "$tmp/miss.exr" --no-png \
  >"$tmp/out.log" 2>"$tmp/err.log"
rc=$?
[ "$rc" -ne 0 ] && ok || bad "missing module: exit 0"
grep -q "candela_io_vdb.so not found (OpenVDB, needed to read VDB volumes" "$tmp/err.log" && ok \
  || bad "missing module: message was: $(cat "$tmp/err.log")"
[ "$(grep -c . "$tmp/err.log")" -eq 1 ] && ok || bad "missing module: not one line: $(cat "$tmp/err.log")"
# ... and a plain render needs none
env CANDELA_MODULE_DIR="$tmp/nowhere" "$bin" render "$root/scenes/default.gltf" --res 8x8 --spp 1 \
  -o "$tmp/nomod.exr" >"$tmp/out.log" 2>&1 && [ -s "$tmp/nomod.png" ] && ok \
  || bad "plain render without modules: $(cat "$tmp/out.log")"

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
