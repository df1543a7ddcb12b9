#!/usr/bin/env bash
# Checks the Pi's Debian packages that `cargo xtask pi-package` wrote (default
# target/pi-package):
#   1. lintian: no error or warning (the overrides in packaging/pi/*.lintian-overrides give
#      their reasons); information tags are printed (docs/pi-package.md explains them);
#   2. systemd-analyze verify of every unit, which must print nothing (it exits 0 on a
#      misspelt setting, so its output is what counts), and the service's security rating;
#   3. the arm64 aer-raspi from the aer-tools package, run under QEMU user emulation with the
#      configuration from the aer-raspi package, replays the bundled session into its store with
#      the same rows, table by table, as the amd64 one.
# Needs: lintian, systemd, qemu-user, libc6-dev-arm64-cross (the arm64 loader), python3.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/pi-package}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

deb() {
  local matches=("$out"/"$1"_*_"$2".deb)
  [ -f "${matches[0]}" ] || { echo "no $1 package for $2 in $out" >&2; exit 1; }
  echo "${matches[0]}"
}

echo "--- packages"
ls -l "$out"/*.deb

echo "--- lintian"
lintian --fail-on error,warning --display-info "$out"/*.deb
echo "lintian: no error or warning"

echo "--- systemd-analyze"
for arch in amd64 arm64; do
  root="$work/root-$arch"
  for package in aer-tools aer-dashboard; do
    dpkg-deb -x "$(deb "$package" "$arch")" "$root"
  done
  dpkg-deb -x "$(deb aer-raspi all)" "$root"
done
dpkg-deb -x "$(deb aer-car-display all)" "$work/root-amd64"
root="$work/root-amd64"
# The system unit is verified inside the unpacked package (its ExecStart must exist there),
# next to the host's own units it refers to.
cp -an /lib/systemd/system/. "$root/usr/lib/systemd/system/"
report=$(systemd-analyze verify --root="$root" "$root/usr/lib/systemd/system/aer-raspi.service" 2>&1) || {
  echo "$report"; exit 1; }
[ -z "$report" ] || { echo "$report"; echo "systemd-analyze verify: aer-raspi.service has problems" >&2; exit 1; }
echo "aer-raspi.service: verified"
# systemd 252 cannot verify user units under --root: the user unit is verified on the host
# with its ExecStart pointed at the unpacked binary.
export XDG_RUNTIME_DIR="$work/runtime"
mkdir -m 700 "$XDG_RUNTIME_DIR"
sed "s|^ExecStart=/usr/bin/|ExecStart=$root/usr/bin/|" "$root/usr/lib/systemd/user/aer-dashboard.service" \
  > "$work/aer-dashboard.service"
report=$(systemd-analyze --user verify "$work/aer-dashboard.service" 2>&1) || { echo "$report"; exit 1; }
[ -z "$report" ] || { echo "$report"; echo "systemd-analyze verify: aer-dashboard.service has problems" >&2; exit 1; }
echo "aer-dashboard.service (user): verified"
systemd-analyze security --offline=yes --root="$root" "$root/usr/lib/systemd/system/aer-raspi.service" | tail -1
desktop-file-validate "$root/usr/share/applications/aer-dashboard.desktop" \
  "$root/etc/xdg/autostart/aer-car-display.desktop"
echo "desktop entries: valid"

echo "--- the arm64 service under QEMU replays the bundled session as the amd64 one does"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
replay() {
  local arch=$1 root="$work/root-$1" data="$work/data-$1"
  mkdir -p "$data"
  # The packaged configuration, with /var/lib/aer and /etc/aer inside this check's folders
  # and the broker on a free loopback port.
  sed "s|/var/lib/aer|$data|; s|/etc/aer|$root/etc/aer|" "$root/etc/aer/aer-raspi.toml" > "$work/$arch.toml"
  sed -i "s|127.0.0.1:1883|127.0.0.1:$port|" "$root/etc/aer/rumqttd.toml"
  local run=("$root/usr/bin/aer-raspi")
  [ "$arch" = arm64 ] && run=(qemu-aarch64 -L /usr/aarch64-linux-gnu "${run[@]}")
  file "$root/usr/bin/aer-raspi" | cut -d, -f1-2
  local start
  start=$(date +%s%N)
  NO_COLOR=1 timeout 900 "${run[@]}" --config "$work/$arch.toml" replay --fast raspi/data/session.log \
    > "$work/$arch.log" 2>&1 || { tail -20 "$work/$arch.log"; echo "$arch replay failed" >&2; exit 1; }
  echo "$arch: replayed in $((($(date +%s%N) - start) / 1000000)) ms"
}
replay amd64
replay arm64
python3 tools/compare_stores.py "$work/data-amd64/store.sqlite" "$work/data-arm64/store.sqlite"
