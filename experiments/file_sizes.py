"""Results-file sizes with and without compression.

For each results.h5 given, writes a copy whose datasets are contiguous and unfiltered (what deltajax.io wrote
before chunking + shuffle + gzip; same data and attributes, dimension-scale links left out) to a temporary
file and prints both sizes. The copy is deleted.

Usage: ``python experiments/file_sizes.py outputs/reconfig_indices/<run>/results.h5 [...]``
(commands and figures: docs/BENCHMARKS.md, "Results file sizes").
"""

import argparse
import os
import tempfile

import h5py

_SCALE_ATTRS = ("DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME")  # references into the source file


def uncompressed_copy(src: str, dst: str) -> int:
    """Copy ``src`` to ``dst`` without compression; returns the datasets' raw bytes."""
    raw = 0
    with h5py.File(src, "r") as f, h5py.File(dst, "w") as g:
        for k, v in f.attrs.items():
            g.attrs[k] = v

        def copy(name, obj):
            nonlocal raw
            if isinstance(obj, h5py.Group):
                out = g.require_group(name)
            else:
                out = g.create_dataset(name, data=obj[()])
                raw += obj.size * obj.dtype.itemsize
            for k, v in obj.attrs.items():
                if k not in _SCALE_ATTRS:
                    out.attrs[k] = v

        f.visititems(copy)
    return raw


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    args = ap.parse_args()
    for path in args.files:
        with tempfile.TemporaryDirectory(dir=os.path.dirname(os.path.abspath(path))) as tmp:
            copy = os.path.join(tmp, "uncompressed.h5")
            raw = uncompressed_copy(path, copy)
            plain = os.path.getsize(copy)
        size = os.path.getsize(path)
        print(f"{path}: {size / 1e6:.4g} MB compressed, {plain / 1e6:.4g} MB uncompressed "
              f"(raw data {raw / 1e6:.4g} MB), {plain / size:.1f}x smaller")


if __name__ == "__main__":
    main()
