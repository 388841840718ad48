#!/usr/bin/env bash
# Builds the library and binaries with each cargo feature on its own (and with none), and the
# ONNX crate with and without its runtime, so a `cfg(feature)` gate that only compiles next to
# other features fails here; warnings count as failures. Uses the release profile so it shares build artifacts with the test command.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
for f in "" video plot eval rig optimize; do
  printf '== cargo check --no-default-features%s\n' "${f:+ --features $f}"
  log=$(cargo check --release --no-default-features ${f:+--features "$f"} --lib --bins --message-format short 2>&1) || {
    echo "$log"; status=1; continue; }
  if grep -E '^(src|tests)/.*(warning|error)' <<<"$log"; then status=1; fi
done
# The ONNX toolchain crate alone: graphs only, and with ONNX Runtime.
for f in "" runtime; do
  printf '== cargo check -p pav-onnx --no-default-features%s\n' "${f:+ --features $f}"
  log=$(cargo check --release -p pav-onnx --no-default-features ${f:+--features "$f"} --lib --message-format short 2>&1) || {
    echo "$log"; status=1; continue; }
  if grep -E '^crates/pav-onnx/src/.*(warning|error)' <<<"$log"; then status=1; fi
done
exit $status
