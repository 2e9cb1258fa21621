#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, for testing the workflow's SLURM executor for real
# (tests/test_slurm.py; docs/cluster.md). Debian 12's SLURM 22.05 with accounting (slurmdbd on a private
# MariaDB), because snakemake-executor-plugin-slurm asks `sacct` for job states.
#
#   scripts/local_slurm.sh install   apt-get the packages (root)
#   scripts/local_slurm.sh start     write the configs under $TOHGS_SLURM_DIR and start munged, mariadbd,
#                                    slurmdbd, slurmctld, slurmd; prints `export SLURM_CONF=...`
#   scripts/local_slurm.sh stop      stop the daemons started by `start` (their pid files)
#   scripts/local_slurm.sh status    sinfo
#
# Everything lives in $TOHGS_SLURM_DIR (default /tmp/tohgs-slurm): slurm.conf, slurmdbd.conf, the
# database, logs, spool and state. Clients find the cluster through SLURM_CONF, except inside a job:
# the plugin's job step (snakemake-executor-plugin-slurm-jobstep) removes every SLURM_* variable but the
# job's identity before it calls srun, so srun reads the default /etc/slurm/slurm.conf. `start` links
# that to ours when /etc/slurm/slurm.conf does not exist, and `stop` removes the link. Needs root (slurmd runs jobs as their user; the daemons run as root here). The node gets
# max(16, this machine's CPUs) CPUs and 90 % of its memory; one partition, `debug`; account `tohgs`.
set -euo pipefail

DIR=${TOHGS_SLURM_DIR:-/tmp/tohgs-slurm}
DB_PORT=${TOHGS_SLURM_DB_PORT:-3307}
PACKAGES="slurm-wlm slurmdbd mariadb-server munge"
export SLURM_CONF="$DIR/etc/slurm.conf"

die() { echo "local_slurm: $*" >&2; exit 1; }

need_root() { [ "$(id -u)" = 0 ] || die "needs root (it starts system daemons)"; }

wait_for() {  # wait_for <seconds> <what> <command...>: poll until the command succeeds
  local limit=$1 what=$2; shift 2
  for _ in $(seq 1 $((limit * 4))); do
    if "$@" >/dev/null 2>&1; then return 0; fi
    sleep 0.25
  done
  die "$what did not come up within ${limit}s (logs: $DIR/log)"
}

install() {
  need_root
  local missing=""
  for cmd in slurmctld slurmd slurmdbd mariadbd munged sacct; do
    command -v "$cmd" >/dev/null 2>&1 || [ -x "/usr/sbin/$cmd" ] || missing=1
  done
  if [ -n "$missing" ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PACKAGES >/dev/null
  fi
}

write_configs() {
  local host cpus mem
  host=$(hostname -s)
  # The node advertises at least TOHGS_SLURM_CPUS (default 16) CPUs, oversubscribing a small machine,
  # so that jobs sized for a real cluster's nodes (a group of 8 one-thread jobs asks for 8) can start.
  cpus=$(( $(nproc) > ${TOHGS_SLURM_CPUS:-16} ? $(nproc) : ${TOHGS_SLURM_CPUS:-16} ))
  mem=$(awk '/MemTotal/ {printf "%d", $2 / 1024 * 0.9}' /proc/meminfo)
  mkdir -p "$DIR"/{etc,log,run,state,spool,mysql}
  cat > "$DIR/etc/slurm.conf" <<EOF
ClusterName=tohgs
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/run/slurmctld.pid
SlurmdPidFile=$DIR/run/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
# No cgroups in a container: track processes by their parent and bind nothing.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SlurmdParameters=config_overrides
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
JobAcctGatherType=jobacct_gather/none
AccountingStoreFlags=job_comment
JobCompType=jobcomp/none
# Keep finished jobs visible to squeue a while, and answer quickly.
MinJobAge=300
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=10
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  cat > "$DIR/etc/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdHost=localhost
SlurmUser=root
PidFile=$DIR/run/slurmdbd.pid
LogFile=$DIR/log/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$DB_PORT
StorageUser=root
StorageLoc=slurm_acct_db
EOF
  chmod 600 "$DIR/etc/slurmdbd.conf"
}

start_munge() {
  if pgrep -x munged >/dev/null; then return 0; fi
  mkdir -p /run/munge /var/log/munge /var/lib/munge
  chown munge:munge /run/munge /var/log/munge /var/lib/munge
  [ -s /etc/munge/munge.key ] || { mungekey --create --keyfile /etc/munge/munge.key; chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key; }
  runuser -u munge -- /usr/sbin/munged
  wait_for 20 munged sh -c 'munge -n | unmunge'
}

start_mariadb() {
  if [ ! -d "$DIR/mysql/mysql" ]; then
    mariadb-install-db --datadir="$DIR/mysql" --user=root --auth-root-authentication-method=normal \
      --skip-test-db > "$DIR/log/mariadb-install.log" 2>&1 || die "mariadb-install-db failed: $DIR/log/mariadb-install.log"
  fi
  /usr/sbin/mariadbd --datadir="$DIR/mysql" --user=root --bind-address=127.0.0.1 --port="$DB_PORT" \
    --socket="$DIR/run/mysqld.sock" --pid-file="$DIR/run/mariadbd.pid" --log-error="$DIR/log/mariadb.log" \
    --innodb-buffer-pool-size=64M > /dev/null 2>&1 &
  wait_for 60 mariadbd mariadb --protocol=tcp -h 127.0.0.1 -P "$DB_PORT" -u root -e 'select 1'
}

start() {
  need_root
  install
  [ -e "$DIR/run/slurmctld.pid" ] && kill -0 "$(cat "$DIR/run/slurmctld.pid")" 2>/dev/null && die "already running ($DIR)"
  write_configs
  start_munge
  start_mariadb
  /usr/sbin/slurmdbd
  wait_for 60 slurmdbd sacctmgr -i list cluster
  sacctmgr -i add cluster tohgs >/dev/null 2>&1 || true
  sacctmgr -i add account tohgs Cluster=tohgs Description=tests Organization=tohgs >/dev/null 2>&1 || true
  sacctmgr -i add user root Account=tohgs DefaultAccount=tohgs >/dev/null 2>&1 || true
  /usr/sbin/slurmctld
  wait_for 60 slurmctld scontrol ping
  /usr/sbin/slurmd
  wait_for 60 "the node" sh -c "sinfo -h -o %t | grep -qE '^(idle|mix|alloc)'"
  if [ ! -e /etc/slurm/slurm.conf ]; then
    mkdir -p /etc/slurm
    ln -s "$SLURM_CONF" /etc/slurm/slurm.conf
  elif [ "$(readlink -f /etc/slurm/slurm.conf)" != "$(readlink -f "$SLURM_CONF")" ]; then
    echo "local_slurm: warning: /etc/slurm/slurm.conf is another cluster's; srun inside jobs will use it" >&2
  fi
  echo "export SLURM_CONF=$SLURM_CONF"
}

stop() {
  local pid
  for daemon in slurmd slurmctld slurmdbd mariadbd; do
    if [ -e "$DIR/run/$daemon.pid" ]; then
      pid=$(cat "$DIR/run/$daemon.pid")
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 1 80); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
      kill -9 "$pid" 2>/dev/null || true
      rm -f "$DIR/run/$daemon.pid"
    fi
  done
  if [ -L /etc/slurm/slurm.conf ] && [ "$(readlink /etc/slurm/slurm.conf)" = "$SLURM_CONF" ]; then
    rm -f /etc/slurm/slurm.conf
  fi
}

case "${1:-}" in
  install) install ;;
  start) start ;;
  stop) stop ;;
  status) sinfo ;;
  *) die "usage: $0 install|start|stop|status   (state in \$TOHGS_SLURM_DIR, default /tmp/tohgs-slurm)" ;;
esac
