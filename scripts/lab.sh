#!/usr/bin/env bash
# A lab in a box: N "PCs" on this machine, each a Linux network namespace
# with its own address on a private subnet and its own host name (a UTS
# namespace), joined by a switch (a bridge in one more namespace), each
# running an sshd; then one MPI job across them, launched by mpirun over ssh
# and talking TCP only (no shared memory crosses a "PC"), optionally over
# links shaped to 100 Mbit/s or 10 Mbit/s (tc's tbf on both ends of each
# PC's cable). Everything it makes is removed at the end, also on interrupt.
#
#   bash scripts/lab.sh [--hosts N] [--np R] [--link 100mbit|10mbit|none]
#                       [--fault kill:K@S | --fault down:K@S]
#                       [--name PREFIX] [--subnet A.B.C] SCENE [rigidsim options]
#   bash scripts/lab.sh --check     # can a lab be made here? (one line; exit 0 or 1)
#
#   --hosts N     PCs (default 2), named pc1 … pcN, at A.B.C.1 … A.B.C.N.
#   --np R        ranks (default N), one per PC in turn (rank r on PC r mod N + 1).
#   --link RATE   each PC's link: 100mbit, 10mbit, any tc rate, or none (default).
#                 The thesis had shared hubs; these are switched, full-duplex links.
#   --fault kill:K@S   S seconds into the run, kill every process of the job on pcK.
#   --fault down:K@S   S seconds into the run, take pcK's link down (a pulled cable).
#   --name PREFIX      namespaces PREFIX-sw, PREFIX-pc1 … (default rslab).
#   --subnet A.B.C     the lab's /24 (default 10.250.0); it exists only inside the lab.
#
# Runs target/release/rigidsim (RIGIDSIM_BIN for another build). Needs root
# (network namespaces), iproute2, openssh-server and Open MPI
# (scripts/setup.sh installs them). Exit status: mpirun's.
set -euo pipefail
cd "$(dirname "$0")/.."

hosts=2 np="" link=none fault="" name=rslab subnet=10.250.0 check=0
while [ $# -gt 0 ]; do
  case $1 in
    --hosts) hosts=$2; shift 2 ;;
    --np) np=$2; shift 2 ;;
    --link) link=$2; shift 2 ;;
    --fault) fault=$2; shift 2 ;;
    --name) name=$2; shift 2 ;;
    --subnet) subnet=$2; shift 2 ;;
    --check) check=1; shift ;;
    --) shift; break ;;
    -*) echo "lab: unknown option $1 (see the top of scripts/lab.sh)" >&2; exit 2 ;;
    *) break ;;
  esac
done
np=${np:-$hosts}
say() { echo "lab: $*" >&2; }

# --- What this machine allows ------------------------------------------------
# One line saying why a lab cannot be made here, or nothing.
cannot() {
  [ "$(id -u)" -eq 0 ] || { echo "needs root for network namespaces"; return; }
  local t
  for t in ip tc unshare ssh ssh-keygen mpirun /usr/sbin/sshd; do
    command -v "$t" >/dev/null 2>&1 || { echo "$t is missing (run scripts/setup.sh)"; return; }
  done
  local probe="${name}-probe$$" err
  if ! err=$(ip netns add "$probe" 2>&1); then
    echo "cannot create a network namespace: ${err//$'\n'/ }"; return
  fi
  err=$(ip -n "$probe" link add vtest0 type veth peer name vtest1 2>&1 &&
        ip -n "$probe" link add brtest type bridge 2>&1 &&
        ip -n "$probe" link set vtest0 up 2>&1 &&
        tc -n "$probe" qdisc add dev vtest0 root tbf rate 10mbit burst 3000 latency 50ms 2>&1 &&
        ip netns exec "$probe" unshare --uts sh -c 'hostname labprobe' 2>&1) || err="${err:-failed}"
  ip netns del "$probe" 2>/dev/null || true
  [ -z "$err" ] || echo "cannot build a lab's network here: ${err//$'\n'/ }"
}
if [ "$check" -eq 1 ]; then
  why=$(cannot)
  [ -z "$why" ] && { echo "ok"; exit 0; }
  echo "$why"; exit 1
fi

[ $# -ge 1 ] || { echo "lab: a scene is required (see the top of scripts/lab.sh)" >&2; exit 2; }
case $hosts in ''|*[!0-9]*) say "--hosts must be a number"; exit 2 ;; esac
case $np in ''|*[!0-9]*) say "--np must be a number"; exit 2 ;; esac
[ "$hosts" -ge 1 ] && [ "$hosts" -le 200 ] || { say "--hosts must be 1 … 200"; exit 2; }
[ "$np" -ge 1 ] || { say "--np must be at least 1"; exit 2; }
[[ $subnet =~ ^[0-9]{1,3}\.[0-9]{1,3}\.[0-9]{1,3}$ ]] || { say "--subnet must be A.B.C"; exit 2; }
[[ $name =~ ^[a-z][a-z0-9]{0,9}$ ]] || { say "--name must be 1-10 lower-case letters and digits"; exit 2; }
case $link in
  none) ;;
  *[0-9]kbit|*[0-9]mbit|*[0-9]gbit) ;;
  *) say "--link must be none or a tc rate such as 100mbit or 10mbit"; exit 2 ;;
esac
fault_kind="" fault_pc="" fault_at=""
if [ -n "$fault" ]; then
  [[ $fault =~ ^(kill|down):([0-9]+)@([0-9.]+)$ ]] || { say "--fault must be kill:K@S or down:K@S"; exit 2; }
  fault_kind=${BASH_REMATCH[1]} fault_pc=${BASH_REMATCH[2]} fault_at=${BASH_REMATCH[3]}
  [ "$fault_pc" -ge 1 ] && [ "$fault_pc" -le "$hosts" ] || { say "--fault: no pc$fault_pc"; exit 2; }
fi
why=$(cannot)
[ -z "$why" ] || { say "$why"; exit 1; }

bin=$(realpath "${RIGIDSIM_BIN:-${CARGO_TARGET_DIR:-target}/release/rigidsim}")
[ -x "$bin" ] || { say "$bin not built (cargo build --release)"; exit 1; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 NODEVICE_SELECT=1

sw="${name}-sw"
ns() { echo "${name}-pc$1"; }
addr() { echo "$subnet.$1"; }
ranks_on() { # PC number: the ranks --map-by node put there
  local r out=""
  for r in $(seq 0 $((np - 1))); do [ $((r % hosts + 1)) -ne "$1" ] || out+="${out:+, }$r"; done
  echo "${out:-none}"
}
# Refuse to start over anything of the same names (another lab, or not ours).
for n in "$sw" $(for i in $(seq 1 "$hosts"); do ns "$i"; done); do
  if ip netns list | awk '{print $1}' | grep -qx "$n"; then
    say "network namespace $n exists already (another lab running, or left over?); refusing to start"
    exit 1
  fi
done

# --- Teardown: everything made below, by name and by process id --------------
dir="" made_ns=() pids=() mpirun_pid="" fault_pid="" made_run_sshd=0 made_run_netns=0 cleaned=0
[ -d /run/netns ] || made_run_netns=1
cleanup() {
  [ "$cleaned" -eq 0 ] || return 0
  cleaned=1
  local p n
  for p in $fault_pid $mpirun_pid "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  # Whatever else runs in a lab PC was started by this lab (orted, ranks,
  # ssh logins): end it by id before its namespace goes.
  for n in "${made_ns[@]}"; do
    for p in $(ip netns pids "$n" 2>/dev/null); do kill -9 "$p" 2>/dev/null || true; done
  done
  for p in $fault_pid $mpirun_pid "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  for n in "${made_ns[@]}"; do ip netns del "$n" 2>/dev/null || true; done
  [ -z "$dir" ] || rm -rf "$dir"
  # sshd's privilege-separation folder, if this lab made it and no other
  # sshd (another lab's) still needs it.
  if [ "$made_run_sshd" -eq 1 ] && ! pgrep -x sshd >/dev/null; then rmdir /run/sshd 2>/dev/null || true; fi
  [ "$made_run_netns" -eq 0 ] || rmdir /run/netns 2>/dev/null || true
}
trap cleanup EXIT
trap 'say "interrupted; removing the lab"; cleanup; exit 130' INT TERM HUP

dir=$(mktemp -d /tmp/rigidsim-lab.XXXXXX)
chmod 700 "$dir"
mkdir "$dir/tmp"

# --- The network: a switch and N PCs with a cable each -----------------------
ip netns add "$sw"; made_ns+=("$sw")
ip -n "$sw" link set lo up
ip -n "$sw" link add br0 type bridge
ip -n "$sw" link set br0 up
shape() { # namespace, device: tbf at the link's rate on that end of the cable
  [ "$link" = none ] && return 0
  # A bucket of 1 ms at the rate (at least two frames) keeps bursts short,
  # as on a real 10/100 link; packets wait at most 50 ms before dropping.
  local bits=${link%bit} mult=1
  case $bits in *k) mult=1000 ;; *m) mult=1000000 ;; *g) mult=1000000000 ;; esac
  local rate=$(( ${bits%[kmg]} * mult / 8 ))
  local burst=$(( rate / 1000 > 3028 ? rate / 1000 : 3028 ))
  tc -n "$1" qdisc add dev "$2" root tbf rate "$link" burst "$burst" latency 50ms
}
for i in $(seq 1 "$hosts"); do
  n=$(ns "$i")
  ip netns add "$n"; made_ns+=("$n")
  ip -n "$n" link set lo up
  ip -n "$sw" link add "pc$i" type veth peer name eth0 netns "$n"
  ip -n "$sw" link set "pc$i" master br0 up
  ip -n "$n" addr add "$(addr "$i")/24" dev eth0
  ip -n "$n" link set eth0 up
  shape "$sw" "pc$i"   # into the PC
  shape "$n" eth0      # out of the PC
done

# --- ssh: a key made for this lab, root login by that key only ---------------
ssh-keygen -q -t ed25519 -N '' -C rigidsim-lab -f "$dir/id"
ssh-keygen -q -t ed25519 -N '' -C rigidsim-lab-host -f "$dir/host_key"
echo "from=\"$subnet.0/24\" $(cat "$dir/id.pub")" >"$dir/authorized_keys"
: >"$dir/known_hosts"
for i in $(seq 1 "$hosts"); do echo "$(addr "$i") $(cat "$dir/host_key.pub")" >>"$dir/known_hosts"; done
cat >"$dir/ssh_config" <<EOF
Host *
  User root
  IdentityFile $dir/id
  IdentitiesOnly yes
  UserKnownHostsFile $dir/known_hosts
  StrictHostKeyChecking yes
  BatchMode yes
  LogLevel ERROR
  ConnectTimeout 5
  ServerAliveInterval 2
  ServerAliveCountMax 3
EOF
if [ ! -d /run/sshd ]; then mkdir -p /run/sshd; chmod 755 /run/sshd; made_run_sshd=1; fi
for i in $(seq 1 "$hosts"); do
  cat >"$dir/sshd_pc$i.conf" <<EOF
ListenAddress $(addr "$i"):22
HostKey $dir/host_key
AuthorizedKeysFile $dir/authorized_keys
PermitRootLogin prohibit-password
PubkeyAuthentication yes
PasswordAuthentication no
KbdInteractiveAuthentication no
UsePAM no
StrictModes no
X11Forwarding no
AllowTcpForwarding no
PidFile none
AcceptEnv OMPI_* NODEVICE_SELECT
EOF
  # The PC's own host name: a UTS namespace for its sshd and every login.
  ip netns exec "$(ns "$i")" unshare --uts sh -c \
    "hostname pc$i && exec /usr/sbin/sshd -D -e -f $dir/sshd_pc$i.conf" 2>>"$dir/sshd_pc$i.log" &
  pids+=($!)
done
# Every sshd answers before the job starts.
for i in $(seq 1 "$hosts"); do
  ok=0
  for _ in $(seq 1 50); do
    if ip netns exec "$(ns 1)" ssh -F "$dir/ssh_config" "$(addr "$i")" true 2>/dev/null; then ok=1; break; fi
    sleep 0.1
  done
  [ "$ok" -eq 1 ] || { say "sshd on pc$i does not answer: $(tail -2 "$dir/sshd_pc$i.log" | tr '\n' ' ')"; exit 1; }
done

: >"$dir/hostfile"
for i in $(seq 1 "$hosts"); do
  echo "$(addr "$i") slots=$(( (np + hosts - i) / hosts ))" >>"$dir/hostfile"
done
say "$hosts PCs pc1 … pc$hosts on $subnet.0/24, links: $link$([ "$link" = none ] || echo ' (tbf, switched full duplex)'); $np ranks over ssh and TCP"

# --- The job: launched from pc1, TCP on the lab subnet only ------------------
job_start=$(date +%s.%N)
ip netns exec "$(ns 1)" unshare --uts sh -c 'hostname pc1 && exec "$@"' sh \
  mpirun --hostfile "$dir/hostfile" -np "$np" --map-by node \
    --mca plm_rsh_agent "ssh -F $dir/ssh_config" --mca plm_rsh_no_tree_spawn 1 \
    --mca pml ob1 --mca btl tcp,self \
    --mca btl_tcp_if_include "$subnet.0/24" --mca oob_tcp_if_include "$subnet.0/24" \
    --mca orte_tmpdir_base "$dir/tmp" \
    --mca oob_tcp_keepalive_time 2 --mca oob_tcp_keepalive_intvl 1 --mca oob_tcp_keepalive_probes 3 \
    -x OMPI_ALLOW_RUN_AS_ROOT -x OMPI_ALLOW_RUN_AS_ROOT_CONFIRM -x NODEVICE_SELECT \
    --wdir "$PWD" "$bin" "$@" &
mpirun_pid=$!

if [ -n "$fault_kind" ]; then
  (
    sleep "$fault_at"
    if [ "$fault_kind" = kill ]; then
      sshd_pid=${pids[$((fault_pc - 1))]}
      victims=$(ip netns pids "$(ns "$fault_pc")" | grep -vx "$sshd_pid" | tr '\n' ' ')
      echo "lab: fault: killing pc$fault_pc's processes ($victims), rank(s) $(ranks_on "$fault_pc")" >&2
      # shellcheck disable=SC2086
      kill -9 $victims 2>/dev/null || true
    else
      echo "lab: fault: pc$fault_pc's link goes down (rank(s) $(ranks_on "$fault_pc"))" >&2
      ip -n "$sw" link set "pc$fault_pc" down
    fi
    date +%s.%N >"$dir/fault_at"
  ) &
  fault_pid=$!
fi

rc=0
wait "$mpirun_pid" || rc=$?
mpirun_pid=""
if [ "$rc" -ne 0 ]; then
  for i in $(seq 1 "$hosts"); do say "pc$i ($(addr "$i")) ran rank(s) $(ranks_on "$i")"; done
fi
if [ -s "$dir/fault_at" ]; then
  say "the job ended $(awk -v a="$(cat "$dir/fault_at")" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }') s after the fault, exit status $rc"
elif [ -n "$fault_kind" ]; then
  say "the job ended before the fault (exit status $rc)"
fi
say "job took $(awk -v a="$job_start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }') s; removing the lab"
exit "$rc"
