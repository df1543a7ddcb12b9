#!/usr/bin/env bash
# A minimal Debian 12 root with systemd (debootstrap), kept between runs: the base of the Pi
# package's boot test (tools/boot_pi_package.sh) and of the virtual Pi (tools/virtual_pi.sh).
# Also readies this machine for systemd-nspawn into it.
#
# Needs: root, debootstrap; Debian's mirror (DEBIAN_MIRROR).
# Usage: debian_root.sh ROOT_DIR
set -euo pipefail
root=$1
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
# nspawn keeps its mount propagation folder in /run and refuses to clean one that is not on
# a tmpfs, which /run is not on every build machine.
mkdir -p /run/systemd/nspawn
[ "$(stat -fc %T /run/systemd/nspawn)" = tmpfs ] || mount -t tmpfs tmpfs /run/systemd/nspawn
[ -x "$root/usr/bin/apt-get" ] && exit 0
rm -rf "$root"
mkdir -p "$(dirname "$root")"
echo "--- debootstrap bookworm into $root"
# Once more if the mirror fails the first time (a download, not a test).
for attempt in 1 2; do
  debootstrap --variant=minbase --include=systemd,systemd-sysv,dbus,python3 \
    bookworm "$root" "$mirror" > "$root.debootstrap.log" 2>&1 && exit 0
  tail -20 "$root.debootstrap.log"
  rm -rf "$root"
done
echo "debootstrap failed" >&2
exit 1
