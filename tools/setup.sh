#!/usr/bin/env bash
# Sets anymo up on a fresh machine with the Rust toolchain: builds the release binary.
# (Models and their downloads arrive with the tokenizer and text-encoder issues; nothing is
# fetched at run time.)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked -p anymo-services
echo "built target/release/anymo"
