#!/usr/bin/env bash
# Installs the Python BVH libraries the throughput bench compares against (PyPI only).
set -euo pipefail
python3 -m pip install --quiet pybvh==0.9.0 bvhio==1.5.4 bvh==0.3
