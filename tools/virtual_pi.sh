#!/usr/bin/env bash
# The virtual Pi: the amd64 package installed into Debian 12 and booted on Debian's own kernel
# under QEMU (software emulation; KVM is not available on the build machines), with a real
# systemd, the package's hardened unit, the CAN modules (vcan, can-raw, can-isotp) and
# can-utils as the bus. The scenarios (tools/virtual_pi/scenarios.py) run inside the guest
# and print their results on its serial console; this script builds the disk, boots it,
# and fails unless every scenario passed.
#
# What stands in for the car: vcan links named as the hat's (can0, can1), made by
# systemd-networkd from a .netdev, with the package's .network overridden only to leave out
# its [CAN] bit timing (a vcan has none). Everything else is the package as shipped.
#
# Needs: root, debootstrap, systemd-container, qemu-system-x86, e2fsprogs; Debian's mirror.
# The calibration scenario adds the car model's CCM as an XCP-on-CAN node on can0
# (aer-car-node, from this checkout's build: AER_CAR_NODE or target/debug/aer-car-node) and
# pyxcp with pya2ldb (the versions tools/requirements.txt pins) in a venv in the guest.
#
# Usage: virtual_pi.sh [PACKAGES_DIR] [BASE_ROOT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath "${1:-target/pi-package}")
base=${2:-target/pi-boot-root}
root=target/virtual-pi-root
image=target/virtual-pi.img
console=target/virtual-pi.console
car_node=${AER_CAR_NODE:-target/debug/aer-car-node}
[ -x "$car_node" ] || cargo build -p aer-car-node
xcp_tools=$(grep -E '^(pyxcp|pya2ldb)==' tools/requirements.txt | tr '\n' ' ')

bash tools/debian_root.sh "$base"
rm -rf "$root"
cp -a "$base" "$root"
nspawn=(systemd-nspawn --quiet --keep-unit --register=no -D "$root")

echo "--- install: Debian's kernel, can-utils, mosquitto-clients, the packages"
mkdir -p "$root/root/debs"
rm -f "$root"/root/debs/*.deb
# The guest's pip has no route to PyPI of its own: the host's venv (the same Python, 3.11)
# fetches the wheels, the guest installs them offline.
rm -rf "$root/root/wheels"
.venv/bin/pip download --quiet --disable-pip-version-check --only-binary=:all: \
  --dest "$root/root/wheels" $xcp_tools
cp "$out"/aer-tools_*_amd64.deb "$out"/aer-raspi_*_all.deb "$root/root/debs/"
# The base root may have held the package before (the boot test): back to a fresh system.
"${nspawn[@]}" sh -c 'dpkg --purge aer-car-display aer-dashboard aer-raspi aer-tools >/dev/null 2>&1;
  rm -rf /var/lib/aer; userdel aer 2>/dev/null; groupdel aer 2>/dev/null;
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
  --no-install-recommends linux-image-amd64 initramfs-tools can-utils mosquitto-clients \
  iproute2 udev python3-venv /root/debs/*.deb &&
  python3 -m venv /opt/xcp && /opt/xcp/bin/pip install --quiet --disable-pip-version-check \
    --no-index --find-links /root/wheels '"$xcp_tools"'' \
  > "$root.install.log" 2>&1 || {
  tail -30 "$root.install.log"; exit 1; }
kernel=$(ls "$root"/boot/vmlinuz-* | sort -V | tail -1)
initrd=$(ls "$root"/boot/initrd.img-* | sort -V | tail -1)
echo "kernel: $(basename "$kernel")"

echo "--- the car's buses as vcan, the scenarios as a unit"
cat > "$root/etc/systemd/network/10-virtual-pi-can0.netdev" <<'NETDEV'
[NetDev]
Name=can0
Kind=vcan
NETDEV
sed 's/can0/can1/' "$root/etc/systemd/network/10-virtual-pi-can0.netdev" \
  > "$root/etc/systemd/network/10-virtual-pi-can1.netdev"
grep -v -e '^\[CAN\]' -e '^BitRate' -e '^RestartSec' "$root/usr/lib/systemd/network/80-aer-can.network" \
  > "$root/etc/systemd/network/80-aer-can.network"
echo "virtual-pi" > "$root/etc/hostname"
echo "/dev/vda / ext4 rw,noatime 0 1" > "$root/etc/fstab"
mkdir -p "$root/root/virtual-pi"
cp tools/virtual_pi/scenarios.py raspi/data/session.log tools/xcp_scenarios.py generated/aer.a2l \
  tools/xcp_gateway_client.py \
  "$car_node" "$root/root/virtual-pi/"
# The pit's side of the radio scenario: the dashboard from its package (the release binary;
# it loads its display libraries only when it opens a window), and the team's CA with the
# Pi's certificate for the pit listener, made as docs/dashboard.md says.
dpkg-deb --fsys-tarfile "$(ls "$out"/aer-dashboard_*_amd64.deb)" | tar -xO ./usr/bin/aer-dashboard \
  > "$root/root/virtual-pi/aer-dashboard"
chmod 755 "$root/root/virtual-pi/aer-dashboard"
# The radio's conditions: the 30 s outage (CI), or every one (AER_VIRTUAL_PI_RADIO=all).
echo "${AER_VIRTUAL_PI_RADIO:-ci}" > "$root/root/virtual-pi/radio"
tls="$root/root/virtual-pi/tls"
mkdir -p "$tls"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 30 \
  -subj "/CN=virtual team CA" -keyout "$tls/team-ca.key" -out "$tls/team-ca.pem" 2>/dev/null
openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=virtual-pi" \
  -keyout "$tls/pit.key.pem" -out "$tls/pit.csr" 2>/dev/null
openssl x509 -req -in "$tls/pit.csr" -CA "$tls/team-ca.pem" -CAkey "$tls/team-ca.key" -days 30 \
  -out "$tls/pit.cert.pem" -extfile <(printf "subjectAltName=IP:10.9.0.1\nbasicConstraints=CA:FALSE\nextendedKeyUsage=serverAuth") \
  2>/dev/null
cat > "$root/etc/systemd/system/virtual-pi-scenarios.service" <<'UNIT'
[Unit]
Description=The virtual Pi's scenarios
After=aer-raspi.service systemd-networkd.service multi-user.target
Wants=aer-raspi.service

[Service]
Type=oneshot
ExecStart=/usr/bin/python3 -u /root/virtual-pi/scenarios.py
StandardOutput=tty
StandardError=tty
TTYPath=/dev/ttyS0
ExecStopPost=/usr/bin/systemctl poweroff --no-block

[Install]
WantedBy=multi-user.target
UNIT
ln -sf /etc/systemd/system/virtual-pi-scenarios.service \
  "$root/etc/systemd/system/multi-user.target.wants/virtual-pi-scenarios.service"
# No login prompt on the console the results come back on.
ln -sf /dev/null "$root/etc/systemd/system/serial-getty@ttyS0.service"

echo "--- disk image"
rm -f "$image"
truncate -s 3G "$image"
mkfs.ext4 -q -F -L virtual-pi -d "$root" "$image"
# The image holds the root now: keep the kernel and initrd QEMU boots, give the disk back.
cp "$kernel" target/virtual-pi.vmlinuz
cp "$initrd" target/virtual-pi.initrd
kernel=target/virtual-pi.vmlinuz
initrd=target/virtual-pi.initrd
rm -rf "$root"

echo "--- boot (QEMU, TCG)"
start=$(date +%s)
timeout 900 qemu-system-x86_64 -accel tcg -m 2048 -smp 2 -display none -monitor none \
  -nic none -no-reboot -serial "file:$console" \
  -kernel "$kernel" -initrd "$initrd" \
  -drive "file=$image,format=raw,if=virtio" \
  -append "root=/dev/vda rw console=ttyS0 quiet loglevel=3 systemd.show_status=false" || true
echo "the guest ran $(( $(date +%s) - start )) s"

grep -a '^VPI ' "$console" | sed 's/^VPI //' || true
grep -aq '^VPI done: every scenario passed' "$console" || {
  echo "--- the guest's console, last lines"; tail -60 "$console"
  echo "the virtual Pi failed a scenario (or did not finish)" >&2; exit 1; }
echo "the virtual Pi passed every scenario"
