#!/usr/bin/env bash
# renderer/'s folders are layers (renderer/meson.build): util < materials < scene < lights <
# integrator < app. A file includes renderer headers only from its own folder or the folders
# below it (candela.h, the module's public header at renderer/'s top, from anywhere), no header
# include loop exists inside renderer/, and no source file sits outside the folders. The
# include graph is read from the files themselves. Usage: test_layers.sh SOURCE_ROOT
set -u
root=${1:?usage: test_layers.sh SOURCE_ROOT}
cd "$root/renderer" || exit 1
layers="util materials scene lights integrator app"
rank() { local i=0; for l in $layers; do [ "$l" = "$1" ] && { echo $i; return; }; i=$((i + 1)); done; echo -1; }
fail=0
# where each renderer header lives
declare -A home
for f in */*.h; do
    h=$(basename "$f")
    [ -n "${home[$h]:-}" ] && { echo "FAIL: $h exists in ${home[$h]}/ and $(dirname "$f")/"; fail=1; }
    home[$h]=$(dirname "$f")
done
for f in *.c *.h; do
    [ -e "$f" ] || continue
    [ "$f" = "candela.h" ] && continue
    echo "FAIL: renderer/$f is outside the layer folders"; fail=1
done
for d in */; do
    d=${d%/}
    [ "$(rank "$d")" -ge 0 ] || { echo "FAIL: renderer/$d/ is not a layer ($layers)"; fail=1; }
done
checked=0
for f in */*.c */*.h; do
    dir=$(dirname "$f")
    r=$(rank "$dir")
    while IFS= read -r inc; do
        [ "$inc" = "candela.h" ] && continue
        to=${home[$inc]:-}
        [ -n "$to" ] || continue # another module's public header, or a system one
        if [ "$(rank "$to")" -gt "$r" ]; then
            echo "FAIL: renderer/$f ($dir) includes $inc from $to/, a layer above it"
            fail=1
        fi
        checked=$((checked + 1))
    done < <(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$f")
done
# no include loop among the headers (depth-first search over the header graph)
declare -A state
loop=""
visit() {
    local h=$1 inc
    state[$h]=1
    for inc in $(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "${home[$h]}/$h"); do
        [ -n "${home[$inc]:-}" ] || continue
        case "${state[$inc]:-0}" in
        1) loop="$loop $h -> $inc;" ;;
        0) visit "$inc" ;;
        esac
    done
    state[$h]=2
}
for h in "${!home[@]}"; do [ "${state[$h]:-0}" = 0 ] && visit "$h"; done
if [ -n "$loop" ]; then echo "FAIL: include loop among renderer headers:$loop"; fail=1; fi
[ "$fail" = 0 ] || exit 1
echo "renderer/: $checked includes of renderer headers, each from its own layer or below ($layers); no header loop"
