#!/usr/bin/env bash
# The integrator's seams hold: the wavefront's files (the stages, their sequencing, the path
# state, the film, the scattering interface) name no light-selection strategy; they reach
# light selection only through the protocol of renderer/light_sampler.h. A strategy named
# there would be a second place to change when a strategy (or a second caller of light
# selection) is added. Usage: test_seams.sh SOURCE_ROOT
set -u
root=${1:?usage: test_seams.sh SOURCE_ROOT}
cd "$root/renderer" || exit 1
files=$(ls stage_*.c wavefront.c integrator.h path_state.h path_state.c render.c sort.c film.c scatter.h scatter.c)
pattern='cache ?points?|cachepoint|CachePoint|optimal|light_?tree|LightTree|CANDELA_LIGHT_SAMPLER_[A-Z]+|power_distribution'
hits=$(grep -n -i -E "$pattern" $files)
if [ -n "$hits" ]; then
    echo "FAIL: the wavefront names a light-selection strategy (use renderer/light_sampler.h):"
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
