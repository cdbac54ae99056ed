#!/bin/sh
# mpirun's remote shell for the hosts of deploy/netns-cluster.sh: Open MPI runs
# `netns-rsh.sh HOST COMMAND...` to start its daemon on HOST; host 10.231.0.K is the namespace
# $RAYSTACK_NETNS-h(K-1).
set -eu
host="$1"
shift
: "${RAYSTACK_NETNS:?set RAYSTACK_NETNS to the cluster NAME given to netns-cluster.sh}"
case "$host" in
  10.231.0.*) index=$((${host##*.} - 1)) ;;
  *) echo "netns-rsh: $host is not a host of netns cluster $RAYSTACK_NETNS" >&2; exit 1 ;;
esac
# The "hosts" share one filesystem and hostname: each gets a temporary folder of its own, or
# Open MPI's daemons would race for the same session folder.
ns="$RAYSTACK_NETNS-h$index"
namespaces="$(ip netns list | cut -d' ' -f1)"
if ! printf '%s\n' "$namespaces" | grep -qxF "$ns"; then
  echo "netns-rsh: no network namespace $ns (host $host): is netns cluster $RAYSTACK_NETNS up?" >&2
  exit 1
fi
tmp="${TMPDIR:-/tmp}/raystack-netns-$ns"
mkdir -p "$tmp"
exec ip netns exec "$ns" env TMPDIR="$tmp" /bin/sh -c "$*"
