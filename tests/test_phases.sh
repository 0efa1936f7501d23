#!/bin/bash
# tests/test_phases.sh: the render's phases (issue 28) in the stats JSON, and the loader's memory
# per light at small scale.
#
# 1. Every phase (parse, flatten, embree, lights, sampler, first_iteration) is in "phases" with
#    its seconds (>= 0), the peak memory by its end (> 0, never falling from phase to phase, at
#    most the render's peak_memory_bytes) and the resident memory at its end (at most that
#    peak); the load phases add up to time_seconds.load and the sampler phase to
#    time_seconds.build (sums of recorded numbers, no clock thresholds).
# 2. Memory: the 20,000-light street written as Blender writes light objects (one named node and
#    one light record per light: make_manylights.py street_20k) against city_1k (1,000 lights):
#    the loader's phases (parse, flatten) may grow by at most 4 KiB per extra light and the
#    render's peak by at most 4 KiB. tinygltf's JSON tree and Model took ~6 KiB per light here
#    before the bulk pass (127 MB against 13 MB); ~1.1 KiB with nlohmann's bulk pass; 1.9 KiB
#    with simdjson's (its padded copy of the text); 3.4 KiB since the pass validates the text
#    with simdjson's DOM parser first (b18396f: its tape and string buffer, freed before the
#    pass; on the 1M-light street the whole run's peak is 1,089 MiB, within issue 28's 1.5 GiB).
#    RSS of one process, no timing.
#    Checked in builds without sanitizers only (SANITIZE, meson's b_sanitize: AddressSanitizer's
#    redzones and quarantine multiply every allocation, 9.7 KiB per light here); the release
#    suite runs it.
# usage: test_phases.sh CANDELA_BINARY SOURCE_ROOT [SANITIZE]
set -u
BIN=$1
ROOT=$2
export SANITIZE=${3:-none}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
command -v python3 >/dev/null || { echo "SKIP: no python3"; exit 77; }
python3 "$ROOT/scenes/make_manylights.py" "$TMP" --only city_1k street_20k >/dev/null || { echo "FAIL: generator"; exit 1; }
for s in city_1k street_20k; do
    "$BIN" render "$TMP/$s.gltf" --res 32x18 --spp 2 --threads 2 --light-sampler tree --no-png -q \
        -o "$TMP/$s.exr" --stats-json "$TMP/$s.json" || { echo "FAIL: render $s"; exit 1; }
done
python3 - "$TMP/city_1k.json" "$TMP/street_20k.json" <<'PY'
import json, os, sys
PHASES = ['parse', 'flatten', 'embree', 'lights', 'sampler', 'first_iteration']
fails = []
def check(cond, msg):
    if not cond:
        fails.append(msg)
stats = [json.load(open(p)) for p in sys.argv[1:]]
for name, d in zip(['city_1k', 'street_20k'], stats):
    ph = d.get('phases', {})
    check(list(ph) == PHASES, '%s: phases %s, expected %s' % (name, list(ph), PHASES))
    if list(ph) != PHASES:
        continue
    peak = d['peak_memory_bytes']
    for i, k in enumerate(PHASES):
        check(ph[k]['seconds'] >= 0.0, '%s: %s seconds %g' % (name, k, ph[k]['seconds']))
        check(0 < ph[k]['peak_bytes'] <= peak, '%s: %s peak %d (render peak %d)' % (name, k, ph[k]['peak_bytes'], peak))
        check(0 < ph[k]['rss_bytes'] <= ph[k]['peak_bytes'], '%s: %s resident %d, peak %d' % (name, k, ph[k]['rss_bytes'], ph[k]['peak_bytes']))
        if i:
            prev = PHASES[i - 1]
            check(ph[k]['peak_bytes'] >= ph[prev]['peak_bytes'], '%s: the peak fell from %s to %s' % (name, prev, k))
    t = d['time_seconds']
    load = sum(ph[k]['seconds'] for k in PHASES[:4])
    check(abs(load - t['load']) <= 0.01 + 0.01 * t['load'], '%s: load phases %g, time_seconds.load %g' % (name, load, t['load']))
    check(abs(ph['sampler']['seconds'] - t['build']) <= 0.01 + 0.01 * t['build'],
          '%s: sampler %g, time_seconds.build %g' % (name, ph['sampler']['seconds'], t['build']))
    check(ph['first_iteration']['seconds'] <= t['total'], '%s: first iteration longer than the render' % name)
if not fails and os.environ.get('SANITIZE', 'none') != 'none':
    print('memory per light not checked: built with -fsanitize=%s' % os.environ['SANITIZE'])
elif not fails:
    small, big = stats
    extra = big['lights'] - small['lights']
    check(extra == 19000, 'light counts %d, %d' % (small['lights'], big['lights']))
    loader = lambda d: d['phases']['flatten']['peak_bytes']  # the peak by the loader's end
    per_light = (loader(big) - loader(small)) / extra
    check(per_light <= 4096, 'the loader takes %.0f bytes per light (at most 4096)' % per_light)
    per_light_render = (big['peak_memory_bytes'] - small['peak_memory_bytes']) / extra
    check(per_light_render <= 4096, 'the render takes %.0f bytes per light (at most 4096)' % per_light_render)
    print('loader %.0f bytes per light, render %.0f' % (per_light, per_light_render))
for f in fails:
    print('FAIL: ' + f)
sys.exit(1 if fails else 0)
PY
