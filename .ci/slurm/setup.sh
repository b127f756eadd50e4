#!/usr/bin/env bash
# A real one-node Slurm cluster with accounting on this machine, from Debian's packages:
# what CI runs (`make slurm`) before the tests, so that tests/workflow/test_slurm.py can
# run the workflow through config/profiles/slurm. docs/slurm.md explains each piece.
#
#   .ci/slurm/setup.sh         install what is missing (root + apt-get), write the
#                              configuration, start what is not running, wait until the
#                              node is idle and sacct answers; quick on a running cluster
#   .ci/slurm/setup.sh stop    stop the Slurm daemons, MariaDB and munge
#
# Daemons: munged (authentication), mariadbd (the accounting database), slurmdbd (writes
# accounting to it; sacct and sacctmgr ask it), slurmctld (the controller), slurmd (the
# node). No systemd: each is started directly and found again by its pid file.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
CLUSTER=stringcast      # ClusterName, registered in accounting
ACCOUNT=stringcast      # the account jobs are charged to (root's default)
PARTITION=main          # the one partition (the default)
TIMEOUT=${SLURM_SETUP_TIMEOUT:-90}   # seconds to wait for each daemon
PACKAGES=(munge mariadb-server slurmdbd slurmctld slurmd slurm-client)
ETC=/etc/slurm

say() { echo "make slurm: $*"; }
die() { echo "make slurm: $*" >&2; exit 1; }

# the last lines of a log, on stderr (for the reason a daemon did not come up)
log_tail() {
    { echo "----- last lines of $1 -----"; tail -n 40 "$1" 2>/dev/null || echo "(no such log)"; \
      echo "-----"; } >&2
}

# running PIDFILE NAME: the process in PIDFILE is alive and is NAME
running() {
    local pid
    [ -s "$1" ] && pid=$(cat "$1" 2>/dev/null) && [ -n "$pid" ] &&
        [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$2" ]
}

# wait_until WHAT LOG COMMAND...: poll COMMAND (quietly) until it succeeds, at most TIMEOUT s
wait_until() {
    local what=$1 log=$2; shift 2
    local deadline=$((SECONDS + TIMEOUT))
    until "$@" >/dev/null 2>&1; do
        if [ "$SECONDS" -ge "$deadline" ]; then
            log_tail "$log"
            die "$what did not come up within ${TIMEOUT}s (waited for: $*); its log is $log"
        fi
        sleep 0.3
    done
}

# stop_daemon PIDFILE NAME: SIGTERM and wait for it to exit
stop_daemon() {
    running "$1" "$2" || return 0
    local pid deadline=$((SECONDS + TIMEOUT))
    pid=$(cat "$1")
    kill "$pid"
    while kill -0 "$pid" 2>/dev/null; do
        [ "$SECONDS" -lt "$deadline" ] || die "$2 (pid $pid) did not stop within ${TIMEOUT}s"
        sleep 0.2
    done
    say "stopped $2"
}

stop_all() {
    stop_daemon /run/slurmd.pid slurmd
    stop_daemon /run/slurmctld.pid slurmctld
    stop_daemon /run/slurmdbd.pid slurmdbd
    stop_daemon /run/mysqld/mysqld.pid mariadbd
    stop_daemon /run/munge/munged.pid munged
}

# ---------------------------------------------------------------- checks and packages
node_state() { sinfo -h -N -o %T 2>/dev/null | head -n 1; }
node_up() { case "$(node_state)" in idle*|mixed*|allocated*|completing*) return 0;; *) return 1;; esac; }
cluster_answers() { command -v sinfo >/dev/null && node_up && sacct -n -X -S now >/dev/null 2>&1; }

if [ "${1:-}" = stop ]; then
    [ "$(id -u)" = 0 ] || die "stopping the daemons needs root"
    stop_all
    exit 0
fi
[ $# -eq 0 ] || die "usage: $0 [stop]"

if [ "$(id -u)" != 0 ]; then
    if cluster_answers; then
        say "a Slurm cluster answers (node $(node_state)); nothing to do without root"
        exit 0
    fi
    die "needs root to install and start a one-node Slurm (Debian: apt-get install ${PACKAGES[*]}); see docs/slurm.md"
fi

t0=$SECONDS
missing=()
for cmd in munged mariadbd slurmdbd slurmctld slurmd sbatch sacct sacctmgr; do
    command -v "$cmd" >/dev/null || missing+=("$cmd")
done
if [ ${#missing[@]} -gt 0 ]; then
    command -v apt-get >/dev/null || die "missing ${missing[*]} and no apt-get: install ${PACKAGES[*]} yourself"
    say "installing ${PACKAGES[*]} (missing: ${missing[*]})"
    # --no-install-recommends: 27 packages instead of 77 with the recommended ones, which none of this needs
    apt_install() { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${PACKAGES[@]}" >/tmp/slurm-apt.log 2>&1; }
    if ! apt_install; then
        say "apt-get install failed with the current package lists; updating them and trying again"
        apt-get update -qq || die "apt-get update failed"
        apt_install || { log_tail /tmp/slurm-apt.log; die "apt-get install ${PACKAGES[*]} failed"; }
    fi
    say "installed in $((SECONDS - t0))s"
fi
getent passwd slurm >/dev/null || die "the system user slurm is missing (Debian's slurm packages create it)"

# ---------------------------------------------------------------- configuration
# install_file SRC DEST MODE OWNER: copy when different; returns 0 when DEST changed
install_file() {
    local changed=1
    cmp -s "$1" "$2" || { cp "$1" "$2"; changed=0; }
    chmod "$3" "$2"
    chown "$4" "$2"
    return $changed
}

host=$(hostname -s)
# the node's real hardware, e.g. "NodeName=vm CPUs=2 Boards=1 ... RealMemory=24105"
node=$(slurmd -C | head -n 1)
case "$node" in NodeName=*RealMemory=*) ;; *) die "slurmd -C gave no node line: '$node'";; esac
mkdir -p "$ETC" /var/log/slurm /var/lib/slurm/slurmctld /var/lib/slurm/slurmd
chown slurm:slurm /var/log/slurm /var/lib/slurm/slurmctld
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
sed -e "s|@CLUSTER@|$CLUSTER|; s|@HOST@|$host|; s|@PARTITION@|$PARTITION|; s|@NODE@|$node|" \
    "$HERE/slurm.conf.in" >"$tmp"
slurm_conf_changed=false; dbd_conf_changed=false
install_file "$tmp" "$ETC/slurm.conf" 644 root:root && slurm_conf_changed=true
install_file "$HERE/slurmdbd.conf" "$ETC/slurmdbd.conf" 600 slurm:slurm && dbd_conf_changed=true

# ---------------------------------------------------------------- munge
if ! running /run/munge/munged.pid munged; then
    mkdir -p /run/munge && chown munge:munge /run/munge && chmod 755 /run/munge
    [ -s /etc/munge/munge.key ] || { mungekey --create --keyfile=/etc/munge/munge.key && chown munge:munge /etc/munge/munge.key; }
    runuser -u munge -- munged || { log_tail /var/log/munge/munged.log; die "munged did not start"; }
fi
wait_until munged /var/log/munge/munged.log bash -c 'munge -n | unmunge'

# ---------------------------------------------------------------- MariaDB
if ! running /run/mysqld/mysqld.pid mariadbd; then
    mkdir -p /run/mysqld /var/log/mysql && chown mysql:mysql /run/mysqld /var/log/mysql
    setsid -f mariadbd --user=mysql --log-error=/var/log/mysql/error.log </dev/null >/dev/null 2>&1
fi
wait_until MariaDB /var/log/mysql/error.log mariadb-admin ping
# the database user slurm logs in as the system user slurm (unix_socket): no password
mariadb <<SQL || die "could not create MariaDB's user slurm and its database"
CREATE DATABASE IF NOT EXISTS slurm_acct_db;
CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED VIA unix_socket;
GRANT ALL ON slurm_acct_db.* TO 'slurm'@'localhost';
SQL

# ---------------------------------------------------------------- slurmdbd, accounts
if $dbd_conf_changed; then stop_daemon /run/slurmdbd.pid slurmdbd; fi
if ! running /run/slurmdbd.pid slurmdbd; then
    slurmdbd || { log_tail /var/log/slurm/slurmdbd.log; die "slurmdbd did not start"; }
fi
wait_until slurmdbd /var/log/slurm/slurmdbd.log sacctmgr -n list cluster

# exists KIND NAME: sacctmgr lists it
exists() { [ -n "$(sacctmgr -n -P list "$1" "$2" format="$1" 2>/dev/null)" ]; }
exists cluster "$CLUSTER" || sacctmgr -i add cluster "$CLUSTER" >/dev/null || die "sacctmgr could not add cluster $CLUSTER"
exists account "$ACCOUNT" || sacctmgr -i add account "$ACCOUNT" cluster="$CLUSTER" \
    Description="stringcast tests" Organization=stringcast >/dev/null || die "sacctmgr could not add account $ACCOUNT"
for user in root ${SUDO_USER:-}; do
    [ -n "$(sacctmgr -n -P list assoc user="$user" account="$ACCOUNT" cluster="$CLUSTER" format=user)" ] ||
        sacctmgr -i add user "$user" account="$ACCOUNT" DefaultAccount="$ACCOUNT" cluster="$CLUSTER" >/dev/null ||
        die "sacctmgr could not add user $user to account $ACCOUNT"
done

# ---------------------------------------------------------------- slurmctld, slurmd
if $slurm_conf_changed; then
    stop_daemon /run/slurmd.pid slurmd
    stop_daemon /run/slurmctld.pid slurmctld
fi
if ! running /run/slurmctld.pid slurmctld; then
    slurmctld || { log_tail /var/log/slurm/slurmctld.log; die "slurmctld did not start"; }
fi
wait_until slurmctld /var/log/slurm/slurmctld.log bash -c 'scontrol ping | grep -q "is UP"'
if ! running /run/slurmd.pid slurmd; then
    slurmd || { log_tail /var/log/slurm/slurmd.log; die "slurmd did not start"; }
fi
# a node left down or drained by an earlier run is put back into service
case "$(node_state)" in down*|drain*|fail*) scontrol update nodename="$host" state=resume || true;; esac
wait_until "the node $host (idle in sinfo)" /var/log/slurm/slurmd.log node_up
wait_until "accounting (sacct)" /var/log/slurm/slurmdbd.log sacct -n -X -S now

say "cluster $CLUSTER up in $((SECONDS - t0))s: node $host $(node_state) ($(sinfo -h -N -o '%c CPUs, %m MB')), partition $PARTITION, account $ACCOUNT"
