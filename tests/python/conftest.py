"""Shared fixtures of the vnr module's tests: the CLI, small generated volumes written as raw + sidecar."""
import json
import os
import shutil
import subprocess

import pytest

try:  # test_module.py skips (visibly) without them
    import numpy as np
    import vnr
except ImportError:
    np = vnr = None

HERE = os.path.dirname(os.path.abspath(__file__))


def cli_path():
    path = os.environ.get("VNR_CLI") or shutil.which("vnr")
    if not path:
        guess = os.path.join(HERE, "..", "..", "build", "vnr")
        path = guess if os.path.exists(guess) else None
    return path


@pytest.fixture(scope="session")
def cli():
    path = cli_path()
    if not path:
        pytest.skip("the vnr CLI was not found (set VNR_CLI)")

    def run(*args):
        r = subprocess.run([path, *map(str, args)], capture_output=True, text=True)
        assert r.returncode == 0, f"vnr {' '.join(map(str, args))} failed:\n{r.stderr}"
        return r
    return run


def smooth_volume(shape=(12, 14, 16), dtype="uint8", seed=1):
    """A smooth (learnable) volume with some noise, scaled to dtype's range."""
    nz, ny, nx = shape
    z, y, x = np.meshgrid(np.linspace(0, 1, nz), np.linspace(0, 1, ny), np.linspace(0, 1, nx), indexing="ij")
    f = 0.5 + 0.3 * np.sin(6 * x) * np.cos(5 * y) + 0.2 * z
    f += 0.02 * np.random.default_rng(seed).standard_normal(shape)
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        lo, hi = max(info.min, -1000), min(info.max, 1000)
        return np.clip(lo + f * (hi - lo), info.min, info.max).astype(dtype)
    return (f * 100 - 20).astype(dtype)


def write_raw(array, path_json):
    """array (nz, ny, nx) written with tofile + a vnr JSON sidecar."""
    raw = path_json[:-5] + ".raw"
    np.ascontiguousarray(array).tofile(raw)
    order = array.dtype.byteorder
    big = order == ">" or (order == "=" and np.little_endian is False)
    with open(path_json, "w") as f:
        json.dump({"file": os.path.basename(raw), "dims": [array.shape[2], array.shape[1], array.shape[0]],
                   "dtype": array.dtype.newbyteorder("=").name, "byte_order": "big" if big else "little"}, f)
    return path_json


def read_raw_json(path_json):
    with open(path_json) as f:
        side = json.load(f)
    x, y, z = side["dims"]
    data = np.fromfile(os.path.join(os.path.dirname(path_json), side["file"]), dtype=np.dtype(side["dtype"]))
    return data.reshape(z, y, x)


def read_pfm(path):
    with open(path, "rb") as f:
        assert f.readline().strip() == b"PF"
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4").reshape(h, w, 3)
    return data[::-1]  # PFM rows run bottom to top
