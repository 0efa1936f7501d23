#!/usr/bin/env bash
# A real single-node Slurm cluster on this machine, started and stopped by this test:
# munged with its own key and socket, slurmctld and slurmd on 127.0.0.1 with a slurm.conf
# written here (own ports, state and spool in a temporary folder, SlurmUser=root,
# proctrack/linuxproc, task/none, select/cons_tres, one node with CPUs=2). Jobs go through
# scenes/farm/candela_submit.sh, as a user's would.
#   0. the submit script refuses bad options with one line, and its dry run shows every option
#      in the job scripts and sbatch commands (partition, cpus, memory, time, requeue, ...); it
#      reads numbers as candela does, by asking candela (--dry-run): --frames 08-09 and
#      1,5,10-12 give 2 and 5 tasks, --sample-shards 70000, 2^63 and 20 digits are refused at
#      once. --sbatch-arg words reach every sbatch line (array and merge) exactly once, their
#      shell metacharacters unexecuted; --max-running N throttles the array (%N; 08 is 8), and
#      0, x and 20 digits are refused; without -c, tasks get nproc CPUs and threads. Part 0 needs
#      no cluster and runs before the checks that may skip the rest;
#   1. a 4-way sample-sharded frame (an array job, task I runs --sample-shard I/4, then the
#      merge job, submitted with --max-running 2 and --sbatch-arg "--comment=a b;c"): the cluster's
#      shard films equal local renders of the same shards byte for byte, its merged EXR equals the
#      local merge of those shards bit for bit, and the merge job's comment is "a b;c";
#   1a. shards that fail (a bad render option): the merge job fails, naming the missing films;
#   1b. resume on requeue: a 2-shard frame whose task 0 is requeued (`scontrol requeue`: Slurm
#      kills it and starts it again) after its first checkpoint resumes from it, and the merged
#      frame still equals the local merge bit for bit;
#   2. a 6-frame array job (candela render --frames 1-6 -o dir/f.####.exr, each task taking its
#      share from SLURM_ARRAY_TASK_ID / COUNT): every frame exists exactly once and equals a
#      local render of that frame bit for bit. Runs only when `candela --help` lists --frames.
# Skips (77) with the reason when not root (SlurmUser=root), when Slurm or munge is not
# installed (.ci/setup installs slurm-wlm and munge) or when the cluster does not come up.
# The daemons and jobs also run in the ASan build (about 50 s there): no skip needed.
# usage: test_slurm.sh CANDELA_BINARY SOURCE_ROOT EXR_SAME   (CANDELA_SLURM_KEEP=1 keeps the cluster's
# folder, with the daemons' and jobs' logs, for inspection)
set -u
bin=$(cd "$(dirname "$1")" && pwd)/$(basename "$1"); root=$(cd "$2" && pwd)
exr_same=$3
# the same pixels bit for bit (tests/exr_same.c): EXR headers carry each run's provenance
same_exr() { "$exr_same" "$1" "$2" 2>/dev/null; }
pass=0; fail=0
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }
# the cluster part may skip; what ran before it (part 0) must have passed
skip() { [ $fail -eq 0 ] || { echo "slurm tests: $pass passed, $fail failed (then skipped: $*)"; exit 1; }
         echo "skipped: $* (part 0: $pass passed)"; exit 77; }

# this shell's own renders are local ones, even when the suite itself runs inside a Slurm job
unset SLURM_ARRAY_TASK_ID SLURM_ARRAY_TASK_COUNT SLURM_ARRAY_JOB_ID SLURM_JOB_ID SLURM_RESTART_COUNT
submit=$root/scenes/farm/candela_submit.sh
scene=$root/scenes/default.gltf
tmp0=$(mktemp -d /tmp/candela-submit.XXXXXX)
trap 'rm -rf "$tmp0"' EXIT

# --- 0. the submit script's own checks (one line, exit 2) and its job scripts (--dry-run)
for bad_args in "--frames 3-1" "--frames 1-2 --sample-shards 2" "--sample-shards 0" "--cpus-per-task x --frames 1-2" "--bogus"; do
  # shellcheck disable=SC2086
  "$submit" --candela "$bin" $bad_args -o "$tmp0/x.exr" "$scene" >/dev/null 2>"$tmp0/sub.err"; rc=$?
  [ $rc -eq 2 ] && [ "$(grep -c . "$tmp0/sub.err")" -eq 1 ] && ok || bad "submit $bad_args: exit $rc, $(cat "$tmp0/sub.err")"
done
"$submit" --dry-run --candela "$bin" -p candela -c 2 --mem 1G -t 5:00 --sample-shards 4 -o "$tmp0/dry/x.exr" "$scene" \
  -- --spp 8 >/dev/null 2>"$tmp0/dry.out"
for want in "--partition=candela" "--cpus-per-task=2" "--mem=1G" "--time=5:00" "--requeue" "--array=0-3" \
            "--signal=B:TERM@120" "--sample-shard \"\$i/4\"" "--checkpoint \"\$ck\"" "--threads 2" "merge -o" \
            "--dependency=afterany:"; do
  grep -qF -- "$want" "$tmp0/dry.out" && ok || bad "dry run lacks '$want'"
done
[ ! -e "$tmp0/dry/x.exr" ] && ok || bad "a dry run wrote the output"
# numbers as candela reads them (issue 29: bash read 08 as octal, refused lists, accepted 70000
# shards that every task then refused, wrapped 2^63 and looped over 20-digit counts)
arrays() { # ARGS...: the --array of a dry-run submission, or the refusal (exit status, one line)
  timeout 60 "$submit" --dry-run --candela "$bin" -o "$tmp0/n/f.####.exr" "$scene" "$@" >/dev/null 2>"$tmp0/n.err"; local rc=$?
  if [ $rc -eq 0 ]; then grep -o -- '--array=[0-9-]*' "$tmp0/n.err" | head -n 1
  else echo "exit $rc, $(grep -c . "$tmp0/n.err") line(s): $(cat "$tmp0/n.err")"; fi
}
[ "$(arrays --frames 08-09)" = "--array=0-1" ] && ok || bad "--frames 08-09: $(arrays --frames 08-09)"
[ "$(arrays --frames 1,5,10-12)" = "--array=0-4" ] && ok || bad "--frames 1,5,10-12: $(arrays --frames 1,5,10-12)"
# a requeued frame task skips the frames it finished: its job script passes --resume
grep -q -- '--frames.* --resume -o' "$tmp0/n.err" && ok || bad "--frames job script lacks --resume"
[ "$(arrays --frames 1-20 --tasks 08)" = "--array=0-7" ] && ok || bad "--tasks 08: $(arrays --frames 1-20 --tasks 08)"
[ "$(arrays --sample-shards 08)" = "--array=0-7" ] && ok || bad "--sample-shards 08: $(arrays --sample-shards 08)"
grep -qF -- '--sample-shard "$i/8"' "$tmp0/n.err" && ok || bad "--sample-shards 08: the job script does not say 8"
for n in 70000 9223372036854775808 99999999999999999999; do
  got=$(arrays --sample-shards $n)
  case "$got" in "exit 2, 1 line(s): candela_submit: candela: invalid value '0/$n' for --sample-shard"*"N <= 65536)") ok ;;
                 *) bad "--sample-shards $n: $got" ;; esac
done
got=$(arrays --frames 1-3 --tasks 99999999999999999999)
case "$got" in "exit 2, 1 line(s): candela_submit: candela: invalid --shard '0/99999999999999999999'"*) ok ;; *) bad "--tasks 20 digits: $got" ;; esac
# a bad render option is refused at submission (candela's own line), not by every task
got=$(arrays --sample-shards 2 -- --max-depth -1)
case "$got" in "exit 2, 1 line(s): candela_submit: candela: invalid value '-1' for --max-depth"*) ok ;; *) bad "a bad render option: $got" ;; esac
got=$(arrays --frames 1-3 --tasks 5)
case "$got" in "exit 2, 1 line(s): candela_submit: --tasks 5 is more than the 3 frames"*) ok ;; *) bad "--tasks 5 of 3 frames: $got" ;; esac
# --sbatch-arg (issue 27): each word once, verbatim (shell-quoted in the printed line), on every
# sbatch line, array and merge; a word's metacharacters ($(...), ;) are never run
pwned=$tmp0/pwned
weird="--comment=a b;c \$(touch $pwned);touch $pwned"
"$submit" --dry-run --candela "$bin" --sbatch-arg --account=x --sbatch-arg "--comment=a b;c" --sbatch-arg "$weird" \
  --sample-shards 2 -o "$tmp0/sa/x.exr" "$scene" >/dev/null 2>"$tmp0/sa.out" || bad "--sbatch-arg dry run: $(cat "$tmp0/sa.out")"
grep '^# sbatch ' "$tmp0/sa.out" > "$tmp0/sa.lines"
[ "$(grep -c 'shard\.sh$' "$tmp0/sa.lines")" -eq 1 ] && [ "$(grep -c 'merge\.sh$' "$tmp0/sa.lines")" -eq 1 ] && ok ||
  bad "--sbatch-arg: expected one array and one merge sbatch line: $(cat "$tmp0/sa.lines")"
for job in shard merge; do
  line=$(grep "$job\.sh\$" "$tmp0/sa.lines")
  for word in --account=x "--comment=a b;c" "$weird"; do
    q=$(printf '%q' "$word")
    n=$(grep -oF -- " $q " <<<"$line " | wc -l)
    [ "$n" -eq 1 ] && ok || bad "--sbatch-arg $word: $n times (not once) in the $job sbatch line: $line"
  done
done
[ ! -e "$pwned" ] && ok || bad "--sbatch-arg: a word's shell metacharacters were executed"
"$submit" --dry-run --candela "$bin" --sbatch-arg --account=x --frames 1-2 -o "$tmp0/sa/f.####.exr" "$scene" \
  >/dev/null 2>"$tmp0/sa2.out"
[ "$(grep '^# sbatch .*frames\.sh$' "$tmp0/sa2.out" | grep -oF -- ' --account=x ' | wc -l)" -eq 1 ] && ok ||
  bad "--sbatch-arg: the frames array's sbatch line lacks --account=x once: $(grep '^# sbatch' "$tmp0/sa2.out")"
# --max-running N: the array's --array=0-M%N (frames and sample shards)
for n in 0 x -1 1.5 99999999999999999999; do
  got=$(arrays --frames 1-2 --max-running $n)
  case "$got" in "exit 2, 1 line(s): candela_submit: invalid --max-running '$n' (a positive whole number"*) ok ;;
                 *) bad "--max-running $n: $got" ;; esac
done
[ "$(arrays --frames 1-4 --max-running 3 | grep -c .)" -eq 1 ] &&
  grep -qF -- "--array=0-3%3 " "$tmp0/n.err" && ok || bad "--max-running 3 (frames): $(grep '^# sbatch' "$tmp0/n.err")"
arrays --sample-shards 5 --max-running 08 >/dev/null
grep -qF -- "--array=0-4%8 " "$tmp0/n.err" && ok || bad "--max-running 08 (shards): $(grep '^# sbatch' "$tmp0/n.err")"
arrays --frames 1-4 >/dev/null
grep -qF -- "--array=0-3 " "$tmp0/n.err" && ok || bad "no --max-running: the array is throttled: $(grep '^# sbatch' "$tmp0/n.err")"
# without -c: the cores of the submitting machine (nproc), for Slurm and for candela's --threads
cores=$(nproc)
arrays --sample-shards 2 >/dev/null
grep '^# sbatch .*shard\.sh$' "$tmp0/n.err" | grep -qF -- "--cpus-per-task=$cores " && ok ||
  bad "no -c: the array's sbatch line lacks --cpus-per-task=$cores: $(grep '^# sbatch' "$tmp0/n.err")"
grep -qF -- "--threads $cores " "$tmp0/n.err" && ok || bad "no -c: the job script lacks --threads $cores"
arrays --frames 1-2 >/dev/null
grep -qF -- "--cpus-per-task=$cores " "$tmp0/n.err" && grep -qF -- "--threads $cores " "$tmp0/n.err" && ok ||
  bad "no -c (frames): --cpus-per-task=$cores and --threads $cores expected: $(cat "$tmp0/n.err")"
# the job scripts are written as candela's outputs are (FILE.tmp-PID, synced, renamed): on a full
# disk (a small tmpfs, where this test may mount one) the submission fails in one line naming the
# script and the reason, and leaves neither a cut job script nor a temporary
mkdir -p "$tmp0/full"
if mount -t tmpfs -o size=16k tmpfs "$tmp0/full" 2>/dev/null; then
  mkdir "$tmp0/full/work"
  head -c 1M /dev/zero > "$tmp0/full/fill" 2>/dev/null
  "$submit" --dry-run --candela "$bin" --work-dir "$tmp0/full/work" --sample-shards 2 -o "$tmp0/full.exr" "$scene" \
    >/dev/null 2>"$tmp0/full.err"; rc=$?
  left=$(ls -A "$tmp0/full/work")
  if [ $rc -eq 2 ] && [ "$(grep -c . "$tmp0/full.err")" -eq 1 ] &&
     grep -q "^candela_submit: $tmp0/full/work/shard.sh: cannot write: No space left on device\$" "$tmp0/full.err" &&
     [ -z "$left" ]; then ok
  else bad "job scripts on a full disk: exit $rc, left '$left', $(cat "$tmp0/full.err")"; fi
  umount "$tmp0/full"
else
  echo "full-disk job script check skipped: cannot mount a tmpfs here"
fi

[ "$(id -u)" -eq 0 ] || skip "the test cluster runs its daemons as root (SlurmUser=root)"
for c in munged munge slurmctld slurmd sbatch sinfo scontrol; do
  command -v $c >/dev/null 2>&1 || skip "$c not installed (apt-get install slurm-wlm munge; .ci/setup does)"
done

tmp=$(mktemp -d /tmp/candela-slurm.XXXXXX)
chmod 755 "$tmp"
pids=()
cleanup() {
  # only what this test started, by pid
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  [ -s "$tmp/munge/munged.pid" ] && kill "$(cat "$tmp/munge/munged.pid")" 2>/dev/null
  for _ in $(seq 1 50); do
    alive=0
    for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    [ $alive -eq 0 ] && break; sleep 0.1
  done
  for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null; done
  if [ "${CANDELA_SLURM_KEEP:-0}" = 1 ]; then echo "kept $tmp"; else rm -rf "$tmp"; fi
  rm -rf "$tmp0"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

# --- munge: its own key, socket, pid, log and seed files
mkdir -p "$tmp/munge" "$tmp/munge-key" "$tmp/log" "$tmp/state" "$tmp/spool" "$tmp/work"
chmod 700 "$tmp/munge-key"; chmod 755 "$tmp/munge"
dd if=/dev/urandom of="$tmp/munge-key/munge.key" bs=1024 count=1 2>/dev/null
chmod 400 "$tmp/munge-key/munge.key"
sock=$tmp/munge/munge.sock
munged -f --key-file="$tmp/munge-key/munge.key" --socket="$sock" --pid-file="$tmp/munge/munged.pid" \
  --log-file="$tmp/log/munged.log" --seed-file="$tmp/munge-key/munged.seed" >/dev/null 2>&1 ||
  skip "munged does not start: $(tail -n 1 "$tmp/log/munged.log" 2>/dev/null)"
munge -S "$sock" -n >/dev/null 2>&1 || skip "munge does not answer on its socket"

# --- ports: two free consecutive TCP ports
port_free() { ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
port=""
for _ in $(seq 1 50); do
  p=$((20000 + RANDOM % 30000))
  if port_free $p && port_free $((p + 1)); then port=$p; break; fi
done
[ -n "$port" ] || skip "no free TCP ports"

host=$(hostname -s)
mem_mb=$(awk '/MemTotal/ { print int($2 / 1024 / 2) }' /proc/meminfo)
cat > "$tmp/slurm.conf" <<EOF
ClusterName=candelatest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
ReturnToService=2
InactiveLimit=0
MinJobAge=600
KillWait=5
NodeName=candela1 NodeHostname=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=$mem_mb State=UNKNOWN
PartitionName=candela Nodes=candela1 Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$tmp/slurm.conf

slurmctld -D >"$tmp/log/slurmctld.out" 2>&1 & pids+=($!)
slurmd -D -N candela1 >"$tmp/log/slurmd.out" 2>&1 & pids+=($!)
up=0
for _ in $(seq 1 120); do
  [ "$(sinfo -h -n candela1 -o %T 2>/dev/null)" = idle ] && { up=1; break; }
  sleep 0.5
done
if [ $up -eq 0 ]; then
  echo "--- slurmctld.log"; tail -n 5 "$tmp/log/slurmctld.log" 2>/dev/null
  echo "--- slurmd.log"; tail -n 5 "$tmp/log/slurmd.log" 2>/dev/null
  skip "the test cluster did not come up (node state '$(sinfo -h -n candela1 -o %T 2>/dev/null)')"
fi
echo "cluster up: slurmctld on 127.0.0.1:$port, node candela1 idle"

opts=(--spp 16 --res 32x24 --quiet)

# --- 1. a 4-way sample-sharded frame
echo "[$(date +%T)] 1. a 4-way sample-sharded frame"
work=$tmp/work/shards
if timeout 600 "$submit" --candela "$bin" --partition candela --cpus-per-task 1 --mem 500M --time 10:00 \
     --max-running 2 --sbatch-arg "--comment=a b;c" --sample-shards 4 --work-dir "$work" --wait -o "$tmp/work/frame.exr" "$scene" -- "${opts[@]}" >"$tmp/submit1.out" 2>&1; then
  ok
else
  bad "sharded job: $(cat "$tmp/submit1.out")"
  for f in "$work"/*.log; do echo "--- $f"; cat "$f"; done
fi
films=()
for i in 0 1 2 3; do
  "$bin" render "$scene" "${opts[@]}" --sample-shard $i/4 -o "$tmp/local.$i.film" || bad "local shard $i"
  films+=("$tmp/local.$i.film")
  cmp -s "$work/shard.$i.film" "$tmp/local.$i.film" && ok || bad "shard $i: the cluster's film differs from the local one"
done
"$bin" merge -o "$tmp/local.exr" --no-png "${films[@]}" || bad "local merge"
same_exr "$tmp/work/frame.exr" "$tmp/local.exr" && ok || bad "the cluster's merged frame differs from the local merge"
[ "$(ls "$work"/shard.*.film | wc -l)" -eq 4 ] && ok || bad "expected exactly 4 shard films"
merge1=$(awk '/^array .* merge /{print $4}' "$tmp/submit1.out")
scontrol show job "$merge1" 2>/dev/null | grep -q '^ *Comment=a b;c *$' && ok ||
  bad "--sbatch-arg: the merge job $merge1's comment: $(scontrol show job "$merge1" 2>&1 | grep -i comment)"

# --- 1a. shards that fail (a scene that cannot load: the dry run at submission does not load
# it): the merge job fails and names the missing films
head -c 3000 /dev/urandom > "$tmp/work/broken.gltf"
if timeout 600 "$submit" --candela "$bin" --partition candela -c 1 --sample-shards 2 --work-dir "$tmp/work/failing" --wait \
     -o "$tmp/work/failing.exr" "$tmp/work/broken.gltf" -- "${opts[@]}" >"$tmp/submit1a.out" 2>&1; then
  bad "a sharded job whose shards fail succeeded"
else
  grep -q "films are missing" "$tmp/work/failing/merge.log" && [ ! -e "$tmp/work/failing.exr" ] && ok ||
    bad "failing shards: merge.log says $(cat "$tmp/work/failing/merge.log")"
fi

# --- 1b. resume on requeue: a shard task requeued (killed) after its first checkpoint continues
# from it, and the merged frame is still the local merge bit for bit
echo "[$(date +%T)] 1b. resume on requeue"
slow=(--spp 192 --res 32x24 --threads 1 --batch 64 --quiet)
rwork=$tmp/work/requeue
ids=$("$submit" --candela "$bin" --partition candela -c 1 --sample-shards 2 --work-dir "$rwork" -o "$tmp/work/rq.exr" \
        "$scene" -- "${slow[@]}" 2>"$tmp/submit3.err") || bad "requeue job submission: $(cat "$tmp/submit3.err")"
array=$(echo "$ids" | awk '{print $2}'); merge=$(echo "$ids" | awk '{print $4}')
requeued=0
for _ in $(seq 1 1200); do
  if [ -e "$rwork/shard.0.ckpt" ]; then
    # a requeued job waits (BeginTime) before it may start again: now is fine here
    scontrol requeue "${array}_0" && requeued=1
    break
  fi
  sleep 0.05
done
[ $requeued -eq 1 ] && ok || bad "could not requeue shard 0 after its first checkpoint"
# Slurm holds a requeued job (Reason=BeginTime) for two minutes; once it is pending again, now
for _ in $(seq 1 300); do
  scontrol show job "${array}_0" 2>/dev/null | grep -q "JobState=PENDING" &&
    scontrol update JobId="${array}_0" StartTime=now 2>/dev/null && break
  sleep 0.1
done
echo "[$(date +%T)] requeued: $requeued"
state=""
for _ in $(seq 1 600); do
  state=$(scontrol show job "$merge" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
  case "$state" in COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY) break ;; esac
  sleep 1
done
[ "$state" = COMPLETED ] && ok || { bad "requeue: the merge job ended $state"; cat "$rwork"/*.log; }
echo "[$(date +%T)] merge job: $state"
restarts=$(scontrol show job "${array}_0" 2>/dev/null | sed -n 's/.*Restarts=\([0-9]*\).*/\1/p')
[ "${restarts:-0}" -ge 1 ] && ok || bad "requeue: shard 0 did not restart (Restarts=${restarts:-?})"
grep -q "resuming from" "$rwork/shard.0.log" && ok || bad "requeue: shard 0 did not resume from its checkpoint: $(cat "$rwork/shard.0.log")"
for i in 0 1; do "$bin" render "$scene" "${slow[@]}" --sample-shard $i/2 -o "$tmp/rq.$i.film" || bad "local shard $i/2"; done
"$bin" merge -o "$tmp/rq-local.exr" --no-png "$tmp/rq.0.film" "$tmp/rq.1.film" || bad "local merge (requeue)"
same_exr "$tmp/work/rq.exr" "$tmp/rq-local.exr" && ok || bad "the requeued render's merged frame differs from the local merge"

# --- 2. a 6-frame array job (candela render --frames, when built)
echo "[$(date +%T)] 2. a 6-frame array job"
if "$bin" --help | grep -q -- '--frames'; then
  fwork=$tmp/work/frames
  mkdir -p "$tmp/work/seq" "$tmp/local"
  if timeout 600 "$submit" --candela "$bin" --partition candela --cpus-per-task 1 --time 10:00 --frames 1-6 \
       --work-dir "$fwork" --wait -o "$tmp/work/seq/f.####.exr" "$scene" -- "${opts[@]}" >"$tmp/submit2.out" 2>&1; then
    ok
  else
    bad "frames job: $(cat "$tmp/submit2.out")"
    for f in "$fwork"/*.log; do echo "--- $f"; cat "$f"; done
  fi
  n=$(ls "$tmp/work/seq"/f.*.exr 2>/dev/null | wc -l)
  [ "$n" -eq 6 ] && ok || bad "expected 6 frames, found $n: $(ls "$tmp/work/seq")"
  for f in 1 2 3 4 5 6; do
    name=$(printf 'f.%04d.exr' $f)
    [ "$(ls "$tmp/work/seq" | grep -c "^$name\$")" -eq 1 ] || { bad "frame $f not there exactly once"; continue; }
    "$bin" render "$scene" "${opts[@]}" --frames $f-$f -o "$tmp/local/f.####.exr" >/dev/null 2>&1 ||
      { bad "local render of frame $f"; continue; }
    same_exr "$tmp/work/seq/$name" "$tmp/local/$name" && ok || bad "frame $f differs from a local render of it"
  done
else
  echo "skipped: --frames not built yet (part 2, the 6-frame array job)"
fi

echo "slurm tests: $pass passed, $fail failed"
[ $fail -eq 0 ]
