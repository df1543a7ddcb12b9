#!/usr/bin/env bash
# Installs the amd64 packages (cargo xtask pi-package) into a fresh Debian 12 and boots it
# under systemd (systemd-nspawn), to prove on a real service manager what the static checks
# cannot: the maintainer scripts, the user, the hardened unit starting and running the
# pipeline, a clean stop on SIGTERM, and a purge that keeps the recorded data.
#
# The container shares this machine's network (loopback included), and its kernel: there
# is no CAN here, so the service replays the bundled session in a loop through a drop-in, as an
# administrator would (`systemctl edit aer-raspi`).
#
# Needs: root, debootstrap, systemd-container, mosquitto-clients; Debian's mirror.
# Usage: boot_pi_package.sh [PACKAGES_DIR] [ROOT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath "${1:-target/pi-package}")
root=${2:-target/pi-boot-root}
bash tools/debian_root.sh "$root"

# No system bus outside: no machine registration, no scope of its own.
nspawn=(systemd-nspawn --quiet --keep-unit --register=no -D "$root")

echo "--- install"
mkdir -p "$root/root/debs"
rm -f "$root"/root/debs/*.deb
cp "$out"/aer-tools_*_amd64.deb "$out"/aer-raspi_*_all.deb "$out"/aer-dashboard_*_amd64.deb "$out"/aer-car-display_*_all.deb \
  "$root/root/debs/"
# A root kept from an earlier run is first put back to before the first install.
"${nspawn[@]}" sh -c 'dpkg --purge aer-car-display aer-dashboard aer-raspi aer-tools >/dev/null 2>&1;
  rm -rf /var/lib/aer; userdel aer 2>/dev/null; groupdel aer 2>/dev/null;
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
  --no-install-recommends /root/debs/*.deb' > "$root.install.log" 2>&1 || {
  tail -30 "$root.install.log"; exit 1; }
grep -E "^(Setting up aer|Created symlink)" "$root.install.log" || true

# The broker on a free port (the container shares this machine's loopback), the bundled
# session in a loop instead of CAN.
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
sed -i "s|127.0.0.1:[0-9]*\"|127.0.0.1:$port\"|" "$root/etc/aer/rumqttd.toml"
mkdir -p "$root/etc/systemd/system/aer-raspi.service.d"
printf '[Service]\nExecStart=\nExecStart=/usr/bin/aer-raspi --config /etc/aer/aer-raspi.toml replay --loop\n' \
  > "$root/etc/systemd/system/aer-raspi.service.d/replay.conf"

echo "--- boot"
"${nspawn[@]}" --boot > "$root.boot.log" 2>&1 &
boot=$!
cleanup() { kill "$boot" 2>/dev/null || true; wait "$boot" 2>/dev/null || true; }
trap cleanup EXIT
init=""
for _ in $(seq 1 600); do
  init=$(pgrep -P "$boot" -x systemd || true)
  [ -n "$init" ] && break
  kill -0 "$boot" 2>/dev/null || { cat "$root.boot.log"; echo "the container did not boot" >&2; exit 1; }
  sleep 0.1
done
[ -n "$init" ] || { echo "no systemd in the container" >&2; exit 1; }
inside() { nsenter -t "$init" -a "$@"; }
# systemctl answers once the manager's socket is there.
for _ in $(seq 1 600); do
  inside test -S /run/systemd/private && break
  sleep 0.1
done
state=$(inside timeout 120 systemctl is-system-running --wait || true)
echo "system: $state"

failed=0
check() { # check DESCRIPTION COMMAND...
  if "${@:2}"; then echo "ok: $1"; else echo "FAILED: $1" >&2; failed=1; fi
}
networkd_without_wait_online() {
  [ "$(inside systemctl is-enabled systemd-networkd)" = enabled ] &&
    ! inside systemctl is-enabled --quiet systemd-networkd-wait-online
}
telemetry_on_the_broker() {
  mosquitto_sub -h 127.0.0.1 -p "$port" -t 'aer/car1/telemetry' -C 1 -W 30 | grep -q motor_speed
}
stops_cleanly() {
  inside systemctl stop aer-raspi && [ "$(inside systemctl show -P Result aer-raspi)" = success ]
}
purge_keeps_data() {
  inside sh -c 'DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq aer-car-display aer-raspi >/dev/null 2>&1' &&
    inside test -s /var/lib/aer/store.sqlite && ! inside test -e /etc/aer/aer-raspi.toml
}

check "aer-raspi.service is active" inside systemctl is-active --quiet aer-raspi
pid=$(inside systemctl show -P MainPID aer-raspi)
user=$(inside stat -c %U "/proc/$pid" 2>/dev/null || echo "no process")
check "the service runs as aer (it is $user)" test "$user" = aer
check "no capabilities" inside grep -q '^CapEff:.0000000000000000' "/proc/$pid/status"
check "systemd-networkd enabled, its wait-online not" networkd_without_wait_online
check "telemetry on the broker (mosquitto_sub)" telemetry_on_the_broker
rows=0
for _ in $(seq 1 300); do
  rows=$(inside python3 -c "import sqlite3; print(sqlite3.connect('file:/var/lib/aer/store.sqlite?mode=ro', uri=True).execute('SELECT count(*) FROM telemetry').fetchone()[0])" 2>/dev/null || echo 0)
  [ "$rows" -gt 0 ] && break
  sleep 0.1
done
check "rows committed to /var/lib/aer/store.sqlite ($rows)" test "$rows" -gt 0
modes=$(inside stat -c '%U:%G %a' /var/lib/aer /var/lib/aer/store.sqlite /etc/aer/aer-raspi.toml | tr '\n' ' ')
check "data aer:aer 750/640, config root:aer 640 ($modes)" \
  test "$modes" = "aer:aer 750 aer:aer 640 root:aer 640 "
inside systemd-analyze security aer-raspi --no-pager | tail -1
check "SIGTERM stops it cleanly" stops_cleanly
journal=$(inside journalctl -b -u aer-raspi --no-pager -o cat)
check "the journal has no colour codes" test "$journal" = "${journal//$'\e'/}"
check "the journal has no ERROR and no refused system call" \
  test -z "$(grep -E 'ERROR|EPERM|Operation not permitted|SIGSYS' <<< "$journal")"
check "purge keeps the data, removes the configuration" purge_keeps_data
inside systemctl poweroff || true
wait "$boot" || true
trap - EXIT
rm -f "$root/etc/systemd/system/aer-raspi.service.d/replay.conf"
[ "$failed" = 0 ] || { echo "the booted package failed a check" >&2; exit 1; }
echo "the packages install, boot and run under systemd"
