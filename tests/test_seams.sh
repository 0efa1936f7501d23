#!/usr/bin/env bash
# The integrator's seams hold: the wavefront's files (the stages, their sequencing, the path
# state, the film, the scattering interface) name no light-selection strategy; they reach
# light selection only through the protocol of renderer/lights/light_sampler.h. A strategy named
# there would be a second place to change when a strategy (or a second caller of light
# selection) is added. And no stage file calls a function another stage file defines (what
# stages share is renderer/integrator/vertex.c's). And wavefront.c, checkpoint.c and render.c reach the
# integrator's features through the feature table only. And the stages and the vertex module call
# the recorder's hooks unconditionally: whether it records is tested inside them (integrator.h).
# Usage: test_seams.sh SOURCE_ROOT
set -u
root=${1:?usage: test_seams.sh SOURCE_ROOT}
cd "$root/renderer" || exit 1
files=$(ls integrator/stage_*.c integrator/wavefront.c integrator/integrator.h integrator/path_state.h integrator/path_state.c app/render.c integrator/queue_sort.c util/sort.c integrator/film.c integrator/scatter.h integrator/scatter.c integrator/vertex.h integrator/vertex.c)
pattern='cache ?points?|cachepoint|CachePoint|optimal|light_?tree|LightTree|CANDELA_LIGHT_SAMPLER_[A-Z]+|power_distribution'
hits=$(grep -n -i -E "$pattern" $files)
if [ -n "$hits" ]; then
    echo "FAIL: the wavefront names a light-selection strategy (use renderer/lights/light_sampler.h):"
    echo "$hits"
    exit 1
fi
# and the stages reach light selection only through the protocol's functions
direct=$(grep -n -E '\bops->(select|pmf|prepare|record)\b' $files)
if [ -n "$direct" ]; then
    echo "FAIL: a stage calls a strategy's operation directly:"
    echo "$direct"
    exit 1
fi
echo "$(echo $files | wc -w) files checked: no strategy named"
# stages do not use each other as libraries: what two stages share lives in vertex.c (or
# integrator.h), so no stage file calls a function another stage file defines
calls=""
for def in integrator/stage_*.c; do
    names=$(grep -E '^[A-Za-z_][A-Za-z0-9_ *]*[ *]([a-z_][a-z0-9_]*)\(' "$def" | grep -v -E '^(static|typedef)' |
            sed -E 's/^[^(]*[ *]([a-z_][a-z0-9_]*)\(.*/\1/')
    for name in $names; do
        for use in integrator/stage_*.c; do
            [ "$use" = "$def" ] && continue
            hit=$(grep -n -E "\b$name\(" "$use")
            [ -n "$hit" ] && calls="$calls$use calls $name (defined in $def): $hit
"
        done
    done
done
if [ -n "$calls" ]; then
    echo "FAIL: a stage calls a function of another stage file (move it to renderer/integrator/vertex.c):"
    printf '%s' "$calls"
    exit 1
fi
echo "$(ls integrator/stage_*.c | wc -l) stage files: none calls another's functions"
# the integrator's features (feature.h: the recorder, guiding, the volume auto choices) are
# reached through the feature table only: the driver, the render loop and the checkpoint file
# name none of them in code (comments may say why)
named=$(for f in integrator/wavefront.c app/checkpoint.c app/render.c; do
    perl -0pe 's{/\*.*?\*/}{}gs; s{//[^\n]*}{}g' "$f" |
        grep -n -i -E 'guid|\b(record|guide|inscatter|emission_auto|emission_probe|auto_probe)_[a-z0-9_]*\s*\(|\big->(record|guide|inscatter|inscatter_auto|emission_auto)\b' |
        sed "s|^|$f:|"
done)
if [ -n "$named" ]; then
    echo "FAIL: a feature is named outside the feature table (add a hook to renderer/integrator/feature.h):"
    echo "$named"
    exit 1
fi
echo "wavefront.c, checkpoint.c, render.c: no feature named"
# the recorder's on/off test lives inside its hooks (record_vertex_child, record_nee_vertex, ...,
# integrator.h): a stage or the vertex module that tests record.active is a second place to
# change when the recorder's condition does (guide.c decides it; record.c is the recorder)
tested=$(for f in integrator/stage_*.c integrator/vertex.h integrator/vertex.c; do
    perl -0pe 's{/\*.*?\*/}{}gs; s{//[^\n]*}{}g' "$f" | grep -n -E 'record\s*(\.|->)\s*active' | sed "s|^|$f:|"
done)
if [ -n "$tested" ]; then
    echo "FAIL: the recorder's on/off test outside its hooks (call a record_* hook of integrator.h, which tests it):"
    echo "$tested"
    exit 1
fi
echo "stage files, vertex.h, vertex.c: the recorder's on/off test only inside its hooks"
