#!/usr/bin/env bash
# The test command (README "Set-up", .ci/run): each cargo feature builds on its own, then every
# test of the workspace with all features (the layer check in tests/it/layers.rs among them).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/check-features.sh
cargo test --release --workspace --all-features
