#!/usr/bin/python3
"""Seam and face-accuracy figures of decoded multi-brick models (docs/benchmarks.md, "Multi-brick models").

usage: brick_seams.py GROUND_TRUTH.raw DIMS(X,Y,Z) SPLITS(axis:pos,...) DECODED.raw [...]
Each decode is float32 x-fastest at the ground truth's dims, normalised like it (range of the truth).
Per decode: PSNR over all voxels, over the voxels next to a brick face (within 1 voxel) and the rest,
and the error jump across planes: J(plane) = mean |e[i] - e[i-1]| over the plane, e = decoded - truth;
the largest J over brick faces against the largest over interior planes.
"""
import sys
import numpy as np


def main():
    truth_path, dims, splits = sys.argv[1], [int(v) for v in sys.argv[2].split(',')], sys.argv[3]
    nx, ny, nz = dims
    faces = {0: [], 1: [], 2: []}
    for s in splits.split(','):
        if s:
            a, p = s.split(':')
            faces['xyz'.index(a)].append(int(p))
    truth = np.fromfile(truth_path, dtype=np.float32).reshape(nz, ny, nx)
    lo, hi = float(truth.min()), float(truth.max())
    t = (truth - lo) / (hi - lo)
    near = np.zeros_like(t, dtype=bool)
    for axis, ps in faces.items():
        ax = 2 - axis  # numpy axes are z, y, x
        for p in ps:
            sl = [slice(None)] * 3
            sl[ax] = slice(p - 1, p + 1)
            near[tuple(sl)] = True
    print(f"{'decode':24s} {'PSNR':>7s} {'faces':>7s} {'inside':>7s} {'Jface':>8s} {'Jinner':>8s}")
    for path in sys.argv[4:]:
        d = (np.fromfile(path, dtype=np.float32).reshape(nz, ny, nx) - lo) / (hi - lo)
        e = d - t
        psnr = lambda m: 10 * np.log10(1 / np.mean(e[m] ** 2))
        jf, ji = 0.0, 0.0
        for axis in range(3):
            ax = 2 - axis
            j = np.mean(np.abs(np.diff(e, axis=ax)), axis=tuple(i for i in range(3) if i != ax))  # J between i-1 and i
            for i in range(1, dims[axis]):
                if i in faces[axis]:
                    jf = max(jf, j[i - 1])
                elif 2 <= i <= dims[axis] - 2:
                    ji = max(ji, j[i - 1])
        print(f"{path:24s} {psnr(np.ones_like(near)):7.2f} {psnr(near):7.2f} {psnr(~near):7.2f} {jf:8.5f} {ji:8.5f}")


if __name__ == '__main__':
    main()
