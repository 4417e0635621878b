#!/usr/bin/env bash
# Create a virtual SocketCAN bus for replay and live tests (Linux, needs root and the vcan module).
#   sudo scripts/setup-vcan.sh [vcan0] [--fd]
# Then: lashscope replay LOG --interface socketcan --channel vcan0
#       lashscope live --interface socketcan --channel vcan0 --vehicle V
# The tests in tests/live/test_socketcan.py run when this interface exists and skip otherwise.
set -euo pipefail
DEV="${1:-vcan0}"
MTU=16
if [ "${2:-}" = "--fd" ] || [ "${1:-}" = "--fd" ]; then
  MTU=72  # CAN FD frames
  [ "$DEV" = "--fd" ] && DEV=vcan0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "setup-vcan: run as root (sudo $0 $*)" >&2
  exit 1
fi
if ! modprobe vcan 2>/dev/null && ! grep -qw vcan /proc/modules; then
  echo "setup-vcan: this kernel has no vcan module (containers and some VMs lack it)." >&2
  echo "            Use the loopback bus instead: python -m app.live.loopback --port 29536" >&2
  exit 2
fi
if ! ip link show "$DEV" >/dev/null 2>&1; then
  ip link add dev "$DEV" type vcan
fi
ip link set "$DEV" mtu "$MTU"
ip link set up "$DEV"
ip -details link show "$DEV"
echo "setup-vcan: $DEV is up (mtu $MTU)"
