#!/usr/bin/env bash
# scenes/farm/candela_submit.sh: render on a Slurm cluster as a job array.
#
# Two kinds of job:
#   frames:        candela_submit.sh --frames 1-48 -o out/shot.####.exr SCENE [-- RENDER OPTIONS]
#                  an array of --tasks tasks (default: one per frame); each runs
#                  `candela render SCENE --frames A-B -o PATTERN`, which reads SLURM_ARRAY_TASK_ID
#                  and SLURM_ARRAY_TASK_COUNT itself and renders its share of the frames (with
#                  --resume, a requeued task skips the frames it finished).
#   sample shards: candela_submit.sh --sample-shards 8 -o out/frame.exr SCENE [-- RENDER OPTIONS]
#                  one frame too slow for one machine: task I renders samples
#                  [spp I/N, spp (I+1)/N) of every pixel (`--sample-shard I/N`) into
#                  WORK/shard.I.film, and a merge job (once all of them have ended, requeued ones
#                  included) runs `candela merge` into the -o EXR (per-pixel means and variances
#                  of all samples); it fails, naming them, when shards failed.
#
# Resume on requeue: tasks are submitted with --requeue (unless --no-requeue). A sample shard
# checkpoints to WORK/shard.I.ckpt (`--checkpoint`, written at about 4, 8, 16, ... spp and when
# Slurm sends SIGTERM before pre-empting or at the time limit); a requeued task (SLURM_RESTART_COUNT
# > 0) with a checkpoint continues it (`--resume-from`), and the image is the same as without the
# interruption. candela is exec'd, so Slurm's SIGTERM reaches it; --signal asks for one 120 s
# before the time limit. A new submission removes the previous submission's checkpoints (they
# belong to another render or to one that is starting over).
#
# Options:
#   -p, --partition NAME     Slurm partition (default: the cluster's default)
#   -c, --cpus-per-task N    CPUs per task, also candela's --threads (default: the cores of the
#                            machine running this script, `nproc`; give N when nodes differ)
#   --mem SIZE               memory per task, Slurm syntax (e.g. 4G; default: the cluster's)
#   -t, --time LIMIT         time limit per task, Slurm syntax (e.g. 2:00:00)
#   --frames RANGE           frames to render (candela's --frames syntax, e.g. 1-48 or 1-48:2)
#   --tasks N                frames: array tasks sharing the frames (default: frames in RANGE)
#   --max-running N          at most N tasks of the array run at once (sbatch --array=0-9%N)
#   --sample-shards N        split one frame's samples over N tasks, then merge
#   -o, --output PATH        frames: the pattern (out/shot.####.exr); shards: the merged EXR
#   --work-dir DIR           shard films, checkpoints, job scripts and Slurm logs (default:
#                            OUTPUT.farm/ for shards, JOBNAME.farm/ beside the frames)
#   --candela PATH           the candela binary (default: `candela` on PATH, resolved now)
#   --job-name NAME          (default candela)
#   --no-requeue             do not requeue pre-empted tasks
#   --sbatch-arg ARG         one more argument, verbatim, for every sbatch call (array and merge),
#                            after the script's own; repeatable (--sbatch-arg --account=lighting
#                            --sbatch-arg --qos=high)
#   --wait                   wait until every job has finished (sbatch --wait); exit status is
#                            non-zero when one failed
#   --dry-run                print the job scripts and sbatch commands, submit nothing
#   --                       everything after goes to `candela render` (--spp, --res, --seed, ...)
#
# Prints the job ids (array, and merge for shards). Example:
#   scenes/farm/candela_submit.sh -p render -c 16 --mem 32G -t 4:00:00 --sample-shards 8 \
#       -o out/hero.exr scenes/default.gltf -- --spp 4096 --res 1920x1080
#   scenes/farm/candela_submit.sh --sbatch-arg --account=lighting --max-running 10 \
#       --frames 1-240 -o out/shot.####.exr scenes/animation.gltf
set -euo pipefail

usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; }
die() { echo "candela_submit: $*" >&2; exit 2; }

partition="" cpus="" mem="" time_limit="" frames="" tasks="" shards="" output="" work="" candela=""
job_name=candela requeue=1 wait=0 dry=0 scene="" max_running=""
render_args=() extra_sbatch=()
while [ $# -gt 0 ]; do
  case "$1" in
    -p|--partition) partition=${2:?}; shift 2 ;;
    -c|--cpus-per-task) cpus=${2:?}; shift 2 ;;
    --mem) mem=${2:?}; shift 2 ;;
    -t|--time) time_limit=${2:?}; shift 2 ;;
    --frames) frames=${2:?}; shift 2 ;;
    --tasks) tasks=${2:?}; shift 2 ;;
    --sample-shards) shards=${2:?}; shift 2 ;;
    -o|--output) output=${2:?}; shift 2 ;;
    --work-dir) work=${2:?}; shift 2 ;;
    --candela) candela=${2:?}; shift 2 ;;
    --job-name) job_name=${2:?}; shift 2 ;;
    --max-running) max_running=${2:?}; shift 2 ;;
    --sbatch-arg) extra_sbatch+=("${2:?}"); shift 2 ;;
    --no-requeue) requeue=0; shift ;;
    --wait) wait=1; shift ;;
    --dry-run) dry=1; shift ;;
    -h|--help) usage; exit 0 ;;
    --) shift; render_args=("$@"); break ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *) [ -z "$scene" ] || die "one scene per submission ('$1')"; scene=$1; shift ;;
  esac
done

[ -n "$scene" ] || die "no scene given (see --help)"
[ -r "$scene" ] || die "$scene: cannot read"
[ -n "$output" ] || die "no -o OUTPUT given"
[ -n "$cpus" ] || cpus=$(nproc 2>/dev/null || getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
[[ $cpus =~ ^[1-9][0-9]*$ ]] || die "invalid --cpus-per-task '$cpus'"
if [ -n "$max_running" ]; then # base 10, as candela reads --tasks (08 is 8)
  [[ $max_running =~ ^0*([1-9][0-9]{0,8})$ ]] ||
    die "invalid --max-running '$max_running' (a positive whole number, at most 999999999)"
  max_running=${BASH_REMATCH[1]}
fi
throttle=${max_running:+%$max_running} # --array=0-9%N
if [ -n "$frames" ] && [ -n "$shards" ]; then die "--frames and --sample-shards do not combine (shard one frame at a time)"; fi
if [ -z "$frames" ] && [ -z "$shards" ]; then die "give --frames RANGE or --sample-shards N"; fi
if [ -z "$candela" ]; then candela=$(command -v candela || true); fi
[ -n "$candela" ] && [ -x "$candela" ] || die "candela binary not found (--candela PATH)"
candela=$(cd "$(dirname "$candela")" && pwd)/$(basename "$candela")
scene=$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")
out_dir=$(dirname "$output"); mkdir -p "$out_dir"; out_dir=$(cd "$out_dir" && pwd)
output=$out_dir/$(basename "$output")
if [ -z "$work" ]; then
  if [ -n "$shards" ]; then work=$output.farm; else work=$out_dir/$job_name.farm; fi
fi
mkdir -p "$work"; work=$(cd "$work" && pwd)
quote() { local s; s=$(printf '%q ' "$@"); printf '%s' "${s% }"; } # shell-quoted words, for the job scripts
# write_script FILE: the job script on stdin into FILE, made executable, written as candela writes
# its outputs (io/README.md "Writing an output"): to FILE.tmp-PID, synced, then renamed, so that a
# full disk or a killed submission never leaves a cut job script for sbatch; a failure is one line
# naming the file and the reason, and leaves no temporary
write_script() {
  local tmp="$1.tmp-$$" why
  if ! why=$( { cat > "$tmp" && chmod +x "$tmp" && sync -- "$tmp" && mv -f -- "$tmp" "$1"; } 2>&1 ); then
    rm -f -- "$tmp"
    why=$(head -n 1 <<<"$why"); die "$1: cannot write: ${why##*: }"
  fi
}

sbatch_opts=(--parsable --job-name="$job_name" --cpus-per-task="$cpus" --signal=B:TERM@120)
[ -n "$partition" ] && sbatch_opts+=(--partition="$partition")
[ -n "$mem" ] && sbatch_opts+=(--mem="$mem")
[ -n "$time_limit" ] && sbatch_opts+=(--time="$time_limit")
if [ $requeue -eq 1 ]; then sbatch_opts+=(--requeue); else sbatch_opts+=(--no-requeue); fi

# submit SCRIPT_FILE SBATCH_OPTIONS...: prints the job id; --sbatch-arg's words come last
submit() {
  local script=$1; shift
  set -- "$@" "${extra_sbatch[@]}"
  if [ $dry -eq 1 ]; then
    echo "# sbatch $(quote "$@") $script" >&2; cat "$script" >&2; echo "DRY-RUN"
  else
    sbatch "$@" "$script"
  fi
}

# Numbers are candela's to read: each job's command line is checked by candela itself
# (`candela render ... --dry-run`, which loads nothing) before anything is submitted, and the
# counts used here are the ones it prints back, in base 10 and within its bounds (bash
# arithmetic read 08 as octal, wrapped 2^63, and looped 20-digit counts). SLURM_ARRAY_* are left
# out so that a submission from inside an array task still sees the whole request.
# dry_run ARGS...: candela's answer on stdout; its one-line refusal becomes this script's
dry_run() {
  local out
  if ! out=$(env -u SLURM_ARRAY_TASK_ID -u SLURM_ARRAY_TASK_COUNT -u SLURM_ARRAY_TASK_MIN -u SLURM_ARRAY_TASK_STEP \
               "$candela" render "$scene" "${render_args[@]}" --threads "$cpus" "$@" --dry-run 2>"$work/dry-run.err"); then
    local why; why=$(head -n 1 "$work/dry-run.err"); rm -f "$work/dry-run.err"
    die "$why"
  fi
  rm -f "$work/dry-run.err"
  printf '%s\n' "$out"
}

if [ -n "$shards" ]; then
  [[ $shards =~ ^[0-9]+$ ]] || die "invalid --sample-shards '$shards' (a whole number)"
  checked=$(dry_run --sample-shard "0/$shards" --checkpoint "$work/shard.0.ckpt" -o "$work/shard.0.film") || exit 2
  shards=$(sed -n 's|^sample-shard 0/\([0-9]*\) .*|\1|p' <<<"$checked")
  [ -n "$shards" ] || die "candela --dry-run printed no shard count: $checked"
  # a new render: nothing of an earlier one is resumed or merged
  [ $dry -eq 1 ] || rm -f "$work"/shard.*.ckpt "$work"/shard.*.film
  write_script "$work/shard.sh" <<EOF
#!/usr/bin/env bash
# one sample shard (array task \$SLURM_ARRAY_TASK_ID of $shards), resumed from its checkpoint when requeued
set -eu
i=\$SLURM_ARRAY_TASK_ID
ck=$(quote "$work")/shard.\$i.ckpt
resume=()
if [ "\${SLURM_RESTART_COUNT:-0}" -gt 0 ] && [ -e "\$ck" ]; then
  resume=(--resume-from "\$ck")
  echo "candela_submit: restart \$SLURM_RESTART_COUNT of shard \$i/$shards: resuming from \$ck" >&2
fi
exec $(quote "$candela" render "$scene" "${render_args[@]}") --threads $cpus --sample-shard "\$i/$shards" \\
  --checkpoint "\$ck" "\${resume[@]}" -o $(quote "$work")/shard.\$i.film
EOF
  films=()
  for ((i = 0; i < shards; ++i)); do films+=("$work/shard.$i.film"); done
  # The merge runs once every shard task has ended (afterany, not afterok: a task requeued by a
  # pre-emption passes through a failed-looking state, and afterok would cancel the merge). A
  # requeued task is queued again and its film missing: the merge waits while any task of the
  # array is in a state that is not final (squeue -t all: a requeued task passes through
  # REQUEUED / REQUEUE_HOLD, which squeue's default pending-running-completing list leaves out,
  # so the merge took it for gone and failed); a film still missing then belongs to a shard
  # that failed.
  write_script "$work/merge.sh" <<EOF
#!/usr/bin/env bash
set -u
films=($(quote "${films[@]}"))
missing() { local f m=""; for f in "\${films[@]}"; do [ -e "\$f" ] || m="\$m \$f"; done; echo "\$m"; }
final='COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE'
while [ -n "\$(missing)" ]; do
  if states=\$(squeue -h -t all -j "\$CANDELA_SHARD_ARRAY" -o %T 2>/dev/null) &&
     [ -z "\$(grep -vxE "\$final" <<<"\$states" | grep .)" ]; then
    sleep 5 # a task that just finished: look once more
    [ -z "\$(missing)" ] && break
    echo "candela_submit: no shard task of job \$CANDELA_SHARD_ARRAY is left and these films are missing:\$(missing) (see the shard logs)" >&2
    exit 1
  fi
  sleep 10
done
exec $(quote "$candela" merge -o "$output") "\${films[@]}"
EOF
  array_opts=("${sbatch_opts[@]}" --array="0-$((shards - 1))$throttle" --output="$work/shard.%a.log")
  array_id=$(submit "$work/shard.sh" "${array_opts[@]}")
  merge_opts=("${sbatch_opts[@]}" --cpus-per-task=1 --dependency=afterany:"$array_id"
              --export=ALL,CANDELA_SHARD_ARRAY="$array_id" --output="$work/merge.log")
  # with --wait, sbatch returns once the merge (which waits for the array) has ended
  if [ $wait -eq 1 ] && [ $dry -eq 0 ]; then merge_opts+=(--wait); fi
  merge_id=$(submit "$work/merge.sh" "${merge_opts[@]}")
  echo "array $array_id merge $merge_id"
else
  # a requeued task skips the frames it finished (candela --frames --resume; a grep -q on
  # candela's help here was killed by SIGPIPE under pipefail and silently dropped it)
  resume="--resume"
  # candela reads --frames (lists, ranges, steps, base 10) and prints the frames back
  listed=$(dry_run --frames "$frames" $resume -o "$output") || exit 2
  nframes=$(grep -c '^frame ' <<<"$listed")
  if [ -z "$tasks" ]; then
    tasks=$nframes
  else
    [[ $tasks =~ ^[0-9]+$ ]] || die "invalid --tasks '$tasks' (a whole number)"
    checked=$(dry_run --frames "$frames" --shard "0/$tasks" $resume -o "$output") || exit 2
    tasks=$(sed -n 's|^shard 0/\([0-9]*\)$|\1|p' <<<"$checked")
    [ -n "$tasks" ] || die "candela --dry-run printed no task count: $checked"
    [ "$tasks" -le "$nframes" ] || die "--tasks $tasks is more than the $nframes frames (every task needs a frame)"
  fi
  write_script "$work/frames.sh" <<EOF
#!/usr/bin/env bash
# array task \$SLURM_ARRAY_TASK_ID of $tasks: candela takes its share of the frames from SLURM_ARRAY_TASK_*
set -eu
exec $(quote "$candela" render "$scene" "${render_args[@]}") --threads $cpus --frames $(quote "$frames") $resume -o $(quote "$output")
EOF
  opts=("${sbatch_opts[@]}" --array="0-$((tasks - 1))$throttle" --output="$work/frames.%a.log")
  [ $wait -eq 1 ] && [ $dry -eq 0 ] && opts+=(--wait)
  array_id=$(submit "$work/frames.sh" "${opts[@]}")
  echo "array $array_id"
fi
