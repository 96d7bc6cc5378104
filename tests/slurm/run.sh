#!/usr/bin/env bash
# CI's check of deploy/slurm/transcode-array.sbatch on a real Slurm (docs/cluster.md): installs
# Debian's slurm-wlm and munge when they are missing, starts munged, slurmctld and slurmd on
# this machine as a one-node cluster whose configuration, state and logs all live in a
# temporary folder, submits the shipped sbatch script as a job array of 3 tasks over a
# 6-frame sequence plus a dependent --collect job, and checks every frame's outputs, the three
# shard manifests and the merged sequence.json and sequence.html.
# Fails (never skips) when Slurm cannot run here; prints the daemons' and jobs' logs on any
# failure.
# Usage: tests/slurm/run.sh TRANSCODE_BIN
set -euo pipefail
transcode="$(realpath "${1:?usage: tests/slurm/run.sh TRANSCODE_BIN}")"
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
[ -x "$transcode" ] || { echo "error: $transcode is not an executable" >&2; exit 1; }

# slurmd starts job steps as the submitting user and so must run as root; so must munged's
# key and socket setup here. Without root, rerun through passwordless sudo, else fail.
if [ "$(id -u)" != 0 ]; then
    if command -v sudo > /dev/null && sudo -n true 2> /dev/null; then
        exec sudo -n -- env "PATH=$PATH" bash "$0" "$transcode"
    fi
    echo "error: a Slurm test cluster needs root (slurmd runs jobs as their user); run as root or with passwordless sudo" >&2
    exit 1
fi

bash "$repo/.ci/ensure-debian-command" slurmctld slurm-wlm
bash "$repo/.ci/ensure-debian-command" munged munge
for command in slurmd sbatch squeue sinfo scontrol scancel python3; do
    command -v "$command" > /dev/null || { echo "error: $command is missing" >&2; exit 1; }
done
slurm_version="$(slurmd -V)"
echo "$slurm_version; $(munged -V 2>&1 | sed -n 1p)"

tmp="$(mktemp -d)"
chmod 755 "$tmp"
conf="$tmp/etc/slurm.conf"
mkdir -p "$tmp/etc" "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/log" "$tmp/jobs"
export SLURM_CONF="$conf"
started=$(date +%s)

show_logs() {
    echo "---- Slurm and munge logs (test folder $tmp)" >&2
    for log in "$tmp"/log/* "$tmp"/jobs/*.out; do
        [ -f "$log" ] || continue
        echo "---- $log" >&2
        tail -n 80 "$log" >&2
    done
    echo "---- sinfo" >&2
    sinfo -N -l >&2 2>&1 || true
    echo "---- squeue" >&2
    squeue >&2 2>&1 || true
}

# Stops only the daemons this script started, by their pid files.
stop_daemons() {
    scancel --quiet --full "${jobs[@]}" 2> /dev/null || true
    for pidfile in "$tmp/slurmd.pid" "$tmp/slurmctld.pid" "$tmp/munged.pid"; do
        if [ -s "$pidfile" ]; then
            kill "$(cat "$pidfile")" 2> /dev/null || true
        fi
    done
    # Give them a moment to exit before their folder goes.
    for _ in $(seq 50); do
        alive=0
        for pidfile in "$tmp/slurmd.pid" "$tmp/slurmctld.pid" "$tmp/munged.pid"; do
            if [ -s "$pidfile" ] && kill -0 "$(cat "$pidfile")" 2> /dev/null; then
                alive=1
            fi
        done
        [ "$alive" = 0 ] && break
        sleep 0.1
    done
}

jobs=()
on_exit() {
    status=$?
    if [ "$status" != 0 ]; then
        show_logs
        echo "FAILED: the Slurm sequence test (exit $status)" >&2
    fi
    stop_daemons
    rm -rf "$tmp"
    exit "$status"
}
trap on_exit EXIT

fail() {
    echo "error: $*" >&2
    exit 1
}

# A free TCP port each for slurmctld and slurmd, so that a Slurm already on this machine (or a
# parallel run) does not answer instead of ours.
free_port() {
    python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}
ctld_port=$(free_port)
slurmd_port=$(free_port)
[ "$ctld_port" != "$slurmd_port" ] || slurmd_port=$(free_port)

# munge: our own key and socket, so that no system munged is needed or disturbed.
dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge/munge.key"
socket="$tmp/munge/munge.socket"
# --force: munged refuses to run as root otherwise.
munged --force --key-file="$tmp/munge/munge.key" --socket="$socket" \
    --pid-file="$tmp/munged.pid" --log-file="$tmp/log/munged.log" \
    --seed-file="$tmp/munge/munged.seed" ||
    fail "munged did not start (see its log below)"
for _ in $(seq 50); do
    [ -S "$socket" ] && break
    sleep 0.1
done
[ -S "$socket" ] || fail "munged made no socket $socket"
munge --socket="$socket" -n | unmunge --socket="$socket" > /dev/null ||
    fail "munge cannot encode and decode a credential with our munged"

# Slurm wants the node's name to be this host's short name; the address is fixed to loopback.
host="$(hostname -s)"
cat > "$conf" << EOF
# One-node test cluster written by tests/slurm/run.sh.
ClusterName=transcodeci
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# Containers rarely give a writable cgroup hierarchy: track processes by their parents and
# bind no tasks, and gather no accounting, so that nothing needs cgroups.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
# The node below is smaller than most machines; config_overrides keeps slurmd from draining
# it when the machine is smaller than that, too.
SlurmdParameters=config_overrides
ReturnToService=2
MailProg=/bin/true
# Keep finished jobs in slurmctld's memory long enough for scontrol to show their exit codes.
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=1000 State=UNKNOWN
PartitionName=ci Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF

slurmctld -f "$conf" || fail "slurmctld did not start"
slurmd -f "$conf" || fail "slurmd did not start"

echo "== waiting for the node to be idle"
state=""
for _ in $(seq 120); do
    state="$(sinfo -h -N -o '%T' 2> /dev/null | sed -n 1p || true)"
    [ "$state" = idle ] && break
    sleep 0.5
done
[ "$state" = idle ] || fail "the node is '${state:-not listed}' after 60 s, not idle"
echo "node $host idle after $(($(date +%s) - started)) s"

echo "== a 6-frame sequence"
frames="$tmp/frames"
"$transcode" synth --mesh "$repo/testdata/meshes/spider/spider.obj" --out "$frames" \
    --frames 6 --points 20000 --grid 100 --cameras 13
out="$tmp/out"

echo "== the shipped sbatch script as a job array of 3 tasks, then a dependent --collect job"
# The quoted glob goes through sbatch and the script to transcode unexpanded. The command-line
# options override the script's #SBATCH defaults to fit this small node.
small=(--cpus-per-task=1 --mem=300M --time=10)
settings="--resolution 64 --iterations 60"
cd "$tmp/jobs"
array_job=$(sbatch --parsable --array=0-2 "${small[@]}" \
    "--export=ALL,INPUT=$frames/*.ply,OUT=$out,TRANSCODE=$transcode,TRANSCODE_ARGS=$settings" \
    "$repo/deploy/slurm/transcode-array.sbatch")
array_job="${array_job%%;*}"
jobs+=("$array_job")
collect_job=$(sbatch --parsable --array=0 --dependency="afterany:$array_job" "${small[@]}" \
    "--export=ALL,INPUT=$frames/*.ply,OUT=$out,TRANSCODE=$transcode,COLLECT=1" \
    "$repo/deploy/slurm/transcode-array.sbatch")
collect_job="${collect_job%%;*}"
jobs+=("$collect_job")
echo "submitted array job $array_job and collect job $collect_job"

submitted=$(date +%s)
timeout_s=300
while [ -n "$(squeue -h -j "$array_job,$collect_job" -o '%i' 2> /dev/null)" ]; do
    if [ $(($(date +%s) - submitted)) -gt "$timeout_s" ]; then
        fail "the jobs are still queued or running after $timeout_s s"
    fi
    sleep 1
done
echo "jobs done $(($(date +%s) - submitted)) s after submission"

echo "== checks"
# Every task of both jobs: COMPLETED with exit code 0 (scontrol -o: one line per task).
records="$(scontrol -o show job "$array_job"; scontrol -o show job "$collect_job")"
tasks=0
while read -r record; do
    task="$(grep -o 'ArrayJobId=[0-9]* ArrayTaskId=[0-9]*' <<< "$record" || true)"
    state="$(grep -o 'JobState=[A-Z_]*' <<< "$record" || true)"
    code="$(grep -o ' ExitCode=[0-9:]*' <<< "$record" || true)"
    echo "$task $state$code"
    if [ "$state" != JobState=COMPLETED ] || [ "$code" != " ExitCode=0:0" ]; then
        fail "job $task ended $state$code"
    fi
    tasks=$((tasks + 1))
done <<< "$records"
[ "$tasks" = 4 ] || fail "scontrol shows $tasks tasks, not the array's 3 and the collect job"

for task in 0 1 2; do
    log="$tmp/jobs/transcode-${array_job}_$task.out"
    [ -f "$log" ] || fail "no log $log from array task $task"
    grep -q "shard $task/3: 2 of 2 frames finished" "$log" ||
        fail "array task $task's log does not say that shard $task/3 finished its 2 frames"
    [ -f "$out/shards/shard-$task-of-3.json" ] || fail "no shard manifest shard-$task-of-3.json"
done
# One array task (the last to finish) merged the manifests itself; the collect job again.
grep -l "sequence: 6 frames, 6 finished, 0 failed" "$tmp"/jobs/transcode-"${array_job}"_*.out > /dev/null ||
    fail "no array task merged the manifests (none printed 'sequence: 6 frames, 6 finished')"
grep -q "sequence: 6 frames, 6 finished, 0 failed" "$tmp/jobs/transcode-${collect_job}_0.out" ||
    fail "the collect job did not print 'sequence: 6 frames, 6 finished, 0 failed'"

for frame in "$frames"/*.ply; do
    name="$(basename "$frame" .ply)"
    for file in model/splats.ply report/report.json; do
        [ -s "$out/frames/$name/$file" ] || fail "frame $name has no $file"
    done
done
[ -s "$out/sequence.html" ] || fail "no sequence.html"
python3 - "$out/sequence.json" << 'EOF'
import json
import sys

m = json.load(open(sys.argv[1]))
frames = m["frames"]
assert len(frames) == 6, f"{len(frames)} frames in sequence.json, not 6"
assert all(f["state"] == "finished" for f in frames), [(f["name"], f["state"]) for f in frames]
s = m["summary"]
assert (s["frames"], s["finished"], s["failed"]) == (6, 6, 0), s
# Contiguous blocks of 2: each block's first frame cold, its second warm from the first.
shards = [f["shard"]["index"] for f in frames]
assert shards == [0, 0, 1, 1, 2, 2], shards
assert all(f["shard"]["count"] == 3 for f in frames), frames
for k, f in enumerate(frames):
    expected = None if k % 2 == 0 else frames[k - 1]["name"]
    assert f["warm_start"] == expected, (f["name"], f["warm_start"], expected)
print("sequence.json: 6 frames finished in shards", shards, "warm starts as expected")
EOF

echo "$slurm_version: the 3-task array and the collect job passed in $(($(date +%s) - started)) s"
