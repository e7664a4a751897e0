#!/usr/bin/env python3
"""Peak memory of training and decoding a large uint8 array through the module, against the bound
the module documents: the input array + the larger of vnr's normalised float32 copy (alive while
vnr.train(array) runs; freed when it returns) and the float32 decode output + the model (fp32
parameters, Adam's two moments, gradients: 16 bytes a parameter) + 256 MiB for Python, numpy, the
trainer's batch buffers and the allocator. No hidden copy of the volume fits under it.

  PYTHONPATH=build/python /usr/bin/python3 bench/python_memory.py [--size 512] [--steps 3]
"""
import argparse
import subprocess
import sys

CHILD = r"""
import resource, sys, numpy as np, vnr
n, steps, config = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
z = np.arange(n, dtype=np.float32)[:, None, None]
array = np.empty((n, n, n), np.uint8)
for k in range(n):  # built slice by slice: no float temporary of the whole volume
    array[k] = (127 + 120 * np.sin(z[k] / 9) * np.cos(np.arange(n)[:, None] / 7) * np.cos(np.arange(n) / 5)).astype(np.uint8)
model = vnr.train(array, config=config, steps=steps, device="cpu")
decoded = model.decode(device="cpu")
assert decoded.shape == array.shape
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, array.nbytes, decoded.nbytes, model.n_params)
"""


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--config", default="paper")
    a = p.parse_args()
    out = subprocess.run([sys.executable, "-c", CHILD, str(a.size), str(a.steps), a.config], check=True,
                         capture_output=True, text=True).stdout.split()
    peak, input_bytes, decoded_bytes, n_params = map(int, out)
    normalised = input_bytes * 4
    bound = input_bytes + max(normalised, decoded_bytes) + 16 * n_params + (256 << 20)
    mib = lambda b: f"{b / (1 << 20):.0f} MiB"  # noqa: E731
    print(f"{a.size}^3 uint8, {a.steps} steps of '{a.config}' ({n_params} params), decode to float32")
    print(f"bound: input {mib(input_bytes)} + max(normalised {mib(normalised)}, decoded {mib(decoded_bytes)}) + model "
          f"{mib(16 * n_params)} + 256 MiB = {mib(bound)}")
    print(f"peak RSS (ru_maxrss): {mib(peak)} -> {'within' if peak <= bound else 'OVER'} the bound")
    sys.exit(0 if peak <= bound else 1)


if __name__ == "__main__":
    main()
