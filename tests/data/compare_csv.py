"""Compares two seed_reference CSV files: same metadata, header and shape; numbers equal to
1e-12 relative per column (BLAS kernels may differ in the last bit between CPUs)."""
import sys

import numpy as np


def load(path):
    with open(path) as f:
        lines = f.read().splitlines()
    meta = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if not line.startswith("#")]
    return meta, body[0], np.array([[float(v) for v in row.split(",")] for row in body[1:]])


def main(a_path, b_path):
    meta_a, head_a, a = load(a_path)
    meta_b, head_b, b = load(b_path)
    if meta_a != meta_b or head_a != head_b or a.shape != b.shape:
        sys.exit(f"{a_path} and {b_path} differ in metadata, header or shape")
    scale = np.maximum(np.abs(b).max(axis=0), 1e-300)
    rel = (np.abs(a - b).max(axis=0) / scale).max()
    print(f"fixture regenerated: {a.shape[0]} rows, max relative difference {rel:.2e}")
    if rel > 1e-12:
        sys.exit(f"fixture differs from its script's output: {rel:e} > 1e-12")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
