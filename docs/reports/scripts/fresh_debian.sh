#!/usr/bin/env bash
# A new user's evaluate-only path on a fresh Debian 12 root made by debootstrap: the README's
# prerequisites (Python's pip, git, rustup's stable toolchain), then `scripts/setup.sh --evaluate`
# and the main job, in a fresh clone of this checkout with ../shared beside it. Writes
# stage,seconds to DIR/stages.csv and the main job's output to DIR/root/work/pav/out/evaluate.
# usage: docs/reports/scripts/fresh_debian.sh DIR   (as root, from the repository root; needs
#   network access to a Debian mirror, crates.io, PyPI and static.rust-lang.org)
set -euo pipefail
dir=$(mkdir -p "$1" && cd "$1" && pwd)
here=$(pwd)
shared=$(cd .. && pwd)/shared
root="$dir/root"
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
command -v debootstrap >/dev/null || DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap
if [ ! -f "$root/etc/debian_version" ]; then
  debootstrap bookworm "$root" "$mirror" > "$dir/debootstrap.log" 2>&1
fi
mkdir -p "$root/work/shared"
[ -d "$root/work/pav" ] || git clone -q "$here" "$root/work/pav"
cp /etc/resolv.conf "$root/etc/resolv.conf"
# The network's own certificate authorities (a TLS-inspecting proxy's), which any machine on it
# is given.
mkdir -p "$root/usr/local/share/ca-certificates"
cp /usr/local/share/ca-certificates/*.crt "$root/usr/local/share/ca-certificates/" 2>/dev/null || true
mounted=()
bind() { mount --bind "$1" "$2" && mounted=("$2" "${mounted[@]}"); }
cleanup() { for m in "${mounted[@]}"; do umount -l "$m" || true; done; }
trap cleanup EXIT
mount -t proc proc "$root/proc" && mounted=("$root/proc")
bind /dev "$root/dev"
bind /dev/pts "$root/dev/pts"
bind /sys "$root/sys"
bind "$shared" "$root/work/shared"
mount -o remount,bind,ro "$root/work/shared"
# The stages run as the README says a user runs them; each line of stages.csv is one stage.
cat > "$root/work/stages.sh" <<'EOF'
set -euo pipefail
cd /work/pav
csv=/work/stages.csv
echo "stage,seconds" > "$csv"
s=$(date +%s)
apt-get update -qq
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  ca-certificates curl git python3-pip python3-venv > /dev/null
update-ca-certificates > /dev/null
# rustup-init itself, as rustup.rs's "other installation methods" give it.
curl -sSf -o /tmp/rustup-init https://static.rust-lang.org/rustup/dist/x86_64-unknown-linux-gnu/rustup-init
chmod +x /tmp/rustup-init
/tmp/rustup-init -y --profile minimal --default-toolchain stable > /dev/null
. "$HOME/.cargo/env"
t=$(date +%s); echo "prerequisites,$((t - s))" >> "$csv"; s=$t
bash scripts/setup.sh --evaluate
t=$(date +%s); echo "setup --evaluate,$((t - s))" >> "$csv"; s=$t
cargo run --release --bin pav-rig -- evaluate fixtures/turntable.mp4 -d configs/detectors -o out/evaluate
t=$(date +%s); echo "main job,$((t - s))" >> "$csv"
EOF
chroot "$root" /usr/bin/env -i HOME=/root TERM=dumb \
  PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin bash /work/stages.sh \
  < /dev/null 2>&1 | tee "$dir/chroot.log"
cp "$root/work/stages.csv" "$dir/stages.csv"
cat "$dir/stages.csv"
