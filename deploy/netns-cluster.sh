#!/usr/bin/env bash
# A cluster of N "hosts" on this machine, for trying and testing multi-host jobs: each host is a
# network namespace NAME-hI with one interface eth0 at 10.231.0.(I+1)/24, all plugged into a
# bridge inside a namespace of their own (NAME-sw); nothing touches the machine's own network.
# Needs root (CAP_NET_ADMIN) and iproute2.
#   netns-cluster.sh up NAME N     create the hosts, print an Open MPI hostfile on stdout
#   netns-cluster.sh down NAME     remove them
# Launch across them from host 0 with deploy/netns-rsh.sh as mpirun's remote shell:
#   netns-cluster.sh up demo 3 > hosts
#   RAYSTACK_NETNS=demo ip netns exec demo-h0 mpirun --allow-run-as-root --hostfile hosts -np 3 \
#     --mca plm_rsh_agent deploy/netns-rsh.sh --mca btl tcp,self \
#     --mca btl_tcp_if_include 10.231.0.0/24 --mca oob_tcp_if_include 10.231.0.0/24 raystack render ...
set -euo pipefail
usage() { sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 2 ] || usage
cmd="$1"; name="$2"
case "$cmd" in
  up)
    [ $# -eq 3 ] || usage
    n="$3"
    if [ "$n" -lt 1 ] || [ "$n" -gt 200 ]; then echo "netns-cluster: N must be 1..200" >&2; exit 2; fi
    # A cluster of that name already up is left as it is (the clean-up below of a failed `up`
    # removed it: found by an operator who ran `up` twice).
    namespaces="$(ip netns list | awk '{print $1}')"  # not piped into grep -q: SIGPIPE under pipefail
    if grep -qE "^$name-(sw|h[0-9]+)$" <<<"$namespaces"; then
      echo "netns-cluster: a cluster named $name is up already (netns-cluster.sh down $name first)" >&2
      exit 1
    fi
    trap '"$0" down "$name" 2>/dev/null' ERR
    ip netns add "$name-sw"
    ip -n "$name-sw" link add br0 type bridge
    ip -n "$name-sw" link set br0 up
    for ((i = 0; i < n; i++)); do
      host="$name-h$i"
      ip netns add "$host"
      ip link add eth0 netns "$host" type veth peer name "p$i" netns "$name-sw"
      ip -n "$name-sw" link set "p$i" master br0
      ip -n "$name-sw" link set "p$i" up
      ip -n "$host" addr add "10.231.0.$((i + 1))/24" dev eth0
      ip -n "$host" link set eth0 up
      ip -n "$host" link set lo up
      echo "10.231.0.$((i + 1)) slots=1"
    done
    ;;
  down)
    for ns in $(ip netns list | awk '{print $1}' | grep -E "^$name-(sw|h[0-9]+)$" || true); do
      ip netns del "$ns"
      rm -rf "${TMPDIR:-/tmp}/raystack-netns-$ns"  # its temporary folder (deploy/netns-rsh.sh)
    done
    ;;
  *) usage ;;
esac
