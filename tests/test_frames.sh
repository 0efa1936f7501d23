#!/usr/bin/env bash
# Animation frame batches (candela render --frames): every frame of a batch equals a
# single-frame render of it bit for bit; --resume after an interrupted batch renders only the
# missing frames and ends with the same images; shards (--shard, SLURM_ARRAY_*) partition the
# frames; a frame that fails is counted in the exit status and the batch goes on; bad
# animations, frame ranges and shard specs give one line, a non-zero exit and write nothing.
# usage: test_frames.sh CANDELA_BINARY SOURCE_ROOT EXR_SAME
set -u
bin=$1; root=$2; exr_same=$3
# the same pixels bit for bit (tests/exr_same.c): EXR headers carry each run's provenance
same_exr() { "$exr_same" "$1" "$2" 2>/dev/null; }
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

scene=$root/scenes/animation.gltf
# tiny frames; the tree sampler keeps them fast (cache points get their own check below)
fast=(--res 32x24 --spp 2 --light-sampler tree --quiet --no-png)

# frame numbers rendered according to a --frame-stats log, sorted, space separated
# (no file: none; every line must parse as JSON)
logged() { [ -e "$1" ] || { echo ""; return; }
  python3 -c 'import json,sys; print(" ".join(str(f) for f in sorted(json.loads(l)["frame"] for l in open(sys.argv[1]) if json.loads(l)["status"] == sys.argv[2])))' "$1" "${2:-ok}"; }

# ---- 1. a batch equals single-frame renders, frame by frame (LINEAR camera and ball, slerped
# camera rotation, CUBICSPLINE light, STEP cube: frame 6 is t = 0.25 s, the cube's first step)
mkdir -p "$tmp/batch" "$tmp/single"
"$bin" render "$scene" --frames 1-6 "${fast[@]}" -o "$tmp/batch/f.####.exr" --frame-stats "$tmp/batch/log.jsonl"
rc=$?
[ $rc -eq 0 ] && ok || bad "batch 1-6 exit $rc"
[ "$(logged "$tmp/batch/log.jsonl")" = "1 2 3 4 5 6" ] && ok || bad "batch log lists $(logged "$tmp/batch/log.jsonl")"
# issue 27: each line says how its frame was made: the --version line and the frame's image
# identity (its EXR's candela:identity, what --resume compares)
python3 -c 'import json, sys
ls = [json.loads(l) for l in open(sys.argv[1])]
sys.exit(0 if ls and all(l["software"] == sys.argv[2] and l["identity"].startswith("scene=") and
                         " seed=%d " % l["seed"] in l["identity"] for l in ls) else 1)' \
  "$tmp/batch/log.jsonl" "$("$bin" --version)" && ok || bad "--frame-stats software/identity: $(head -c 600 "$tmp/batch/log.jsonl")"
if command -v oiiotool >/dev/null 2>&1; then
  want=$(oiiotool --info -v "$tmp/batch/f.0003.exr" | sed -n 's/^ *candela:identity: "\(.*\)"$/\1/p')
  got=$(python3 -c 'import json, sys
print([json.loads(l) for l in open(sys.argv[1]) if json.loads(l)["frame"] == 3][0]["identity"])' "$tmp/batch/log.jsonl")
  [ -n "$want" ] && [ "$got" = "$want" ] && ok || bad "frame 3's logged identity '$got' is not its EXR's '$want'"
fi
for f in 1 2 3 4 5 6; do
  "$bin" render "$scene" --frames $f "${fast[@]}" -o "$tmp/single/f.####.exr" || bad "single frame $f failed"
  same_exr "$tmp/batch/f.000$f.exr" "$tmp/single/f.000$f.exr" && ok || bad "frame $f of the batch differs from its single-frame render"
done
# the frames do differ (the animation moves things): no test that cannot fail
same_exr "$tmp/batch/f.0001.exr" "$tmp/batch/f.0002.exr" && bad "frames 1 and 2 are identical" || ok
# the thread count changes nothing
"$bin" render "$scene" --frames 4 "${fast[@]}" --threads 1 -o "$tmp/single/t1.####.exr" &&
  same_exr "$tmp/batch/f.0004.exr" "$tmp/single/t1.0004.exr" && ok || bad "frame 4 differs with 1 thread"
# cache points are rebuilt per frame: frame 5 after frame 2 in one session equals frame 5 alone
cp_opts=(--res 32x24 --spp 2 --light-sampler cachepoints --quiet --no-png)
"$bin" render "$scene" --frames 2,5 "${cp_opts[@]}" -o "$tmp/batch/cp.####.exr" &&
  "$bin" render "$scene" --frames 5 "${cp_opts[@]}" -o "$tmp/single/cp.####.exr" &&
  same_exr "$tmp/batch/cp.0005.exr" "$tmp/single/cp.0005.exr" && ok || bad "cache point frame 5 differs after frame 2"
# per-frame seeds: the same frame with another --seed differs, the same seed reproduces it
"$bin" render "$scene" --frames 3 "${fast[@]}" --seed 7 -o "$tmp/single/s7.####.exr"
same_exr "$tmp/single/s7.0003.exr" "$tmp/batch/f.0003.exr" && bad "--seed does not change frame 3" || ok

# a still scene renders any frame, and frame f is exactly a plain render with the frame's seed
# (the session's path is candela_render's). Frame 1 of --seed 0 has seed 7960286522194355700,
# the second output of splitmix64 seeded with 0 (computed independently in Python).
still=$root/tests/scenes/point_plane.gltf
"$bin" render "$still" --frames 1 "${fast[@]}" -o "$tmp/single/still.####.exr" --frame-stats "$tmp/single/still.jsonl"
seed=$(python3 -c 'import json,sys; print(json.loads(open(sys.argv[1]).readline())["seed"])' "$tmp/single/still.jsonl")
[ "$seed" = 7960286522194355700 ] && ok || bad "frame 1's seed is $seed"
"$bin" render "$still" --seed "$seed" "${fast[@]}" -o "$tmp/single/plain.exr" &&
  same_exr "$tmp/single/still.0001.exr" "$tmp/single/plain.exr" && ok || bad "frame 1 of a still scene differs from a plain render with its seed"

# ---- 2. --resume: outputs deleted, a temporary left by a killed write; only those re-render
mkdir -p "$tmp/resume"
cp "$tmp/batch"/f.000?.exr "$tmp/resume/"
rm "$tmp/resume/f.0002.exr" "$tmp/resume/f.0005.exr" "$tmp/resume/f.0003.exr"
echo partial > "$tmp/resume/f.0003.exr.tmp-999999"   # what a SIGKILL during the write leaves
touch -d '2001-01-01' "$tmp/resume"/f.000?.exr
"$bin" render "$scene" --frames 1-6 "${fast[@]}" --resume -o "$tmp/resume/f.####.exr" --frame-stats "$tmp/resume/log.jsonl"
[ "$(logged "$tmp/resume/log.jsonl")" = "2 3 5" ] && ok || bad "resume rendered frames '$(logged "$tmp/resume/log.jsonl")', expected 2 3 5"
[ "$(logged "$tmp/resume/log.jsonl" skipped)" = "1 4 6" ] && ok || bad "resume logged '$(logged "$tmp/resume/log.jsonl" skipped)' as skipped"
for f in 1 4 6; do
  [ "$(stat -c %Y "$tmp/resume/f.000$f.exr")" = "$(date -d 2001-01-01 +%s)" ] && ok || bad "resume rewrote frame $f"
done
for f in 1 2 3 4 5 6; do
  same_exr "$tmp/batch/f.000$f.exr" "$tmp/resume/f.000$f.exr" && ok || bad "resumed frame $f differs"
done
[ -e "$tmp/resume/f.0003.exr.tmp-999999" ] && bad "a stale temporary was left" || ok
# a batch killed (SIGKILL) at some point, then resumed: every frame once, each as in the batch
mkdir -p "$tmp/kill"
"$bin" render "$scene" --frames 1-6 "${fast[@]}" -o "$tmp/kill/f.####.exr" &
pid=$!
for _ in $(seq 200); do [ -e "$tmp/kill/f.0002.exr" ] && break; sleep 0.02; done
kill -KILL $pid 2>/dev/null; wait $pid 2>/dev/null
before=$(cd "$tmp/kill" && ls f.000?.exr 2>/dev/null | sed 's/f\.000\(.\)\.exr/\1/' | tr '\n' ' ')
"$bin" render "$scene" --frames 1-6 "${fast[@]}" --resume -o "$tmp/kill/f.####.exr" --frame-stats "$tmp/kill/log.jsonl"
expected=""
for f in 1 2 3 4 5 6; do case " $before" in *" $f "*) ;; *) expected="$expected $f";; esac; done
[ "$(logged "$tmp/kill/log.jsonl")" = "${expected# }" ] && ok ||
  bad "after a kill with frames '$before' done, resume rendered '$(logged "$tmp/kill/log.jsonl")'"
for f in 1 2 3 4 5 6; do
  same_exr "$tmp/batch/f.000$f.exr" "$tmp/kill/f.000$f.exr" && ok || bad "killed+resumed frame $f differs"
done
ls "$tmp/kill" | grep -q tmp- && bad "temporaries left after resume: $(ls "$tmp/kill")" || ok

# ---- 3. shards: round-robin over the sorted list, together exactly the list, frames as in the batch
mkdir -p "$tmp/shard"
for i in 0 1 2; do
  "$bin" render "$scene" --frames 1-6 --shard $i/3 "${fast[@]}" -o "$tmp/shard/f.####.exr" --frame-stats "$tmp/shard/log$i.jsonl" ||
    bad "shard $i/3 failed"
done
[ "$(logged "$tmp/shard/log0.jsonl")" = "1 4" ] && [ "$(logged "$tmp/shard/log1.jsonl")" = "2 5" ] &&
  [ "$(logged "$tmp/shard/log2.jsonl")" = "3 6" ] && ok || bad "shards are not round-robin"
for f in 1 2 3 4 5 6; do
  same_exr "$tmp/batch/f.000$f.exr" "$tmp/shard/f.000$f.exr" && ok || bad "sharded frame $f differs"
done
# Slurm's variables (a 1-based array 1-3: task 2 is shard 1/3)
mkdir -p "$tmp/slurm"
SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_TASK_MIN=1 SLURM_ARRAY_TASK_COUNT=3 \
  "$bin" render "$scene" --frames 1-6 "${fast[@]}" -o "$tmp/slurm/f.####.exr" --frame-stats "$tmp/slurm/log.jsonl"
[ "$(logged "$tmp/slurm/log.jsonl")" = "2 5" ] && ok || bad "Slurm task 2 of 1-3 rendered '$(logged "$tmp/slurm/log.jsonl")'"
# --shard wins over the environment
SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=3 \
  "$bin" render "$scene" --frames 1-6 --shard 2/3 "${fast[@]}" -o "$tmp/slurm/g.####.exr" --frame-stats "$tmp/slurm/log2.jsonl"
[ "$(logged "$tmp/slurm/log2.jsonl")" = "3 6" ] && ok || bad "--shard did not override SLURM_ARRAY_TASK_ID"

# ---- 4. malformed animations (generated here) and bad requests
python3 - "$tmp" <<'EOF'
import base64, json, math, struct, sys
out = sys.argv[1]
def scene(times, values, interp='LINEAR', path='translation', ncomp=3, out_count=None, in_type='SCALAR', target=0,
          rest_scale=None):
    buf = bytearray()
    def view(floats):
        off = len(buf)
        buf.extend(struct.pack('<%df' % len(floats), *floats))
        return {'buffer': 0, 'byteOffset': off, 'byteLength': 4 * len(floats)}
    tri = [0, 0, 0, 1, 0, 0, 0, 1, 0]
    views = [view(tri), view(times), view([c for v in values for c in v])]
    acc = [{'bufferView': 0, 'componentType': 5126, 'count': 3, 'type': 'VEC3', 'min': [0, 0, 0], 'max': [1, 1, 0]},
           {'bufferView': 1, 'componentType': 5126, 'count': len(times), 'type': in_type},
           {'bufferView': 2, 'componentType': 5126, 'count': out_count if out_count is not None else len(values),
            'type': 'VEC4' if ncomp == 4 else 'VEC3'}]
    return {'asset': {'version': '2.0'}, 'scene': 0, 'scenes': [{'nodes': [0, 1]}],
            'nodes': [dict({'name': 'tri', 'mesh': 0}, **({'scale': rest_scale} if rest_scale else {})),
                      {'name': 'cam', 'camera': 0, 'translation': [0.3, 0.3, 2]}],
            'meshes': [{'primitives': [{'attributes': {'POSITION': 0}}]}],
            'cameras': [{'type': 'perspective', 'perspective': {'yfov': 0.8, 'znear': 0.01}}],
            'animations': [{'name': 'a', 'samplers': [{'input': 1, 'output': 2, 'interpolation': interp}],
                            'channels': [{'sampler': 0, 'target': {'node': target, 'path': path}}]}],
            'accessors': acc, 'bufferViews': views,
            'buffers': [{'byteLength': len(buf), 'uri': 'data:application/octet-stream;base64,' + base64.b64encode(bytes(buf)).decode()}]}
def write(name, doc):
    with open('%s/%s.gltf' % (out, name), 'w') as f:
        json.dump(doc, f)
nan = float('nan')
write('counts', scene([0, 1, 2], [(0, 0, 0), (1, 0, 0)]))
write('cubic_counts', scene([0, 1, 2], [(0, 0, 0), (1, 0, 0), (2, 0, 0)], 'CUBICSPLINE'))
write('nonmonotonic', scene([0, 1, 0.5], [(0, 0, 0), (1, 0, 0), (2, 0, 0)]))
write('repeated_time', scene([0, 1, 1], [(0, 0, 0), (1, 0, 0), (2, 0, 0)]))
write('nan_time', scene([0, nan, 2], [(0, 0, 0), (1, 0, 0), (2, 0, 0)]))
write('nan_value', scene([0, 1, 2], [(0, 0, 0), (nan, 0, 0), (2, 0, 0)]))
write('zero_quat', scene([0, 1], [(0, 0, 0, 1), (0, 0, 0, 0)], path='rotation', ncomp=4))
write('bad_interp', scene([0, 1], [(0, 0, 0), (1, 0, 0)], 'BEZIER'))
write('vec2_input', scene([0, 1, 2, 3], [(0, 0, 0), (1, 0, 0)], in_type='VEC2'))
write('weights', scene([0, 1], [(0, 0, 0), (1, 0, 0)], path='weights'))
# indices that are not whole numbers (tinygltf dropped such a channel without a word)
d = scene([0, 1], [(0, 0, 0), (1, 0, 0)]); d['animations'][0]['channels'][0]['target']['node'] = 1.5; write('node_frac', d)
d = scene([0, 1], [(0, 0, 0), (1, 0, 0)]); d['animations'][0]['channels'][0]['sampler'] = 0.5; write('sampler_frac', d)
d = scene([0, 1], [(0, 0, 0), (1, 0, 0)]); d['animations'][0]['samplers'][0]['output'] = 2.0; write('output_float', d)
# fine data: the triangle's scale 1, 0, 0, 1 held (STEP) at 0, 1, 2, 3 s (hidden in frames 1
# and 2 at 1 fps); the same with scale 0 at rest (kept, hidden, until it appears at 3 s); the
# camera's scale 0 in frames 1 and 2 (it cannot be placed: those frames fail)
write('vanishing', scene([0, 1, 2, 3], [(1, 1, 1), (0, 0, 0), (0, 0, 0), (1, 1, 1)], 'STEP', path='scale'))
write('appearing', scene([0, 1, 2, 3], [(0, 0, 0), (0, 0, 0), (0, 0, 0), (1, 1, 1)], 'STEP', path='scale', rest_scale=[0, 0, 0]))
write('camera_zero', scene([0, 1, 2, 3], [(1, 1, 1), (0, 0, 0), (0, 0, 0), (1, 1, 1)], 'STEP', path='scale', target=1))
EOF

# expect_error NAME PATTERN -- ARGS... : non-zero exit below 128, exactly one stderr line with
# PATTERN, and nothing new or changed in $tmp/out (it holds one earlier frame: never overwritten)
mkdir -p "$tmp/out"
cp "$tmp/batch/f.0001.exr" "$tmp/out/f.0001.exr"
expect_error() {
  local name=$1 pattern=$2; shift 3
  "$@" >"$tmp/stdout" 2>"$tmp/stderr"; local rc=$?
  local lines; lines=$(grep -c . "$tmp/stderr")
  if [ $rc -eq 0 ] || [ $rc -ge 128 ]; then bad "$name: exit code $rc"; return; fi
  if [ "$lines" -ne 1 ]; then bad "$name: expected one error line, got $lines: $(cat "$tmp/stderr")"; return; fi
  if ! grep -q -- "$pattern" "$tmp/stderr"; then bad "$name: message lacks '$pattern': $(cat "$tmp/stderr")"; return; fi
  if [ "$(ls "$tmp/out")" != "f.0001.exr" ]; then bad "$name: wrote $(ls "$tmp/out")"; return; fi
  if ! cmp -s "$tmp/out/f.0001.exr" "$tmp/batch/f.0001.exr"; then bad "$name: overwrote a frame"; return; fi
  ok
}
o=(-o "$tmp/out/f.####.exr" --res 16x12 --spp 1 --light-sampler tree --quiet)
expect_error "count mismatch" "input has 3 times but output has 2 values" -- "$bin" render "$tmp/counts.gltf" --frames 0-1 "${o[@]}"
expect_error "cubic count mismatch" "CUBICSPLINE needs 3 per time" -- "$bin" render "$tmp/cubic_counts.gltf" --frames 0-1 "${o[@]}"
expect_error "non-monotonic times" "not increasing" -- "$bin" render "$tmp/nonmonotonic.gltf" --frames 0-1 "${o[@]}"
expect_error "repeated time" "not increasing" -- "$bin" render "$tmp/repeated_time.gltf" --frames 0-1 "${o[@]}"
expect_error "NaN time" "key time 1 is not finite" -- "$bin" render "$tmp/nan_time.gltf" --frames 0-1 "${o[@]}"
expect_error "NaN value" "value 1 is not finite" -- "$bin" render "$tmp/nan_value.gltf" --frames 0-1 "${o[@]}"
expect_error "zero quaternion" "zero quaternion" -- "$bin" render "$tmp/zero_quat.gltf" --frames 0-1 "${o[@]}"
expect_error "bad interpolation" "unknown interpolation 'BEZIER'" -- "$bin" render "$tmp/bad_interp.gltf" --frames 0-1 "${o[@]}"
expect_error "input type" "expected SCALAR" -- "$bin" render "$tmp/vec2_input.gltf" --frames 0-1 "${o[@]}"
expect_error "node 1.5" 'channel 0 target: "node" must be a whole number (an integer index), not 1.5' -- "$bin" render "$tmp/node_frac.gltf" --frames 0-1 "${o[@]}"
expect_error "sampler 0.5" 'channel 0: "sampler" must be a whole number (an integer index), not 0.5' -- "$bin" render "$tmp/sampler_frac.gltf" --frames 0-1 "${o[@]}"
expect_error "output 2.0" "'output' property is not an integer" -- "$bin" render "$tmp/output_float.gltf" --frames 0-1 "${o[@]}"
# the malformed file also fails a plain render (the animation is validated at every load)
expect_error "plain render" "not increasing" -- "$bin" render "$tmp/nonmonotonic.gltf" -o "$tmp/out/plain.exr" --res 16x12 --spp 1 --quiet
expect_error "range past the end" "outside the animation (0 to 2 s: frames 0-48)" -- "$bin" render "$scene" --frames 1-100 "${o[@]}"
expect_error "range at fps" "at 48 fps" -- "$bin" render "$scene" --frames 90-97 --fps 48 "${o[@]}"
expect_error "bad frames" "invalid --frames '6-2'" -- "$bin" render "$scene" --frames 6-2 "${o[@]}"
expect_error "bad frames list" "invalid --frames '1,,2'" -- "$bin" render "$scene" --frames 1,,2 "${o[@]}"
expect_error "bad step" "invalid --frames '1-6:0'" -- "$bin" render "$scene" --frames 1-6:0 "${o[@]}"
expect_error "no pattern" "needs a frame pattern" -- "$bin" render "$scene" --frames 1-2 -o "$tmp/out/plain.exr" --res 16x12 --spp 1 --quiet
for spec in 3/3 1/0 a/2 1 -1/2 1/2/3 ""; do
  expect_error "bad shard '$spec'" "invalid --shard" -- "$bin" render "$scene" --frames 1-6 --shard "$spec" "${o[@]}"
done
expect_error "Slurm task past the count" "SLURM_ARRAY_TASK_COUNT=3" -- env SLURM_ARRAY_TASK_ID=3 SLURM_ARRAY_TASK_COUNT=3 "$bin" render "$scene" --frames 1-6 "${o[@]}"
expect_error "Slurm count missing" "SLURM_ARRAY_TASK_COUNT is missing" -- env SLURM_ARRAY_TASK_ID=1 "$bin" render "$scene" --frames 1-6 "${o[@]}"
expect_error "Slurm id garbage" "invalid SLURM_ARRAY_TASK_ID" -- env SLURM_ARRAY_TASK_ID=x SLURM_ARRAY_TASK_COUNT=3 "$bin" render "$scene" --frames 1-6 "${o[@]}"
expect_error "shard without frames" "need --frames" -- "$bin" render "$scene" --shard 0/2 "${o[@]}"
expect_error "stats-json with frames" "--frame-stats" -- "$bin" render "$scene" --frames 1-2 --stats-json "$tmp/out/s.json" "${o[@]}"

# morph target weights are animated but not rendered: a warning, and the frames render
mkdir -p "$tmp/weights"
"$bin" render "$tmp/weights.gltf" --frames 0-1 -o "$tmp/weights/w.#.exr" --res 16x12 --spp 1 --quiet --no-png 2>"$tmp/weights/stderr" &&
  grep -q "warning: .*weights are animated; they are not rendered" "$tmp/weights/stderr" && [ -e "$tmp/weights/w.1.exr" ] && ok ||
  bad "a weights channel: $(cat "$tmp/weights/stderr")"

# ---- 5. a mesh scaled to zero is hidden in those frames (animations hide objects so), also
# when it starts at zero; a frame that fails (a camera scaled to zero) is reported, the batch
# goes on, and the exit status counts the failures
mkdir -p "$tmp/vanish"
tiny=(--fps 1 --res 16x12 --spp 1 --quiet --no-png)
"$bin" render "$tmp/vanishing.gltf" --frames 0-3 "${tiny[@]}" -o "$tmp/vanish/v.#.exr" && ok || bad "vanishing mesh: exit $?"
"$bin" render "$tmp/appearing.gltf" --frames 0-3 "${tiny[@]}" -o "$tmp/vanish/a.#.exr" && ok || bad "appearing mesh: exit $?"
"$bin" render "$tmp/vanishing.gltf" --frames 1 "${tiny[@]}" --seed 5 -o "$tmp/vanish/v5.#.exr"
"$bin" render "$tmp/vanishing.gltf" --frames 1 "${tiny[@]}" --seed 6 -o "$tmp/vanish/v6.#.exr"
same_exr "$tmp/vanish/v.0.exr" "$tmp/vanish/v.1.exr" && bad "the mesh did not vanish at frame 1" || ok
same_exr "$tmp/vanish/v5.1.exr" "$tmp/vanish/v6.1.exr" && ok || bad "frame 1 still shows something (seeds differ)"
same_exr "$tmp/vanish/v.3.exr" "$tmp/vanish/a.3.exr" && ok || bad "the appearing mesh's frame 3 differs from the vanishing one's"
same_exr "$tmp/vanish/a.0.exr" "$tmp/vanish/v.1.exr" && ok || bad "the appearing mesh shows at frame 0"
"$bin" render "$tmp/camera_zero.gltf" --frames 0-3 "${tiny[@]}" -o "$tmp/vanish/c.#.exr" \
  --frame-stats "$tmp/vanish/log.jsonl" 2>"$tmp/vanish/stderr"
rc=$?
[ $rc -eq 2 ] && ok || bad "two failing frames gave exit status $rc"
[ "$(ls "$tmp/vanish" | grep '^c\.' | tr '\n' ' ')" = "c.0.exr c.3.exr " ] && ok || bad "the camera frames wrote $(ls "$tmp/vanish")"
grep -q "frame 1 failed: .*'cam'.*singular transform" "$tmp/vanish/stderr" && grep -q "frame 2 failed" "$tmp/vanish/stderr" && ok ||
  bad "failing frames not reported: $(cat "$tmp/vanish/stderr")"
[ "$(logged "$tmp/vanish/log.jsonl" failed)" = "1 2" ] && ok || bad "the log does not mark frames 1 and 2 failed"

# ---- 6. issue 29
# --resume trusts no name alone: an empty frame, one cut short and one of another size are
# rendered again (and the log says why); the good ones stay untouched
mkdir -p "$tmp/r29"
cp "$tmp/batch"/f.000?.exr "$tmp/r29/"
: > "$tmp/r29/f.0002.exr"
head -c 2000 "$tmp/batch/f.0004.exr" > "$tmp/r29/f.0004.exr"
"$bin" render "$scene" --frames 5 --res 16x12 --spp 1 --light-sampler tree --quiet --no-png -o "$tmp/r29/small.####.exr"
mv "$tmp/r29/small.0005.exr" "$tmp/r29/f.0005.exr"
touch -d '2001-01-01' "$tmp/r29"/f.000?.exr
"$bin" render "$scene" --frames 1-6 "${fast[@]}" --resume -o "$tmp/r29/f.####.exr" --frame-stats "$tmp/r29/log.jsonl" 2>"$tmp/r29/err"
[ "$(logged "$tmp/r29/log.jsonl")" = "2 4 5" ] && ok || bad "resume over bad frames rendered '$(logged "$tmp/r29/log.jsonl")', expected 2 4 5"
[ "$(grep -c "rendered again (--resume)" "$tmp/r29/err")" = 2 ] &&
  grep -q "frame 5: .*f.0005.exr was rendered with other options: --spp 1 (this run 2), --res 16x12 (this run 32x24); rendering it again" "$tmp/r29/err" \
  && ok || bad "resume did not say why it rendered frames again: $(cat "$tmp/r29/err")"
for f in 1 2 3 4 5 6; do same_exr "$tmp/batch/f.000$f.exr" "$tmp/r29/f.000$f.exr" && ok || bad "resumed-over frame $f differs"; done
for f in 1 3 6; do
  [ "$(stat -c %Y "$tmp/r29/f.000$f.exr")" = "$(date -d 2001-01-01 +%s)" ] && ok || bad "resume rewrote good frame $f"
done

# ---- 7. issue 27: --resume compares each frame's recorded identity (its EXR's candela:identity)
# with this run's: frames of another --res, or of another --spp (same size: only the identity
# tells), render again, one line each; the same options skip them all
exr_size() { python3 - "$1" <<'PY'
import struct, sys
b = open(sys.argv[1], 'rb').read(); i = 8
while b[i] != 0:
    name_end = b.index(0, i); typ_end = b.index(0, name_end + 1)
    name = b[i:name_end].decode(); size, = struct.unpack_from('<i', b, typ_end + 1); v = typ_end + 5
    if name == 'dataWindow':
        x0, y0, x1, y1 = struct.unpack_from('<4i', b, v); print('%dx%d' % (x1 - x0 + 1, y1 - y0 + 1))
    i = v + size
PY
}
mkdir -p "$tmp/i27"
id_fast=(--spp 2 --light-sampler tree --no-png)
"$bin" render "$scene" --frames 1-3 --res 32x24 "${id_fast[@]}" --quiet -o "$tmp/i27/f.####.exr" || bad "identity batch"
[ "$(exr_size "$tmp/i27/f.0002.exr")" = 32x24 ] && ok || bad "frame 2 is $(exr_size "$tmp/i27/f.0002.exr"), not 32x24"
"$bin" render "$scene" --frames 1-3 --res 40x30 "${id_fast[@]}" --quiet --resume -o "$tmp/i27/f.####.exr" \
  --frame-stats "$tmp/i27/res.jsonl" 2>"$tmp/i27/res.err" || bad "resume at another --res"
[ "$(logged "$tmp/i27/res.jsonl")" = "1 2 3" ] && ok || bad "another --res re-rendered '$(logged "$tmp/i27/res.jsonl")'"
for f in 1 2 3; do [ "$(exr_size "$tmp/i27/f.000$f.exr")" = 40x30 ] && ok || bad "frame $f is $(exr_size "$tmp/i27/f.000$f.exr") after resume at 40x30"; done
[ "$(grep -c "was rendered with other options: --res 32x24 (this run 40x30); rendering it again" "$tmp/i27/res.err")" = 3 ] &&
  grep -q "^candela: frame 3: $tmp/i27/f.0003.exr was rendered with other options" "$tmp/i27/res.err" && ok ||
  bad "resume at another --res did not say so per frame: $(cat "$tmp/i27/res.err")"
# the same options again: every frame skipped, nothing said
"$bin" render "$scene" --frames 1-3 --res 40x30 "${id_fast[@]}" --quiet --resume -o "$tmp/i27/f.####.exr" \
  --frame-stats "$tmp/i27/same.jsonl" 2>"$tmp/i27/same.err" || bad "resume with the same options"
[ "$(logged "$tmp/i27/same.jsonl" skipped)" = "1 2 3" ] && [ -z "$(logged "$tmp/i27/same.jsonl")" ] && ok ||
  bad "the same options re-rendered '$(logged "$tmp/i27/same.jsonl")'"
[ -s "$tmp/i27/same.err" ] && bad "resume with the same options said: $(cat "$tmp/i27/same.err")"
# another --spp (the same size, which alone passed before): frame 2 only (a shard of one frame)
"$bin" render "$scene" --frames 2 --res 40x30 --spp 3 --light-sampler tree --no-png --quiet --resume -o "$tmp/i27/f.####.exr" \
  --frame-stats "$tmp/i27/spp.jsonl" 2>"$tmp/i27/spp.err" || bad "resume at another --spp"
[ "$(logged "$tmp/i27/spp.jsonl")" = "2" ] && grep -q "frame 2: .*f.0002.exr was rendered with other options: --spp 2 (this run 3)" "$tmp/i27/spp.err" &&
  ok || bad "another --spp: rendered '$(logged "$tmp/i27/spp.jsonl")', said '$(cat "$tmp/i27/spp.err")'"

# a frame another writer holds (its EXR's lock) fails, counted and said; the others render
mkdir -p "$tmp/l29"
flock "$tmp/l29/f.0002.exr.lock" sleep 60 & holder=$!
for _ in $(seq 100); do [ -e "$tmp/l29/f.0002.exr.lock" ] && break; sleep 0.05; done
"$bin" render "$scene" --frames 1-3 "${fast[@]}" -o "$tmp/l29/f.####.exr" 2>"$tmp/l29/err"; rc=$?
[ $rc -eq 1 ] && [ -e "$tmp/l29/f.0001.exr" ] && [ -e "$tmp/l29/f.0003.exr" ] && [ ! -e "$tmp/l29/f.0002.exr" ] &&
  grep -q "frame 2 failed: .*f.0002.exr: another candela is writing it" "$tmp/l29/err" && ok ||
  bad "a locked frame: exit $rc, $(ls "$tmp/l29" | tr '\n' ' ') $(cat "$tmp/l29/err")"
kill $holder 2>/dev/null; wait $holder 2>/dev/null
# every frame's names against the run's inputs, before the scene loads
expect_error "frame over --env" "e.2.exr: frame 2's EXR would replace the environment (--env)" -- "$bin" render "$scene" --frames 1-3 \
  -o "$tmp/out/e.#.exr" --env "$tmp/out/e.2.exr" --res 16x12 --spp 1 --quiet
expect_error "frame png over its exr" "are the same file" -- "$bin" render "$scene" --frames 1-3 -o "$tmp/out/e.#.exr" \
  --png "$tmp/out/../out/e.#.exr" --res 16x12 --spp 1 --quiet
# ... and each frame's lock file (emptied, then removed, by the frame's render: a scene named so
# was deleted once frame 2 began)
mkdir -p "$tmp/lk"; cp "$scene" "$tmp/lk/e.2.exr.lock"
expect_error "frame lock over the scene" "e.2.exr.lock: the lock file of frame 2's EXR would replace the scene" -- \
  "$bin" render "$tmp/lk/e.2.exr.lock" --frames 1-3 -o "$tmp/lk/e.#.exr" --res 16x12 --spp 1 --quiet
[ "$(ls "$tmp/lk")" = e.2.exr.lock ] && cmp -s "$scene" "$tmp/lk/e.2.exr.lock" && ok \
  || bad "the scene named as a frame's lock changed, or a frame was written: $(ls "$tmp/lk")"
rm -rf "$tmp/lk"

echo "frames: $pass passed, $fail failed"
[ $fail -eq 0 ]
