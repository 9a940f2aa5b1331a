"""Times the Python BVH libraries (pybvh, bvhio, bvh from PyPI) reading every .bvh file in a
folder, best of three passes, and prints one tab-separated line per library:
name, bytes read, seconds, files failed, files. Called by the Rust bench
`tokenizer/benches/bvh_throughput.rs`; install the libraries with tools/setup-bench.sh."""
import os
import sys
import time


def readers():
    out = []
    try:
        import pybvh
        out.append(('pybvh read', lambda path, text: pybvh.read_bvh_file(path)))
    except ImportError:
        print('pybvh not installed (tools/setup-bench.sh)', file=sys.stderr)
    try:
        import bvhio
        out.append(('bvhio read', lambda path, text: bvhio.readAsBvh(path)))
    except ImportError:
        print('bvhio not installed (tools/setup-bench.sh)', file=sys.stderr)
    try:
        from bvh import Bvh
        # bvh parses lazily; asking for every frame's values makes it read the whole file.
        out.append(('bvh read', lambda path, text: [list(map(float, f)) for f in Bvh(text).frames]))
    except ImportError:
        print('bvh not installed (tools/setup-bench.sh)', file=sys.stderr)
    return out


def main(folder):
    paths = sorted(os.path.join(folder, p) for p in os.listdir(folder) if p.endswith('.bvh'))
    texts = {p: open(p).read() for p in paths}
    for name, read in readers():
        best, done_bytes, failed = float('inf'), 0, 0
        for _ in range(3):
            done_bytes, failed = 0, 0
            start = time.perf_counter()
            for p in paths:
                try:
                    read(p, texts[p])
                    done_bytes += len(texts[p])
                except Exception:
                    failed += 1
            best = min(best, time.perf_counter() - start)
        print(f'{name}\t{done_bytes}\t{best}\t{failed}\t{len(paths)}')


if __name__ == '__main__':
    main(sys.argv[1])
