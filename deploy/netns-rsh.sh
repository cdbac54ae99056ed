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
exec ip netns exec "$RAYSTACK_NETNS-h$index" /bin/sh -c "$*"
