#!/usr/bin/env bash
# README.md against the program (issue 27).
#  flags:   README's "## Options" flag rows (every "- `...` — ..." line: the flags and short aliases
#           before the dash) equal the options table (`candela help --list-flags`: every row's name
#           and alias, and --version): a table flag missing from README fails, and so does a README
#           flag the table does not have.
#  recipes: every fenced block after a `<!-- test: recipe -->` line (README's "A check in seconds":
#           the recipes at tiny resolutions and spp) runs as written, command by command, from a
#           fresh folder holding only `build/renderer/candela` (this build's binary) and `scenes/`
#           (the repository's), and must exit 0 and write what it names. Not run: the quick
#           start's two set-up commands (`bash .ci/setup`, `bash .ci/run`: they install packages
#           and build), the Slurm recipes (`candela_submit.sh` needs sbatch), the Blender export
#           (needs blender and a .blend), the volumes (scenes/make_volumes.py needs
#           python3-openvdb) and the full-size recipes (minutes each at their resolution and spp on
#           a small machine): they carry no marker.
# usage: test_readme.sh CANDELA_BINARY SOURCE_ROOT [flags|recipes]
set -u
bin=$1; root=$(cd "$2" && pwd); what=${3:-all}
readme=$root/README.md
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }

if [ "$what" = all ] || [ "$what" = flags ]; then
  # the table's flags and aliases, one a line
  if "$bin" help --list-flags | tr ' ' '\n' | sed '/^$/d' | sort -u >"$tmp/table"; then ok; else bad "candela help --list-flags failed"; fi
  [ "$(wc -l <"$tmp/table")" -gt 50 ] && ok || bad "candela help --list-flags listed $(wc -l <"$tmp/table") flags"
  # README's flag rows: the "## Options" section's "- `...` — text" lines, the part before " — "
  awk '/^## Options/ { on = 1; next } /^## / { on = 0 } on && /^- `/' "$readme" | sed 's/ — .*//' >"$tmp/rows"
  [ "$(wc -l <"$tmp/rows")" -gt 50 ] && ok || bad "README.md: only $(wc -l <"$tmp/rows") flag rows under ## Options"
  # a flag: a dash or two and a lower-case name, after the start of a backtick span, a space or a comma
  grep -oE '(`|, | )--?[a-z][a-z0-9-]*' "$tmp/rows" | sed -E 's/^(`|, | )//' | sort -u >"$tmp/readme"
  missing=$(comm -23 "$tmp/table" "$tmp/readme" | tr '\n' ' ')
  extra=$(comm -13 "$tmp/table" "$tmp/readme" | tr '\n' ' ')
  [ -z "$missing" ] && ok || bad "flags of the options table missing from README.md's Options: $missing"
  [ -z "$extra" ] && ok || bad "README.md's Options lists flags the options table does not have: $extra"
fi

if [ "$what" = all ] || [ "$what" = recipes ]; then
  # the marked blocks' commands, a line each (a trailing backslash joins the next line)
  awk '/^<!-- test: recipe -->/ { marked = 1; next }
       /^```/ { if (inblock) { inblock = 0; marked = 0; next } if (marked) { inblock = 1; ++n; next } }
       inblock { print n "\t" $0 }' "$readme" |
    awk -F'\t' '{ line = $2; if (cont != "") line = cont " " line; if (line ~ /\\$/) { sub(/\\$/, "", line); cont = line; next }
                  cont = ""; print $1 "\t" line }' >"$tmp/commands"
  [ "$(wc -l <"$tmp/commands")" -ge 5 ] && ok || bad "README.md: fewer than 5 commands in marked recipe blocks"
  work=$tmp/fresh
  mkdir -p "$work/build/renderer"
  ln -s "$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")" "$work/build/renderer/candela"
  ln -s "$root/scenes" "$work/scenes"
  while IFS=$'\t' read -r block cmd; do
    case $cmd in
      *sbatch*|*candela_submit.sh*|*blender*|*.ci/*) bad "marked block $block holds a command this test cannot run: $cmd"; continue ;;
    esac
    echo "recipe block $block: $cmd" >&2
    if (cd "$work" && bash -euo pipefail -c "$cmd") </dev/null >"$tmp/out" 2>"$tmp/err"; then ok
    else bad "README recipe (block $block) failed: $cmd: $(tail -3 "$tmp/err")"; fi
  done <"$tmp/commands"
  # what the recipes say they write is there
  # what the commands name after -o, --out-dir and --dump-cachepoints is there
  for f in $(grep -oE '(-o|--out-dir|--dump-cachepoints) [^ ]+' "$tmp/commands" | cut -d' ' -f2 | grep -v '[$*]'); do
    [ -e "$work/$f" ] && ok || bad "a recipe did not write $f"
  done
  [ -s "$work/out/compare-tiny/index.html" ] && ok || bad "the compare recipe wrote no index.html"
fi
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
