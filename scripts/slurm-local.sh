#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, and the tiny scene run through workflow/profiles/slurm on it.
#
#   scripts/slurm-local.sh up     # as root: apt-get install munge, MariaDB, slurmctld, slurmd, slurmdbd;
#                                 # write slurm.conf/slurmdbd.conf for this host; start the daemons; add
#                                 # cluster, account and user with sacctmgr; install the plugin extra (.[slurm])
#   scripts/slurm-local.sh test   # submit the tiny scene through the slurm profile into a scratch folder and
#                                 # check with sacct that every job COMPLETED (prints the sacct table)
#   scripts/slurm-local.sh down   # stop the daemons this script started (configs and the database stay)
#   scripts/slurm-local.sh status # sinfo, the daemons' pids
#
# Daemons are started directly (no systemd needed; works in containers). The configuration uses no cgroups
# (proctrack/linuxproc, task/none), so it runs where /sys/fs/cgroup is absent or read-only.
# Environment: LIVESCENE_SLURM_ACCOUNT (default: livescene), LIVESCENE_SLURM_SCRATCH (default:
# /tmp/livescene-slurm-test), LIVESCENE_SLURM_CLUSTER (default: livescene).
set -euo pipefail
cd "$(dirname "$0")/.."
REPO=$PWD

CLUSTER=${LIVESCENE_SLURM_CLUSTER:-livescene}
ACCOUNT=${LIVESCENE_SLURM_ACCOUNT:-livescene}
SCRATCH=${LIVESCENE_SLURM_SCRATCH:-/tmp/livescene-slurm-test}
CONF_DIR=/etc/slurm
MARK="# written by livescene scripts/slurm-local.sh"
RUN=/run/livescene-slurm          # pid files
LOGS=/var/log/slurm
DB_PASS_FILE=/etc/slurm/.livescene-dbpass
HOST=$(hostname -s)

say() { echo "slurm-local: $*"; }
die() { echo "slurm-local: error: $*" >&2; exit 1; }
need_root() { [[ $(id -u) -eq 0 ]] || die "'$1' needs root (it installs packages and starts daemons); run it with sudo"; }

pidfile() { if [[ $1 == mariadb ]]; then echo /run/mysqld/mariadb.pid; else echo "$RUN/$1.pid"; fi; }
alive() { [[ -f $(pidfile "$1") ]] && kill -0 "$(cat "$(pidfile "$1")")" 2>/dev/null; }

wait_for() {  # wait_for SECONDS DESCRIPTION COMMAND...
  local limit=$1 what=$2
  shift 2
  for _ in $(seq "$limit"); do
    if "$@" >/dev/null 2>&1; then return 0; fi
    sleep 1
  done
  die "$what did not come up within ${limit}s (logs: $LOGS/)"
}

install_packages() {
  local missing=()
  for bin in munged:munge mariadbd:mariadb-server slurmctld:slurmctld slurmd:slurmd slurmdbd:slurmdbd \
             sbatch:slurm-client; do
    command -v "${bin%%:*}" >/dev/null 2>&1 || [[ -x /usr/sbin/${bin%%:*} ]] || missing+=("${bin#*:}")
  done
  if ((${#missing[@]})); then
    say "installing Debian packages: ${missing[*]}"
    apt-get update -qq
    # policy-rc.d may refuse to start services during install (containers): we start them ourselves.
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
}

write_configs() {
  if [[ -f $CONF_DIR/slurm.conf ]] && ! grep -qF "$MARK" "$CONF_DIR/slurm.conf"; then
    die "$CONF_DIR/slurm.conf exists and was not written by this script; this machine already has a cluster"
  fi
  mkdir -p "$CONF_DIR" "$RUN" "$LOGS" /var/lib/slurm/slurmctld /var/lib/slurm/slurmd
  chown slurm:slurm "$LOGS" "$RUN" /var/lib/slurm/slurmctld
  # CPUs and memory as slurmd itself measures them (a node that claims more is drained).
  local cpus mem
  cpus=$(nproc)
  mem=$(slurmd -C | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
  [[ -n $mem ]] || die "slurmd -C reported no RealMemory"
  [[ -f $DB_PASS_FILE ]] || { head -c 18 /dev/urandom | base64 | tr -d '/+=' >"$DB_PASS_FILE"; chmod 600 "$DB_PASS_FILE"; }
  cat >"$CONF_DIR/slurm.conf" <<EOF
$MARK
# One node ($HOST, $cpus CPUs, $mem MB). Partitions cpu and gpu are the names workflow/profiles/slurm uses;
# here both hold the same node (it has no GPU: the CPU config asks for gpu=0, so no --gpus is sent).
ClusterName=$CLUSTER
SlurmctldHost=$HOST
AuthType=auth/munge
SlurmUser=slurm
SlurmctldPort=6817
SlurmdPort=6818
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$LOGS/slurmctld.log
SlurmdLogFile=$LOGS/slurmd.log
# No cgroups: processes are tracked through /proc, tasks are not bound.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=30
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MpiDefault=none
# Finished jobs stay visible to squeue for 5 min; the snakemake plugin reads states with sacct anyway.
MinJobAge=300
# Accounting through slurmdbd (MariaDB): sacct shows every job, jobs need a valid account.
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=6819
AccountingStorageEnforce=associations
# Keep sbatch --comment (the plugin writes rule_<rule>_wildcards_<...> there) so sacct can show it.
AccountingStoreFlags=job_comment
JobCompType=jobcomp/none
NodeName=$HOST CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=cpu Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
PartitionName=gpu Nodes=$HOST MaxTime=INFINITE State=UP
EOF
  cat >"$CONF_DIR/slurmdbd.conf" <<EOF
$MARK
AuthType=auth/munge
DbdHost=localhost
DbdPort=6819
SlurmUser=slurm
PidFile=$RUN/slurmdbd.pid
LogFile=$LOGS/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=localhost
StoragePort=3306
StorageLoc=slurm_acct_db
StorageUser=slurm
StoragePass=$(cat "$DB_PASS_FILE")
EOF
  chown slurm:slurm "$CONF_DIR/slurmdbd.conf"
  chmod 600 "$CONF_DIR/slurmdbd.conf"
}

start_munge() {
  if pgrep -x munged >/dev/null; then return; fi
  mkdir -p /run/munge /var/log/munge /var/lib/munge
  chown munge:munge /run/munge /var/log/munge /var/lib/munge
  [[ -s /etc/munge/munge.key ]] || { mungekey --create --keyfile /etc/munge/munge.key; chown munge:munge /etc/munge/munge.key; }
  runuser -u munge -- /usr/sbin/munged
  wait_for 20 munged bash -c 'munge -n | unmunge'
}

start_mariadb() {
  if ! mysqladmin ping >/dev/null 2>&1; then
    mkdir -p /run/mysqld
    chown mysql:mysql /run/mysqld
    [[ -d /var/lib/mysql/mysql ]] || mariadb-install-db --user=mysql --datadir=/var/lib/mysql >/dev/null
    (setsid mariadbd --user=mysql --datadir=/var/lib/mysql --pid-file=/run/mysqld/mariadb.pid \
        --bind-address=127.0.0.1 >"$LOGS/mariadb.log" 2>&1 &)
    wait_for 60 MariaDB mysqladmin ping
  fi
  local pass
  pass=$(cat "$DB_PASS_FILE")
  mariadb <<EOF
CREATE DATABASE IF NOT EXISTS slurm_acct_db;
CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED BY '$pass';
ALTER USER 'slurm'@'localhost' IDENTIFIED BY '$pass';
GRANT ALL ON slurm_acct_db.* TO 'slurm'@'localhost';
FLUSH PRIVILEGES;
EOF
}

start_slurm() {
  alive slurmdbd || slurmdbd
  wait_for 60 slurmdbd sacctmgr -n list cluster
  # The cluster must be known to slurmdbd before slurmctld registers with it.
  sacctmgr -i -Q add cluster "$CLUSTER" >/dev/null 2>&1 || true
  sacctmgr -i -Q add account "$ACCOUNT" Cluster="$CLUSTER" Description="LiveScene workflow" \
    Organization=livescene >/dev/null 2>&1 || true
  # root, and under sudo the calling user too, may submit with the account.
  local user
  for user in $(id -un) ${SUDO_USER:-}; do
    sacctmgr -i -Q add user "$user" Account="$ACCOUNT" DefaultAccount="$ACCOUNT" Cluster="$CLUSTER" \
      >/dev/null 2>&1 || true
  done
  if alive slurmctld; then
    scontrol reconfigure  # a rewritten slurm.conf takes effect
  else
    slurmctld
  fi
  wait_for 60 slurmctld scontrol ping
  alive slurmd || slurmd
  wait_for 60 "node $HOST" bash -c "sinfo -h -N -n $HOST -o %T | grep -Eq '^(idle|mixed|allocated)'"
  scontrol update NodeName="$HOST" State=RESUME >/dev/null 2>&1 || true
}

install_plugin() {
  [[ -x .venv/bin/python ]] || scripts/bootstrap.sh
  if ! .venv/bin/python -c 'import snakemake_executor_plugin_slurm' 2>/dev/null; then
    say "installing the optional extra .[slurm] (snakemake-executor-plugin-slurm) into .venv"
    .venv/bin/python -m pip install -q -e ".[slurm]"
  fi
}

cmd_up() {
  need_root up
  install_packages
  write_configs
  start_munge
  start_mariadb
  start_slurm
  install_plugin
  say "cluster '$CLUSTER' up on $HOST; account '$ACCOUNT' for $(id -un)${SUDO_USER:+ and $SUDO_USER}"
  sinfo
  sacctmgr -n -P list associations format=cluster,account,user | sed 's/^/  association: /'
}

cmd_test() {
  scontrol ping >/dev/null 2>&1 || die "no slurmctld answers; run 'scripts/slurm-local.sh up' first"
  rm -rf "$SCRATCH"
  mkdir -p "$SCRATCH"
  printf 'scene\tsource\tpath\tposes\tmasks\tkey_frames\tnames\ttruth\tmethods\n' >"$SCRATCH/scenes.tsv"
  printf 'tiny\tsynthetic\tconfig/captures/tiny.yaml\testimate\tyes\tyes\tyes\tyes\tlivescene\n' >>"$SCRATCH/scenes.tsv"
  cat >"$SCRATCH/config.yaml" <<EOF
# The tiny scene, a few seconds of training: what scripts/slurm-local.sh test submits.
scenes: $SCRATCH/scenes.tsv
results: $SCRATCH/results
reports: $SCRATCH/reports
methods: [livescene]
train: {steps: 40, max_seconds: 0, eval_every: 20}
evaluate: {max_views: 1, unseen_views: 1}
report: {sweep_methods: [livescene], sweep_steps: 2, sweep_scale: 0.5, grid_views: 1}
stability: {run: false, quick: true, groups: []}
EOF
  local mem
  mem=$(scontrol show node "$HOST" | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
  say "submitting the tiny scene through workflow/profiles/slurm (results in $SCRATCH)"
  local start end rc=0
  start=$(date +%s)
  # The profile asks for paper-scale threads and memory (8 CPUs for evaluate, 32 GB for train); this node has $(nproc)
  # CPUs and $mem MB: threads are capped with --max-threads, memory with LIVESCENE_SLURM_MAX_MEM_MB.
  set +e
  LIVESCENE_SLURM_ACCOUNT=$ACCOUNT LIVESCENE_SLURM_MAX_MEM_MB=$((mem / 2)) \
    .venv/bin/snakemake --workflow-profile workflow/profiles/slurm --configfile "$SCRATCH/config.yaml" \
    --max-threads "$(nproc)" 2>&1 | tee "$SCRATCH/snakemake.log"
  rc=${PIPESTATUS[0]}
  set -e
  end=$(date +%s)
  say "snakemake exited with $rc after $((end - start)) s"
  # Every job of this run carries the run ID as its SLURM job name (that is how the plugin finds them).
  local run_id submitted
  run_id=$(sed -n 's/^SLURM run ID: //p' "$SCRATCH/snakemake.log" | head -1)
  [[ -n $run_id ]] || die "no 'SLURM run ID' in $SCRATCH/snakemake.log"
  submitted=$(grep -c 'submitted with SLURM jobid' "$SCRATCH/snakemake.log" || true)
  local since
  since=$(date -d "@$start" +%Y-%m-%dT%H:%M:%S)
  sacct -X --name "$run_id" --starttime "$since" --format=JobID,Comment%40,Partition,Account,AllocCPUS,ReqMem,State,ExitCode,Elapsed \
    | tee "$SCRATCH/sacct.txt"
  local states bad
  states=$(sacct -X -n -P --name "$run_id" --starttime "$since" --format=State)
  bad=$(grep -cv '^COMPLETED$' <<<"$states" || true)
  say "run $run_id: $submitted jobs submitted, $(grep -c . <<<"$states") in sacct, $bad not COMPLETED;" \
      "$(grep -c '^localrule ' "$SCRATCH/snakemake.log" || true) local jobs; wall time $((end - start)) s"
  [[ $(grep -c . <<<"$states") -eq $submitted ]] || die "sacct does not list every submitted job"
  [[ $rc -eq 0 && $bad -eq 0 ]] || die "the SLURM run failed (log: $SCRATCH/snakemake.log, slurm logs: .snakemake/slurm_logs/)"
  [[ -s $SCRATCH/reports/index.html ]] || die "no report index in $SCRATCH/reports"
  say "OK: every job COMPLETED; report at $SCRATCH/reports/index.html"
}

cmd_down() {
  need_root down
  for d in slurmd slurmctld slurmdbd mariadb; do
    if alive "$d"; then
      local pid
      pid=$(cat "$(pidfile "$d")")
      kill "$pid"
      for _ in $(seq 30); do kill -0 "$pid" 2>/dev/null || break; sleep 1; done
      say "stopped $d"
    fi
  done
  local munged
  munged=$(cat /run/munge/munged.pid 2>/dev/null || true)
  if [[ -n $munged ]] && kill -0 "$munged" 2>/dev/null; then
    kill "$munged"
    say "stopped munged"
  fi
}

cmd_status() {
  local munged
  munged=$(cat /run/munge/munged.pid 2>/dev/null || true)
  if [[ -n $munged ]] && kill -0 "$munged" 2>/dev/null; then
    echo "munged: running (pid $munged)"
  else
    echo "munged: stopped"
  fi
  for d in slurmd slurmctld slurmdbd mariadb; do
    if alive "$d"; then echo "$d: running (pid $(cat "$(pidfile "$d")"))"; else echo "$d: stopped"; fi
  done
  sinfo 2>/dev/null || true
}

case "${1:-}" in
  up) cmd_up ;;
  test) cmd_test ;;
  down) cmd_down ;;
  status) cmd_status ;;
  *) echo "usage: $0 up|test|down|status" >&2; exit 2 ;;
esac
