#!/usr/bin/env bash
# Checkpoints, resume, interruption and sample shards at the CLI (renderer/app/checkpoint.c):
# - the checkpoint-skipping schedule (ch. 2 §5.2.2): 4, 8, 16, 32 spp unguided; 4, 8, 14, 22
#   on the guided schedule (cumulative 1..8, 10, 14, 22, 38, 54, 64), never the last barrier;
#   the course's example at 128 guided spp: 4, 8, 14, 22, 54;
# - writing checkpoints does not change the image; resuming from one gives the uninterrupted
#   render's EXR bit for bit (cache points, whose learned visibility the checkpoint carries,
#   --guiding mis, also with learned BSDF shares, adaptive sampling from before and after its
#   pilot); an adaptive checkpoint of
#   the rule before the pilot rule is refused; a guided checkpoint at the end of the guide's
#   bootstrap (8 spp), before the film drops it, resumes to the uninterrupted image;
# - a render killed with SIGKILL after a checkpoint and resumed: bit-identical, and it left no
#   finished-looking file; SIGTERM stops after the current batch (mid-iteration), writes the
#   checkpoint and with --save-partial only NAME.partial.*; resuming that: bit-identical;
# - bad input: a checkpoint of another scene, resolution, spp or options, a damaged or truncated
#   one (a guide field declaring 2^26 leaves: refused before it allocates), a shard film given to
#   --resume-from, bad shard specs and merges: one line, non-zero
#   exit, the existing output untouched;
# - issue 27: `candela render --resume-from FILE` alone takes the scene, the options and the
#   outputs from the checkpoint (from any folder) and gives the uninterrupted render's EXR bit for
#   bit (with another --threads too); flags given as well must agree: every disagreement in one
#   line; options that never change the image (--threads, -o, --quiet, --batch) may differ;
# - sample shards: merging the same films in any order gives the same EXR bit for bit.
# usage: test_checkpoint.sh CANDELA_BINARY SOURCE_ROOT EXR_SAME
set -u
bin=$1; root=$2; exr_same=$3
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }
# EXRs: the same pixels bit for bit (tests/exr_same.c; their headers' provenance differs between
# runs); other files (films): the same bytes
same() {
  case $1 in
    *.exr) if "$exr_same" "$1" "$2" 2>/dev/null; then ok; else bad "$3: $1 and $2 differ"; fi ;;
    *) if cmp -s "$1" "$2"; then ok; else bad "$3: $1 and $2 differ"; fi ;;
  esac
}

scene=$root/scenes/default.gltf
# cache points (the default, auto, picks optimal for this scene's 4 lights: nothing learned)
base=(render "$scene" --res 32x24 --no-png --light-sampler cachepoints)

# expect_error NAME PATTERN -- ARGS...: non-zero exit below 128, one stderr line with PATTERN,
# and $tmp/keep.exr (a finished image from before) untouched; within 120 s, or $limit s when
# set (special files: refused at once, a blocking regression fails in seconds)
expect_error() {
  local name=$1 pattern=$2; shift 3
  echo sentinel > "$tmp/keep.exr"
  timeout "${limit:-120}" "$bin" "$@" >"$tmp/stdout" 2>"$tmp/stderr"; local rc=$?
  if [ $rc -eq 124 ]; then bad "$name: still running after ${limit:-120} s (blocked?), killed"; return; fi
  local lines; lines=$(grep -c . "$tmp/stderr")
  if [ $rc -eq 0 ] || [ $rc -ge 128 ]; then bad "$name: exit code $rc"; return; fi
  if [ "$lines" -ne 1 ]; then bad "$name: expected one error line, got $lines: $(cat "$tmp/stderr")"; return; fi
  if ! grep -q -- "$pattern" "$tmp/stderr"; then bad "$name: message lacks '$pattern': $(cat "$tmp/stderr")"; return; fi
  if [ "$(cat "$tmp/keep.exr")" != sentinel ]; then bad "$name: overwrote the output"; return; fi
  ok
}

# --- schedule, identity of images with checkpoints, resume from the last checkpoint
# (cpaov: the cache point AOV's film sums are saved and resumed too)
# (adaptive: the film's stopped pixels and the targets fixed at the pilot (4 spp) are saved, and
# the pixels a resumed iteration renders are exactly those the checkpoint's film still samples)
adaptive=(--noise-threshold 0.25 --min-spp 4 --aov spp)
# (misshare: the guiding leaves' learned BSDF shares and their sums are saved and resumed too;
# misadjoint: the adjoint-driven roulette's pixel estimates)
for mode in default mis misshare misadjoint cpaov adaptive; do
  extra=(); [ $mode = mis ] && extra=(--guiding mis)
  [ $mode = misshare ] && extra=(--guiding mis --guide-bsdf-share 0 --guide-caustic-threshold 0.002)
  [ $mode = misadjoint ] && extra=(--guiding mis --guide-roulette adjoint)
  [ $mode = cpaov ] && extra=(--light-sampler cachepoints --aov cachepoint)
  [ $mode = adaptive ] && extra=("${adaptive[@]}")
  "$bin" "${base[@]}" --spp 64 "${extra[@]}" -o "$tmp/full-$mode.exr" --quiet || bad "full render ($mode)"
  "$bin" "${base[@]}" --spp 64 "${extra[@]}" -o "$tmp/ck-$mode.exr" --checkpoint "$tmp/$mode.ckpt" 2>"$tmp/log-$mode" ||
    bad "render with --checkpoint ($mode)"
  got=$(sed -n 's/^candela: checkpoint at \([0-9]*\) spp.*/\1/p' "$tmp/log-$mode" | tr '\n' ' ')
  want="4 8 16 32 "; case $mode in mis*) want="4 8 14 22 " ;; esac
  [ "$got" = "$want" ] && ok || bad "checkpoint schedule ($mode): got '$got', want '$want'"
  same "$tmp/full-$mode.exr" "$tmp/ck-$mode.exr" "checkpoints changed the image ($mode)"
  # the file left is the last checkpoint (32 or 22 spp): as if killed right after it
  "$bin" "${base[@]}" --spp 64 "${extra[@]}" -o "$tmp/res-$mode.exr" --resume-from "$tmp/$mode.ckpt" --quiet ||
    bad "resume ($mode)"
  same "$tmp/full-$mode.exr" "$tmp/res-$mode.exr" "resumed render ($mode)"
done
# --guiding auto on the box lit through its ceiling: checkpoints before the probe's decision (4
# spp) and after it (guided) resume bit for bit; the probe runs on mis's schedule, so a box that chooses
# guiding has mis's checkpoints (4, 8, 14, 22, 54)
abox=(render "$root/scenes/cornell_indirect.gltf" --res 48x48 --no-png --spp 128 --guiding auto)
"$bin" "${abox[@]}" -o "$tmp/full-auto.exr" 2>"$tmp/log-auto-full" || bad "full render (auto)"
grep -q "guiding auto: on" "$tmp/log-auto-full" && ok || bad "auto: did not guide the box: $(grep auto "$tmp/log-auto-full")"
"$bin" "${abox[@]}" -o "$tmp/ck-auto.exr" --checkpoint "$tmp/auto.ckpt" 2>"$tmp/log-auto" || bad "render with --checkpoint (auto)"
got=$(sed -n 's/^candela: checkpoint at \([0-9]*\) spp.*/\1/p' "$tmp/log-auto" | tr '\n' ' ')
[ "$got" = "4 8 14 22 54 " ] && ok || bad "checkpoint schedule (auto): got '$got', want '4 8 14 22 54 '"
same "$tmp/full-auto.exr" "$tmp/ck-auto.exr" "checkpoints changed the image (auto)"
"$bin" "${abox[@]}" -o "$tmp/res-auto.exr" --resume-from "$tmp/auto.ckpt" --quiet || bad "resume (auto, guided)"
same "$tmp/full-auto.exr" "$tmp/res-auto.exr" "resumed render (auto, guided)"
"$bin" "${abox[@]}" -o "$tmp/probe.exr" --checkpoint "$tmp/auto-probe.ckpt" --quiet &
pid=$!
for _ in $(seq 1 600); do [ -e "$tmp/auto-probe.ckpt" ] && break; sleep 0.02; done
kill -KILL $pid 2>/dev/null; wait $pid 2>/dev/null
if [ -e "$tmp/auto-probe.ckpt" ]; then
  "$bin" "${abox[@]}" -o "$tmp/res-auto2.exr" --resume-from "$tmp/auto-probe.ckpt" --quiet || bad "resume (auto, at the decision)"
  same "$tmp/full-auto.exr" "$tmp/res-auto2.exr" "resumed render (auto, at the decision)"
else
  bad "auto: no checkpoint at 4 spp"
fi
grep -q "samples per pixel: 4 to 64" "$tmp/log-adaptive" && ok ||
  bad "adaptive: no pixel stopped early: $(grep 'samples per pixel' "$tmp/log-adaptive")"
# an adaptive checkpoint of the rule before the pilot rule (stopped pixels, no targets: made here
# from a new one) is refused in one line, not resumed with pixels another rule stopped
python3 - "$tmp/adaptive.ckpt" "$tmp/old-rule.ckpt" <<'PY'
import struct, sys
src, dst = sys.argv[1:3]
b = bytearray(open(src, 'rb').read())
w, h, idlen = struct.unpack_from('<3I', b, 8 + 12)
reclen, = struct.unpack_from('<I', b, 8 + 24 + idlen + 24 + 8 + 8 + 8)
n = w * h
film = 8 + 24 + idlen + 24 + 8 + 8 + 8 + 4 + reclen + 8 + 12  # the film's arrays, after its tag, version, head
mask, = struct.unpack_from('<i', b, film - 4)
assert mask == 12, mask                                         # stopped pixels and targets
struct.pack_into('<i', b, film - 4, 4)
target = film + 4 * 3 * n * 8 + n * 8 + 2 * n * 4 + n           # after depth, hits, count and stopped
del b[target:target + 4 * n]
h = 0xcbf29ce484222325
for c in b[:-8]: h = ((h ^ c) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
struct.pack_into('<Q', b, len(b) - 8, h)
open(dst, 'wb').write(b)
PY
# a checkpoint from before the pilot (a passed --time-limit stops after 1 spp; the pilot is at 16):
# the resumed render fixes the targets itself, bit-identical to the uninterrupted one
pre=(--spp 64 --noise-threshold 0.25 --min-spp 16 --aov spp)
"$bin" "${base[@]}" "${pre[@]}" -o "$tmp/full-pre.exr" --quiet || bad "full render (adaptive, pilot at 16)"
"$bin" "${base[@]}" "${pre[@]}" -o "$tmp/part-pre.exr" --checkpoint "$tmp/pre.ckpt" --time-limit 1e-6 --quiet ||
  bad "render stopped at 1 spp (adaptive)"
"$bin" "${base[@]}" "${pre[@]}" -o "$tmp/res-pre.exr" --resume-from "$tmp/pre.ckpt" --quiet || bad "resume before the pilot"
same "$tmp/full-pre.exr" "$tmp/res-pre.exr" "resumed from before the pilot (adaptive)"
expect_error "adaptive checkpoint of the earlier rule" "old-rule.ckpt: the checkpoint's film state does not fit this render (adaptive sampling by the rule before the pilot rule" \
  -- "${base[@]}" --spp 64 "${adaptive[@]}" -o "$tmp/keep.exr" --resume-from "$tmp/old-rule.ckpt" --quiet

# progressive cache point insertion (at the barrier after 4 spp): the checkpoints after it carry
# the inserted points, which a resumed render re-inserts before loading the learned state
prog=(render "$scene" --res 64x48 --no-png --light-sampler cachepoints --cachepoint-progressive on --spp 64)
"$bin" "${prog[@]}" -o "$tmp/full-prog.exr" 2>"$tmp/log-prog-full" || bad "full render (progressive)"
grep -q "cache points inserted between iterations: [1-9]" "$tmp/log-prog-full" && ok ||
  bad "progressive: no points inserted: $(grep 'cache points' "$tmp/log-prog-full")"
"$bin" "${prog[@]}" -o "$tmp/ck-prog.exr" --checkpoint "$tmp/prog.ckpt" --quiet || bad "render with --checkpoint (progressive)"
same "$tmp/full-prog.exr" "$tmp/ck-prog.exr" "checkpoints changed the image (progressive)"
"$bin" "${prog[@]}" -o "$tmp/res-prog.exr" --resume-from "$tmp/prog.ckpt" --quiet || bad "resume (progressive)"
same "$tmp/full-prog.exr" "$tmp/res-prog.exr" "resumed render (progressive)"
expect_error "progressive off" "flags disagree with the checkpoint: --cachepoint-progressive off (checkpoint on)$" -- render "$scene" --res 64x48 --no-png --light-sampler cachepoints \
  --cachepoint-progressive off --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/prog.ckpt"

# a checkpoint at the end of the guide's unguided bootstrap (8 spp), taken before the film drops
# it: resumed, the render drops it as the uninterrupted one did (a copy of the checkpoint file made
# when the log says 8 spp; the resumed render's path count says it was that one)
drop=(render "$root/scenes/cornell_indirect.gltf" --res 64x48 --no-png --spp 64 --guiding mis --threads 1 --batch 64)
"$bin" "${drop[@]}" -o "$tmp/drop-full.exr" --quiet || bad "full render (bootstrap drop)"
"$bin" "${drop[@]}" -o "$tmp/drop-ck.exr" --checkpoint "$tmp/drop.ckpt" 2>"$tmp/log-drop" &
pid=$!
for _ in $(seq 1 3000); do
  if grep -q "checkpoint at 8 spp" "$tmp/log-drop" 2>/dev/null; then cp "$tmp/drop.ckpt" "$tmp/drop8.ckpt"; break; fi
  sleep 0.01
done
wait $pid || bad "render with --checkpoint (bootstrap drop)"
same "$tmp/drop-full.exr" "$tmp/drop-ck.exr" "checkpoints changed the image (bootstrap drop)"
if [ -e "$tmp/drop8.ckpt" ]; then
  "$bin" "${drop[@]}" -o "$tmp/drop-res.exr" --resume-from "$tmp/drop8.ckpt" --stats-json "$tmp/drop-res.json" --quiet ||
    bad "resume (bootstrap drop)"
  paths=$(sed -n 's/^  "paths": \([0-9]*\),$/\1/p' "$tmp/drop-res.json")
  [ "$paths" = $((56 * 64 * 48)) ] && ok || bad "bootstrap drop: the copy was not the 8-spp checkpoint (resumed $paths paths)"
  same "$tmp/drop-full.exr" "$tmp/drop-res.exr" "resumed render (at the bootstrap's end)"
else
  bad "bootstrap drop: no checkpoint at 8 spp"
fi

# the course's own example (ch. 2 §5.2.2): a guided 128-spp render, cumulative 1..8, 10, 14, 22,
# 38, 54, 70, ..., 118, 128, checkpoints at 4, 8, 14, 22, 54 (and 128, the end: the image itself)
"$bin" render "$scene" --res 8x6 --no-png --spp 128 --guiding mis -o "$tmp/g128.exr" --checkpoint "$tmp/g128.ckpt" \
  2>"$tmp/log-g128" || bad "guided 128 spp render"
got=$(sed -n 's/^candela: checkpoint at \([0-9]*\) spp.*/\1/p' "$tmp/log-g128" | tr '\n' ' ')
[ "$got" = "4 8 14 22 54 " ] && ok || bad "checkpoint schedule (guided, 128 spp): got '$got', want '4 8 14 22 54 '"

# --- SIGKILL after a checkpoint, then resume (a slower render: one thread, small batches)
slow=(--spp 192 --threads 1 --batch 64)
for mode in default mis adaptive; do
  extra=(); [ $mode = mis ] && extra=(--guiding mis)
  [ $mode = adaptive ] && extra=("${adaptive[@]}")
  "$bin" "${base[@]}" "${slow[@]}" "${extra[@]}" -o "$tmp/kfull-$mode.exr" --quiet || bad "full slow render ($mode)"
  rm -f "$tmp/kill.ckpt" "$tmp/kill.exr"
  "$bin" "${base[@]}" "${slow[@]}" "${extra[@]}" -o "$tmp/kill.exr" --checkpoint "$tmp/kill.ckpt" --quiet &
  pid=$!
  for _ in $(seq 1 600); do [ -e "$tmp/kill.ckpt" ] && break; sleep 0.05; done
  kill -KILL $pid 2>/dev/null; wait $pid 2>/dev/null
  if [ ! -e "$tmp/kill.ckpt" ]; then bad "no checkpoint before SIGKILL ($mode)"; continue; fi
  [ -e "$tmp/kill.exr" ] && bad "the render finished before SIGKILL ($mode): the test proves less (machine too fast?)"
  "$bin" "${base[@]}" "${slow[@]}" "${extra[@]}" -o "$tmp/kill.exr" --resume-from "$tmp/kill.ckpt" \
    --checkpoint "$tmp/kill.ckpt" --quiet || bad "resume after SIGKILL ($mode)"
  same "$tmp/kfull-$mode.exr" "$tmp/kill.exr" "resumed after SIGKILL ($mode)"
  ls "$tmp"/kill.ckpt.tmp-* >/dev/null 2>&1 && bad "a stale checkpoint temporary survived ($mode)"
done

# --- SIGTERM: stop after the current batch, checkpoint, partial image; resume
rm -f "$tmp/term.ckpt"; : > "$tmp/term.log"
"$bin" "${base[@]}" "${slow[@]}" -o "$tmp/term.exr" --checkpoint "$tmp/term.ckpt" --save-partial 2>"$tmp/term.log" &
pid=$!
for _ in $(seq 1 600); do grep -q "checkpoint at 8 spp" "$tmp/term.log" && break; sleep 0.05; done
kill -TERM $pid; wait $pid; rc=$?
if [ $rc -eq 130 ]; then
  ok
  [ ! -e "$tmp/term.exr" ] && [ -e "$tmp/term.partial.exr" ] && ok || bad "SIGTERM: want only term.partial.exr"
  grep -q "checkpoint written to" "$tmp/term.log" && ok || bad "SIGTERM: no checkpoint message"
  "$bin" "${base[@]}" "${slow[@]}" -o "$tmp/term.exr" --resume-from "$tmp/term.ckpt" --quiet || bad "resume after SIGTERM"
  same "$tmp/kfull-default.exr" "$tmp/term.exr" "resumed after SIGTERM"
else
  bad "SIGTERM: exit $rc (want 130; finished before the signal?)"
fi
# A render stopped by SIGTERM once its log says it checkpointed AT spp, then resumed: the resumed
# EXR equals the uninterrupted render's (NAME: its files, WHAT: its messages; then the render's args)
term_and_resume() {
  local name=$1 at=$2 what=$3 pid rc
  shift 3
  "$bin" "$@" -o "$tmp/$name-full.exr" --quiet || bad "full render ($what, SIGTERM)"
  rm -f "$tmp/$name.ckpt"; : > "$tmp/$name.log"
  "$bin" "$@" -o "$tmp/$name.exr" --checkpoint "$tmp/$name.ckpt" 2>"$tmp/$name.log" &
  pid=$!
  for _ in $(seq 1 600); do grep -q "checkpoint at $at spp" "$tmp/$name.log" && break; sleep 0.05; done
  kill -TERM $pid; wait $pid; rc=$?
  if [ $rc -eq 130 ]; then
    "$bin" "$@" -o "$tmp/$name.exr" --resume-from "$tmp/$name.ckpt" --quiet || bad "resume after SIGTERM ($what)"
    same "$tmp/$name-full.exr" "$tmp/$name.exr" "resumed after SIGTERM ($what)"
  else
    bad "SIGTERM ($what): exit $rc (want 130; finished before the signal?)"
  fi
}
# ... guided with the adjoint-driven roulette, stopped within a guided iteration: the pixel
# estimates it decides by are the last barrier's, which the film of a checkpoint taken within an
# iteration no longer holds (the checkpoint keeps them)
term_and_resume gterm 14 "adjoint roulette" "${base[@]}" "${slow[@]}" --guiding mis --guide-roulette adjoint
# ... and with adaptive sampling, stopped within an iteration after some pixels stopped. A render
# with most of its work after the 16-spp checkpoint (64x48, threshold 0.05: pixels stop from 4 to
# ~400 spp, ~2.5 s on one thread, ~90% of it after 16 spp): the 32x24 adaptive render above
# finishes ~10 ms after its 32-spp checkpoint, which a fast machine beat the signal to
term_and_resume aterm 16 adaptive render "$scene" --res 64x48 --no-png --light-sampler cachepoints --spp 512 --threads 1 \
  --batch 64 --noise-threshold 0.05 --min-spp 4 --aov spp

# --- bad input: one line, nothing overwritten
ck=$tmp/default.ckpt
expect_error "another resolution" "flags disagree with the checkpoint: --res 16x16 (checkpoint 32x24)$" -- render "$scene" --res 16x16 --spp 64 --no-png --light-sampler cachepoints \
  -o "$tmp/keep.exr" --resume-from "$ck" --quiet
expect_error "another scene" "scene file's content differs" -- render "$root/tests/scenes/two_lights.gltf" --res 32x24 --light-sampler cachepoints \
  --spp 64 --no-png -o "$tmp/keep.exr" --resume-from "$ck" --quiet
expect_error "another spp" "flags disagree with the checkpoint: --spp 32 (checkpoint 64)$" -- "${base[@]}" --spp 32 -o "$tmp/keep.exr" --resume-from "$ck" --quiet
expect_error "another seed" "flags disagree with the checkpoint: --seed 5 (checkpoint 0)$" -- "${base[@]}" --spp 64 --seed 5 -o "$tmp/keep.exr" --resume-from "$ck" --quiet
expect_error "other options" "flags disagree with the checkpoint: --guiding mis (checkpoint off)$" -- "${base[@]}" --spp 64 --guiding mis -o "$tmp/keep.exr" \
  --resume-from "$ck" --quiet
head -c 2000 "$ck" > "$tmp/cut.ckpt"
expect_error "truncated" "checksum" -- "${base[@]}" --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/cut.ckpt" --quiet
cp "$ck" "$tmp/flip.ckpt"; printf '\x55' | dd of="$tmp/flip.ckpt" bs=1 seek=5000 conv=notrunc 2>/dev/null
expect_error "damaged" "checksum" -- "${base[@]}" --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/flip.ckpt" --quiet
expect_error "not a checkpoint" "not a candela checkpoint" -- "${base[@]}" --spp 64 -o "$tmp/keep.exr" \
  --resume-from "$scene" --quiet
expect_error "missing checkpoint" "cannot read" -- "${base[@]}" --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/none" --quiet
for spec in 4/4 -1/4 1/0 a/4 1/ 2/3x 1/100000; do
  expect_error "shard spec $spec" "--sample-shard" -- "${base[@]}" --spp 8 --sample-shard "$spec" -o "$tmp/s.film" --quiet
done
expect_error "checkpoint with compare" "for candela render" -- compare "$scene" --res 32x24 --spp 4 --checkpoint "$tmp/c.ckpt" \
  --out-dir "$tmp/cmp" --quiet
expect_error "shard output" "NAME.film" -- "${base[@]}" --spp 8 --sample-shard 0/2 -o "$tmp/keep.exr" --quiet
expect_error "shard of too few spp" "cannot be split" -- "${base[@]}" --spp 2 --sample-shard 0/4 -o "$tmp/s.film" --quiet
expect_error "adaptive shard" "cannot be used with --sample-shard" -- "${base[@]}" --spp 8 --sample-shard 0/2 \
  --noise-threshold 0.01 -o "$tmp/s.film" --quiet
expect_error "time-limited shard" "cannot be used with --sample-shard" -- "${base[@]}" --spp 8 --sample-shard 0/2 \
  --time-limit 10 -o "$tmp/s.film" --quiet
expect_error "min-spp alone" "needs --noise-threshold" -- "${base[@]}" --spp 8 --min-spp 4 -o "$tmp/keep.exr" --quiet

# --- issue 27: --resume-from FILE alone
# a guided render killed after a checkpoint (or the last checkpoint of a finished one: the same
# file), resumed with no other flag from another folder: the recorded scene, options and outputs
mkdir -p "$tmp/alone" "$tmp/elsewhere"
alone=(render "$scene" --res 32x24 --spp 64 --guiding mis --light-sampler cachepoints --max-depth 5 --seed 3 --no-png)
"$bin" "${alone[@]}" -o "$tmp/alone/full.exr" --quiet || bad "full render (alone)"
(cd "$tmp/alone" && "$bin" "${alone[@]}" -o img.exr --checkpoint run.ckpt --quiet) || bad "render with --checkpoint (alone)"
rm -f "$tmp/alone/img.exr"
# the record names the build that wrote it (its --version line, quoted): a resume by this build warns of nothing
sw=$("$bin" --version | sed 's/ /%20/g')
grep -a -q "software=\"$sw\"" "$tmp/alone/run.ckpt" && ok || bad "the checkpoint does not record the build ($sw)"
(cd "$tmp/elsewhere" && "$bin" render --resume-from ../alone/run.ckpt 2>"$tmp/alone/resume.log" >/dev/null) ||
  bad "render --resume-from FILE alone"
grep -q "written by" "$tmp/alone/resume.log" && bad "a resume by the same build warned: $(cat "$tmp/alone/resume.log")"
[ -e "$tmp/alone/img.exr" ] && ok || bad "resume alone did not write the recorded output ($(ls "$tmp/alone" "$tmp/elsewhere"))"
[ -e "$tmp/alone/img.png" ] && bad "resume alone wrote a PNG the render did not (--no-png recorded)"
same "$tmp/alone/full.exr" "$tmp/alone/img.exr" "resumed with --resume-from alone"
# with options that never change the image (another thread count, batch, output, --quiet)
"$bin" render --resume-from "$tmp/alone/run.ckpt" --threads 1 --batch 512 -o "$tmp/alone/t1.exr" --quiet ||
  bad "resume alone with --threads 1"
same "$tmp/alone/full.exr" "$tmp/alone/t1.exr" "resumed alone with --threads 1"
[ -e "$tmp/alone/t1.png" ] && ok || bad "-o given: its PNG is the default one"
# the flags given agree with the checkpoint: accepted (the same scene given, same values)
"$bin" "${alone[@]}" --threads 2 -o "$tmp/alone/agree.exr" --resume-from "$tmp/alone/run.ckpt" --quiet ||
  bad "resume with agreeing flags"
same "$tmp/alone/full.exr" "$tmp/alone/agree.exr" "resumed with agreeing flags"
# a sample shard's checkpoint alone: that shard's film, the same bytes as without the interruption
"$bin" "${alone[@]}" --sample-shard 1/2 -o "$tmp/alone/sh.film" --checkpoint "$tmp/alone/sh.ckpt" --quiet && mv "$tmp/alone/sh.film" "$tmp/alone/sh.full" &&
  "$bin" render --resume-from "$tmp/alone/sh.ckpt" --quiet && same "$tmp/alone/sh.full" "$tmp/alone/sh.film" "a shard resumed alone" ||
  bad "a sample shard resumed alone"
# every disagreement in one line (and the scene's content), nothing written
expect_error "several disagreements" \
  "run.ckpt: flags disagree with the checkpoint: --spp 8 (checkpoint 64), --seed 4 (checkpoint 3), --res 64x64 (checkpoint 32x24), --max-depth 2 (checkpoint 5)$" \
  -- render --resume-from "$tmp/alone/run.ckpt" --spp 8 --seed 4 --res 64x64 --max-depth 2 --threads 1 -o "$tmp/keep.exr"
expect_error "disagreeing scene and options" \
  "flags disagree with the checkpoint: --guiding off (checkpoint mis), .*two_lights.gltf (the scene file's content differs)$" \
  -- render "$root/tests/scenes/two_lights.gltf" --resume-from "$tmp/alone/run.ckpt" --guiding off -o "$tmp/keep.exr"
expect_error "resume alone from a missing file" "none.ckpt: cannot read" -- render --resume-from "$tmp/none.ckpt" -o "$tmp/keep.exr"

# --- sample shards: the merge is a pure function of the films (any order, bit for bit)
for i in 0 1 2 3; do
  "$bin" "${base[@]}" --spp 16 --sample-shard $i/4 -o "$tmp/s$i.film" --quiet || bad "shard $i"
done
"$bin" merge -o "$tmp/m1.exr" --no-png "$tmp"/s0.film "$tmp"/s1.film "$tmp"/s2.film "$tmp"/s3.film || bad "merge"
"$bin" merge -o "$tmp/m2.exr" --no-png "$tmp"/s3.film "$tmp"/s1.film "$tmp"/s0.film "$tmp"/s2.film || bad "merge reordered"
same "$tmp/m1.exr" "$tmp/m2.exr" "merge order"
[ -e "$tmp/m1.png" ] && bad "merge --no-png wrote a PNG"
"$bin" merge -o "$tmp/m3.exr" "$tmp"/s*.film && [ -e "$tmp/m3.png" ] && ok || bad "merge with a preview"
expect_error "merge: a shard missing" "shard count" -- merge -o "$tmp/keep.exr" "$tmp"/s0.film "$tmp"/s1.film "$tmp"/s2.film
expect_error "merge: a shard twice" "given twice" -- merge -o "$tmp/keep.exr" "$tmp"/s0.film "$tmp"/s1.film "$tmp"/s2.film \
  "$tmp"/s2.film
"$bin" "${base[@]}" --spp 16 --seed 3 --sample-shard 1/4 -o "$tmp/x1.film" --quiet || bad "shard of another seed"
expect_error "merge: another render" "another render" -- merge -o "$tmp/keep.exr" "$tmp"/s0.film "$tmp"/x1.film \
  "$tmp"/s2.film "$tmp"/s3.film
expect_error "merge: a checkpoint" "not a finished shard film" -- merge -o "$tmp/keep.exr" "$ck"
expect_error "resume alone from a film" "s0.film: a finished shard film" -- render --resume-from "$tmp/s0.film" -o "$tmp/keep.exr"
expect_error "resume from a film" "finished shard film" -- "${base[@]}" --spp 16 --sample-shard 0/4 -o "$tmp/s0b.film" \
  --resume-from "$tmp/s0.film" --quiet

# --- issue 29: SIGINT in a sample shard with --save-partial: nothing is written (a shard's
# film is only ever the whole one) and the message says so with the shard's own spp (it said
# "--save-partial keeps the image so far" and counted the shard's spp against the full render's)
"$bin" "${base[@]}" --spp 1048576 --sample-shard 1/4 --save-partial -o "$tmp/int.film" 2>"$tmp/int.log" &
pid=$!
sleep 2; kill -INT $pid; wait $pid; rc=$?
n=$(sed -n 's/.*interrupted after \([0-9]*\) of the 262144 spp of sample shard 1\/4; nothing written (a shard.s film is written only when complete, --save-partial does not apply to it.*/\1/p' "$tmp/int.log")
[ $rc -eq 130 ] && [ -n "$n" ] && [ "$n" -lt 262144 ] && ! ls "$tmp"/int.* 2>/dev/null | grep -v int.log && ok ||
  bad "shard + --save-partial + SIGINT: exit $rc, $(cat "$tmp/int.log"), $(ls "$tmp" | grep '^int')"
# --- issue 29: a FIFO or a device given as a checkpoint or a film is refused unread (fopen of a
# FIFO blocked forever)
mkfifo "$tmp/fifo.ckpt" "$tmp/fifo.film"
limit=10 expect_error "resume from a FIFO" "fifo.ckpt: not a regular file (a FIFO)" -- "${base[@]}" --spp 64 -o "$tmp/keep.exr" \
  --resume-from "$tmp/fifo.ckpt" --quiet
limit=10 expect_error "merge a FIFO" "fifo.film: not a regular file (a FIFO)" -- merge -o "$tmp/keep.exr" "$tmp/fifo.film"
limit=10 expect_error "merge /dev/zero" "/dev/zero: not a regular file (a device)" -- merge -o "$tmp/keep.exr" /dev/zero
rm -f "$tmp/fifo.ckpt" "$tmp/fifo.film"

# --- issue 29: the merged image never replaces a film being merged; a checkpoint never
# replaces the image it belongs to
cp "$tmp/s1.film" "$tmp/s1.keep"
expect_error "merge png onto a film" "s1.film: the merged PNG (--png) would replace a film being merged" -- merge -o "$tmp/keep.exr" \
  --png "$tmp/s1.film" "$tmp"/s0.film "$tmp"/s1.film "$tmp"/s2.film "$tmp"/s3.film
same "$tmp/s1.film" "$tmp/s1.keep" "a refused merge changed a film"
# the brief's own case: a shard given twice and the PNG onto it (the PNG is refused first)
expect_error "merge png onto a film given twice" "s1.film: the merged PNG (--png) would replace a film being merged" -- \
  merge -o "$tmp/keep.exr" --png "$tmp/s1.film" "$tmp"/s0.film "$tmp"/s1.film
same "$tmp/s1.film" "$tmp/s1.keep" "a refused merge changed a film"
# the merged EXR's lock file (emptied, then removed by the merge) may not be a film either
cp "$tmp/s1.film" "$tmp/lk.exr.lock"
expect_error "merge lock onto a film" "lk.exr.lock: the lock file of the merged EXR (-o) would replace a film being merged" -- \
  merge -o "$tmp/lk.exr" "$tmp"/s0.film "$tmp/lk.exr.lock" "$tmp"/s2.film "$tmp"/s3.film
same "$tmp/lk.exr.lock" "$tmp/s1.keep" "a refused merge changed the film named as its lock"
[ ! -e "$tmp/lk.exr" ] && ok || bad "a refused merge wrote its EXR"
rm -f "$tmp/lk.exr.lock"
expect_error "checkpoint named as the image" "the checkpoint (--checkpoint) and the EXR (-o) are the same file" -- "${base[@]}" --spp 8 \
  -o "$tmp/keep.exr" --checkpoint "$tmp/keep.exr" --quiet
expect_error "resume from the output" "the EXR (-o) would replace the checkpoint resumed (--resume-from)" -- "${base[@]}" --spp 64 \
  -o "$tmp/res.exr" --resume-from "$tmp/res.exr" --quiet

# forged films (the checksum recomputed, so only the merge's own checks can refuse them): NaN
# or infinite sums, a pixel counting 0 samples (it doubled the image) or a wrapped count, were
# written into the EXR with exit 0
forge() { # IN OUT WHAT: the film with one change, its checksum made right again
  python3 - "$1" "$2" "$3" <<'PY'
import struct, sys
src, dst, what = sys.argv[1:4]
b = bytearray(open(src, 'rb').read())
w, h, idlen = struct.unpack_from('<3I', b, 8 + 12)
samples = 8 + 24 + idlen                            # u64 spp_total, sample_begin, sample_count
reclen, = struct.unpack_from('<I', b, 8 + 24 + idlen + 24 + 8 + 8 + 8)
n = w * h
film = 8 + 24 + idlen + 24 + 8 + 8 + 8 + 4 + reclen + 8 + 12  # header, record, film tag + version, film head
sums = film                                         # sum, sum2, albedo, normal (3n doubles each)
count = film + 4 * 3 * n * 8 + n * 8 + n * 4        # after depth (n doubles) and hits (n u32)
if what == 'nan': struct.pack_into('<d', b, sums + 8 * 5, float('nan'))
elif what == 'inf': struct.pack_into('<d', b, sums + 3 * n * 8 + 8 * 7, float('inf'))
elif what == 'zero': struct.pack_into('<%dI' % n, b, count, *([0] * n))
elif what == 'wrap': struct.pack_into('<I', b, count + 4 * 3, 0xFFFFFFFF)
elif what == 'grow':  # shard 2/4 of 16 spp claims [8, 16) and its pixels count 8
    struct.pack_into('<QQ', b, samples + 8, 8, 8); struct.pack_into('<%dI' % n, b, count, *([8] * n))
elif what == 'empty': # shard 3/4 claims [16, 16): no samples, no hits, but its sums stay
    struct.pack_into('<QQ', b, samples + 8, 16, 0); struct.pack_into('<%dI' % (2 * n), b, count - 4 * n, *([0] * (2 * n)))
h = 0xcbf29ce484222325
for c in b[:-8]: h = ((h ^ c) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
struct.pack_into('<Q', b, len(b) - 8, h)
open(dst, 'wb').write(b)
PY
}
for what in nan inf zero wrap; do
  forge "$tmp/s1.film" "$tmp/f_$what.film" $what
  case $what in nan|inf) want="holds a sum that is not a finite number" ;; zero) want="counts 0 samples, the shard declares 4" ;;
                wrap) want="pixel (3, 0) counts 4294967295 samples" ;; esac
  expect_error "merge a forged film ($what)" "f_$what.film: not a film candela wrote: .*$want" -- merge -o "$tmp/keep.exr" --no-png \
    "$tmp"/s0.film "$tmp/f_$what.film" "$tmp"/s2.film "$tmp"/s3.film
done
# ... or a shard declaring other samples than its index gives it (shard 2/4 claiming [8, 16) and
# 3/4 none, still tiling [0, 16): merged with exit 0 into a wrong image)
forge "$tmp/s2.film" "$tmp/f_grow.film" grow
forge "$tmp/s3.film" "$tmp/f_empty.film" empty
expect_error "merge forged sample ranges" "f_grow.film: damaged header (its samples \[8, 16) are not shard 2/4's of 16 spp, \[8, 12))" -- \
  merge -o "$tmp/keep.exr" --no-png "$tmp"/s0.film "$tmp"/s1.film "$tmp/f_grow.film" "$tmp/f_empty.film"
expect_error "merge an empty shard" "f_empty.film: damaged header (its samples \[16, 16) are not shard 3/4's of 16 spp, \[12, 16))" -- \
  merge -o "$tmp/keep.exr" --no-png "$tmp"/s0.film "$tmp"/s1.film "$tmp/s2.film" "$tmp/f_empty.film"
# a checkpoint is the same film with a record: a forged one's NaN went into the resumed image
# and a wrapped count was taken (exit 0 both); its film is checked when loaded, before a sample
forge "$ck" "$tmp/f_nan.ckpt" nan
forge "$ck" "$tmp/f_wrap.ckpt" wrap
expect_error "resume a forged checkpoint (nan)" "f_nan.ckpt: not a checkpoint candela wrote: .*holds a sum that is not a finite number" -- \
  "${base[@]}" --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/f_nan.ckpt" --quiet
expect_error "resume a forged checkpoint (wrap)" "f_wrap.ckpt: not a checkpoint candela wrote: pixel (3, 0) counts 4294967295 samples, the checkpoint declares" -- \
  "${base[@]}" --spp 64 -o "$tmp/keep.exr" --resume-from "$tmp/f_wrap.ckpt" --quiet
# a guide field declaring 2^26 - 1 leaves in a 380 KB file (fuzz_film's finding: the loader
# allocated and freed them all, 5 GB and 9 s): refused from the bytes the file holds, and the
# render's peak memory stays far below that (1.5 GB, room for a sanitizer build; python3 reads
# the child's max RSS)
python3 - "$tmp/mis.ckpt" "$tmp/f_leaves.ckpt" <<'PY'
import struct, sys
b = bytearray(open(sys.argv[1], 'rb').read())
at = b.find(struct.pack('<2I', 0x44544453, 2))       # the first field: "SDTD", version 2
struct.pack_into('<I', b, at + 12, (1 << 26) - 1)   # its leaf count
h = 0xcbf29ce484222325
for c in b[:-8]: h = ((h ^ c) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
struct.pack_into('<Q', b, len(b) - 8, h)
open(sys.argv[2], 'wb').write(b)
PY
expect_error "resume a checkpoint declaring 2^26 guide leaves" "f_leaves.ckpt: the checkpoint's guiding state does not fit this render" -- \
  "${base[@]}" --spp 64 --guiding mis -o "$tmp/keep.exr" --resume-from "$tmp/f_leaves.ckpt" --quiet
peak=$(python3 -c 'import resource, subprocess, sys
subprocess.run(sys.argv[1:], stderr=subprocess.DEVNULL)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024)' \
  "$bin" "${base[@]}" --spp 64 --guiding mis -o "$tmp/keep.exr" --resume-from "$tmp/f_leaves.ckpt" --quiet)
[ "$peak" -lt 1500 ] && ok || bad "resuming a checkpoint declaring 2^26 guide leaves peaked at $peak MB"
forge "$ck" "$tmp/f_same.ckpt" none
"$bin" "${base[@]}" --spp 64 -o "$tmp/f_same.exr" --resume-from "$tmp/f_same.ckpt" --quiet && ok || bad "a re-checksummed checkpoint copy does not resume"
# the forger itself is right: an unchanged copy merges to the original's image
forge "$tmp/s1.film" "$tmp/f_same.film" none
"$bin" merge -o "$tmp/m4.exr" --no-png "$tmp"/s0.film "$tmp/f_same.film" "$tmp"/s2.film "$tmp"/s3.film && same "$tmp/m1.exr" "$tmp/m4.exr" \
  "a merge of a re-checksummed copy"

# a merge into an output another candela writes is refused (its lock)
flock "$tmp/keep.exr.lock" sleep 30 & holder=$!
for _ in $(seq 100); do [ -e "$tmp/keep.exr.lock" ] && break; sleep 0.05; done
expect_error "merge into a locked output" "keep.exr: another candela is writing it" -- merge -o "$tmp/keep.exr" --no-png \
  "$tmp"/s0.film "$tmp"/s1.film "$tmp"/s2.film "$tmp"/s3.film
kill $holder 2>/dev/null; wait $holder 2>/dev/null; rm -f "$tmp/keep.exr.lock"

echo "checkpoint tests: $pass passed, $fail failed"
[ $fail -eq 0 ]
