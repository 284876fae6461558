#!/usr/bin/env bash
# A one-node SLURM cluster on localhost, with accounting, for tests/pipeline/cluster (`make cluster-test`).
#
#   slurm_cluster.sh install     Debian's slurm-wlm, slurmdbd, munge and mariadb-server (as root); the
#                                packages it added are listed in $STATE_ROOT/installed.txt for `purge`
#   slurm_cluster.sh up          munged, MariaDB, slurmdbd, slurmctld and slurmd, everything under $STATE;
#                                returns once `sinfo` reports the node idle
#   slurm_cluster.sh down        stops every daemon that `up` started and removes $STATE
#   slurm_cluster.sh purge       removes the packages, users and folders that `install` added
#   slurm_cluster.sh dbd-stop|dbd-start   slurmdbd alone (the tests' accounting fault)
#   slurm_cluster.sh env         the line to source: export SLURM_CONF=...
#
# The daemons run as root from configs under $STATE, on their own ports, so nothing under /etc is
# touched and no service is started or enabled at boot: a policy-rc.d denies the packages' start
# scripts while they install, and their boot links (rc?.d, systemd wants) are removed right after.

set -euo pipefail

STATE_ROOT=${SLURM_CLUSTER_ROOT:-/var/tmp/penitentes-cluster}
STATE=$STATE_ROOT/state
PACKAGES=(slurm-wlm slurmctld slurmd slurm-client slurmdbd munge mariadb-server)
NODE=localhost
CLUSTER=penitentes
CTLD_PORT=16817
SLURMD_PORT=16818
DBD_PORT=16819
DB_PORT=13306
DEFAULT_CONF=/etc/slurm/slurm.conf
MUNGE_SOCKET=/run/munge/munge.socket.2
DAEMONS=(slurmd slurmctld slurmdbd mariadbd munged) # stop order

log() { echo "cluster: $*" >&2; }
die() {
	echo "cluster: error: $*" >&2
	exit 1
}

need_root() { [ "$(id -u)" = 0 ] || die "run as root (it installs Debian packages and starts daemons)"; }

installed() { [ "$(dpkg-query -W -f='${db:Status-Abbrev}' "$1" 2>/dev/null)" = "ii " ]; }

# ---------------------------------------------------------------- packages

# The boot links of every service that the packages install added ship (rsync's too); packages that
# were there before keep theirs.
disable_boot_links() {
	local packages=() service
	if [ -s "$STATE_ROOT/installed.txt" ]; then mapfile -t packages <"$STATE_ROOT/installed.txt"; else return 0; fi
	for service in $(dpkg -L "${packages[@]}" 2>/dev/null | sed -n 's#^/etc/init.d/\([^/]*\)$#\1#p; s#^/lib/systemd/system/\([^/]*\)\.service$#\1#p' | sort -u); do
		if [ -e "/etc/init.d/$service" ]; then update-rc.d -f "$service" remove >/dev/null 2>&1 || true; fi
		rm -f /etc/systemd/system/*.wants/"$service".service
		rm -f /var/lib/systemd/deb-systemd-helper-enabled/"$service".service.dsh-also \
			/var/lib/systemd/deb-systemd-helper-enabled/*.wants/"$service".service
	done
}

cmd_install() {
	need_root
	mkdir -p "$STATE_ROOT"
	local missing=()
	for package in "${PACKAGES[@]}"; do installed "$package" || missing+=("$package"); done
	if [ ${#missing[@]} -gt 0 ]; then
		log "installing ${missing[*]}"
		dpkg-query -W -f='${Package}\n' | sort >"$STATE_ROOT/packages-before.txt"
		cut -d: -f1 /etc/passwd | sort >"$STATE_ROOT/users-before.txt"
		for path in /etc/munge /etc/slurm /etc/mysql /var/lib/mysql /var/lib/munge /var/log/munge /var/log/mysql \
			/var/lib/slurm /var/log/slurm; do
			[ -e "$path" ] && echo "$path"
		done >"$STATE_ROOT/paths-before.txt" || true
		# Deny the packages' start scripts while they install (Docker images ship such a file already).
		local own_policy=0
		if [ ! -e /usr/sbin/policy-rc.d ]; then
			printf '#!/bin/sh\nexit 101\n' >/usr/sbin/policy-rc.d
			chmod 755 /usr/sbin/policy-rc.d
			own_policy=1
		fi
		export DEBIAN_FRONTEND=noninteractive
		local status=0
		{ apt-get update -qq && apt-get install -y -qq --no-install-recommends "${missing[@]}"; } \
			>"$STATE_ROOT/apt.log" 2>&1 || status=$?
		[ $own_policy = 1 ] && rm -f /usr/sbin/policy-rc.d
		[ $status = 0 ] || {
			tail -30 "$STATE_ROOT/apt.log"
			die "apt-get failed (log: $STATE_ROOT/apt.log)"
		}
		dpkg-query -W -f='${Package}\n' | sort | comm -13 "$STATE_ROOT/packages-before.txt" - \
			>>"$STATE_ROOT/installed.txt"
	fi
	disable_boot_links
}

cmd_purge() {
	need_root
	cmd_down
	if [ ! -s "$STATE_ROOT/installed.txt" ]; then
		log "nothing to purge: the packages were installed before this script ran"
		rm -rf "$STATE_ROOT"
		return
	fi
	log "purging $(wc -l <"$STATE_ROOT/installed.txt") packages that install added"
	local own_policy=0
	if [ ! -e /usr/sbin/policy-rc.d ]; then
		printf '#!/bin/sh\nexit 101\n' >/usr/sbin/policy-rc.d
		chmod 755 /usr/sbin/policy-rc.d
		own_policy=1
	fi
	# shellcheck disable=SC2046
	DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq $(cat "$STATE_ROOT/installed.txt") \
		>"$STATE_ROOT/purge.log" 2>&1 || {
		tail -30 "$STATE_ROOT/purge.log"
		die "apt-get purge failed"
	}
	[ $own_policy = 1 ] && rm -f /usr/sbin/policy-rc.d
	for path in /etc/munge /etc/slurm /etc/mysql /var/lib/mysql /var/lib/munge /var/log/munge /var/log/mysql \
		/var/lib/slurm /var/log/slurm /run/munge /run/mysqld; do
		grep -qx "$path" "$STATE_ROOT/paths-before.txt" 2>/dev/null || rm -rf "$path"
	done
	for user in $(cut -d: -f1 /etc/passwd | sort | comm -13 "$STATE_ROOT/users-before.txt" -); do
		userdel "$user" 2>/dev/null || true
		getent group "$user" >/dev/null && groupdel "$user" 2>/dev/null || true
	done
	rm -rf "$STATE_ROOT"
}

# ---------------------------------------------------------------- daemons

write_configs() {
	local cpus memory
	cpus=$(nproc)
	memory=$(slurmd -C | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
	cat >"$STATE/slurm.conf" <<EOF
# One node on localhost, written by tests/pipeline/cluster/slurm_cluster.sh up.
ClusterName=$CLUSTER
SlurmctldHost=$(hostname -s)(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/slurmd
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
SlurmdTimeout=30
MinJobAge=300
MpiDefault=none
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=$DBD_PORT
AccountingStoreFlags=job_comment
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
	cat >"$STATE/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdHost=localhost
DbdPort=$DBD_PORT
SlurmUser=root
PidFile=$STATE/slurmdbd.pid
LogFile=$STATE/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$DB_PORT
StorageUser=slurm
StoragePass=slurm
StorageLoc=slurm_acct_db
EOF
	chmod 600 "$STATE/slurmdbd.conf"
}

wait_for() { # SECONDS WHAT COMMAND...
	local seconds=$1 what=$2
	shift 2
	for _ in $(seq $((seconds * 2))); do
		"$@" >/dev/null 2>&1 && return 0
		sleep 0.5
	done
	die "$what did not come up within $seconds s (logs under $STATE)"
}

start_dbd() {
	SLURM_CONF=$STATE/slurm.conf slurmdbd
	wait_for 30 slurmdbd sacctmgr -n list cluster
}

cmd_up() {
	need_root
	for binary in munged mariadbd slurmdbd slurmctld slurmd sinfo; do
		command -v "$binary" >/dev/null || die "$binary is missing: run '$0 install' first"
	done
	[ ! -e "$STATE/slurm.conf" ] || die "a cluster is already up under $STATE: run '$0 down' first"
	mkdir -p "$STATE/ctld" "$STATE/slurmd" "$STATE/mysql"
	chmod 700 "$STATE_ROOT" "$STATE"
	export SLURM_CONF=$STATE/slurm.conf
	write_configs
	# The plugin's job step drops SLURM_CONF before its srun, which then reads the default path.
	[ ! -e "$DEFAULT_CONF" ] || die "$DEFAULT_CONF exists: this machine has a SLURM cluster already"
	mkdir -p "${DEFAULT_CONF%/*}"
	ln -s "$SLURM_CONF" "$DEFAULT_CONF"

	log "munged"
	# Client commands (sacctmgr) reach munged at its default socket only, so it listens there.
	[ -e "$MUNGE_SOCKET" ] && die "$MUNGE_SOCKET exists: is another munged running?"
	if [ ! -d "${MUNGE_SOCKET%/*}" ]; then
		mkdir -p "${MUNGE_SOCKET%/*}"
		touch "$STATE/made-munge-run-dir"
	fi
	dd if=/dev/urandom of="$STATE/munge.key" bs=1024 count=1 status=none
	chmod 400 "$STATE/munge.key"
	munged --force --key-file="$STATE/munge.key" --socket="$MUNGE_SOCKET" --pid-file="$STATE/munged.pid" \
		--log-file="$STATE/munged.log" --seed-file="$STATE/munged.seed"
	wait_for 10 munged munge -n

	log "MariaDB"
	mariadb-install-db --no-defaults --user=root --datadir="$STATE/mysql" --auth-root-authentication-method=socket \
		>"$STATE/mariadb-install.log" 2>&1 || die "mariadb-install-db failed (log: $STATE/mariadb-install.log)"
	mariadbd --no-defaults --user=root --datadir="$STATE/mysql" --socket="$STATE/mysqld.sock" \
		--pid-file="$STATE/mariadbd.pid" --port=$DB_PORT --bind-address=127.0.0.1 --skip-name-resolve \
		--log-error="$STATE/mariadbd.log" --innodb-buffer-pool-size=64M >/dev/null 2>&1 &
	wait_for 60 MariaDB mariadb --no-defaults --socket="$STATE/mysqld.sock" -u root -e "SELECT 1"
	mariadb --no-defaults --socket="$STATE/mysqld.sock" -u root -e \
		"CREATE USER 'slurm'@'127.0.0.1' IDENTIFIED BY 'slurm'; GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';"

	log "slurmdbd"
	start_dbd
	sacctmgr -i add cluster "$CLUSTER" >/dev/null

	log "slurmctld and slurmd"
	slurmctld
	wait_for 30 slurmctld scontrol ping
	slurmd -N "$NODE"
	wait_for 60 "the node (idle in sinfo)" sh -c "sinfo -h -N -n $NODE -o %t | grep -qx idle"
	log "up: $(sinfo -h -N -o '%N %c CPUs %m MB %t') (export SLURM_CONF=$SLURM_CONF)"
}

stop_daemon() { # NAME: TERM by its pid file, KILL after 15 s; never by name
	local pidfile=$STATE/$1.pid pid
	[ -s "$pidfile" ] || return 0
	pid=$(cat "$pidfile")
	kill -0 "$pid" 2>/dev/null || return 0
	kill "$pid" 2>/dev/null || true
	for _ in $(seq 30); do
		kill -0 "$pid" 2>/dev/null || return 0
		sleep 0.5
	done
	log "$1 ($pid) did not stop on TERM; killing it"
	kill -9 "$pid" 2>/dev/null || true
}

cmd_down() {
	[ -d "$STATE" ] || return 0
	export SLURM_CONF=$STATE/slurm.conf
	# Jobs first: slurmd kills their processes when told to cancel them.
	if [ -s "$STATE/slurmctld.pid" ] && kill -0 "$(cat "$STATE/slurmctld.pid")" 2>/dev/null; then
		scancel --full --cluster="$CLUSTER" --user=root >/dev/null 2>&1 || true
		sleep 1
	fi
	for daemon in "${DAEMONS[@]}"; do stop_daemon "$daemon"; done
	if [ "$(readlink "$DEFAULT_CONF")" = "$STATE/slurm.conf" ]; then rm -f "$DEFAULT_CONF"; fi
	if [ -e "$STATE/made-munge-run-dir" ]; then rm -rf "${MUNGE_SOCKET%/*}"; fi
	rm -rf "$STATE"
	log "down"
}

case "${1:-}" in
install) cmd_install ;;
up) cmd_up ;;
down) cmd_down ;;
purge) cmd_purge ;;
dbd-stop) stop_daemon slurmdbd ;;
dbd-start) SLURM_CONF=$STATE/slurm.conf start_dbd ;;
env) echo "export SLURM_CONF=$STATE/slurm.conf" ;;
*) die "usage: $0 install|up|down|purge|dbd-stop|dbd-start|env" ;;
esac
