#!/usr/bin/env bash
# Builds the library and binaries with each cargo feature on its own (and with none), each crate
# of the workspace alone with none of its features and with all of them, and the ONNX crate with
# and without its runtime, so a `cfg(feature)` gate that only compiles next to other features, or
# a crate that only builds beside another, fails here; warnings count as failures. Uses the
# release profile so it shares build artifacts with the test command.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
check() {
  printf '== cargo check %s\n' "$*"
  log=$(cargo check --release "$@" --message-format short 2>&1) || { echo "$log"; status=1; return; }
  if grep -E '^(src|tests|crates)/.*(warning|error)' <<<"$log"; then status=1; fi
}
for f in "" video plot eval rig optimize doctor; do
  check --no-default-features ${f:+--features "$f"} --lib --bins
done
for dir in crates/*/; do
  crate=$(basename "$dir")
  check -p "$crate" --no-default-features --lib
  check -p "$crate" --all-features --lib
done
exit $status
