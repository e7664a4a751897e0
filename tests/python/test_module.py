"""The vnr Python module against independent references: the `vnr` CLI on the same data (train, decode,
render, eval), the raw-file loader, and the module's own decode."""
import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest

np = pytest.importorskip("numpy", reason="numpy (Debian python3-numpy) is needed for the vnr module's tests")
vnr = pytest.importorskip("vnr", reason="the vnr module is not built (VNR_PYTHON=ON) or not on PYTHONPATH")

from conftest import read_pfm, read_raw_json, smooth_volume, write_raw  # noqa: E402

SEED, THREADS, STEPS = 3, 2, 80
TRAIN = dict(config="small", steps=STEPS, seed=SEED, device="cpu", threads=THREADS)


@pytest.fixture(scope="module")
def trained(tmp_path_factory, cli):
    """One volume trained by the CLI and by the module with the same seed and threads."""
    d = tmp_path_factory.mktemp("trained")
    array = smooth_volume()
    side = write_raw(array, str(d / "vol.json"))
    cli("train", side, "-o", d / "cli.vnr", "--config", "small", "--steps", STEPS, "--seed", SEED,
        "--threads", THREADS, "--device", "cpu", "-q")
    model = vnr.train(array, **TRAIN)
    return dict(dir=d, array=array, side=side, cli_model=str(d / "cli.vnr"), model=model)


def test_train_decode_equals_cli(trained, cli):
    d = trained["dir"]
    cli("decode", trained["cli_model"], "-o", d / "cli_dec.raw", "--threads", THREADS, "--device", "cpu", "-q")
    cli("decode", trained["cli_model"], "-o", d / "cli_src.raw", "--dtype", "source", "--threads", THREADS,
        "--device", "cpu", "-q")
    model = trained["model"]
    decoded = model.decode(device="cpu")
    assert decoded.shape == trained["array"].shape and decoded.dtype == np.float32
    np.testing.assert_array_equal(decoded, read_raw_json(str(d / "cli_dec.json")))
    source = model.decode(dtype="source", device="cpu")
    assert source.dtype == np.uint8
    np.testing.assert_array_equal(source, read_raw_json(str(d / "cli_src.json")))
    # Another resolution: shape is numpy's (nz, ny, nx), the CLI's --dims is X,Y,Z.
    cli("decode", trained["cli_model"], "-o", d / "cli_small.raw", "--dims", "7,6,5", "--threads", THREADS,
        "--device", "cpu", "-q")
    np.testing.assert_array_equal(model.decode(shape=(5, 6, 7), device="cpu"), read_raw_json(str(d / "cli_small.json")))
    # To a file, as `vnr decode` writes it: the same bytes and sidecar; an existing file needs force=True.
    cli_model = vnr.Model.load(trained["cli_model"])
    cli_model.decode_to_file(str(d / "py_src.raw"), dtype="source", device="cpu")
    assert (d / "py_src.raw").read_bytes() == (d / "cli_src.raw").read_bytes()
    np.testing.assert_array_equal(read_raw_json(str(d / "py_src.json")), source)  # its sidecar describes it
    with pytest.raises(Exception, match="force=True"):
        cli_model.decode_to_file(str(d / "py_src.raw"), dtype="source")
    cli_model.decode_to_file(str(d / "py_src.raw"), shape=(5, 6, 7), device="cpu", force=True)
    np.testing.assert_array_equal(read_raw_json(str(d / "py_src.json")), read_raw_json(str(d / "cli_small.json")))
    assert model.training["steps"] == STEPS
    assert model.value_range == (float(trained["array"].min()), float(trained["array"].max()))
    # A vnr.Volume (shared, not copied) trains to the same model as the array it came from.
    again = vnr.train(vnr.Volume.from_numpy(trained["array"]), **TRAIN)
    np.testing.assert_array_equal(again.decode(device="cpu"), decoded)


def test_save_load_round_trip(trained, tmp_path):
    model = trained["model"]
    path = str(tmp_path / "m.vnr")
    model.save(path)
    loaded = vnr.Model.load(path)
    np.testing.assert_array_equal(loaded.decode(device="cpu"), model.decode(device="cpu"))
    assert loaded.config == model.config and loaded.n_params == model.n_params > 0
    assert loaded.value_range == model.value_range and loaded.dims == (16, 14, 12)
    assert loaded.source_dtype == np.uint8
    assert loaded.compression_ratio == pytest.approx(trained["array"].nbytes / os.path.getsize(path))
    # Another resolution: (nz, ny, nx) as numpy orders it.
    assert loaded.decode(shape=[5, 6, 7], device="cpu").shape == (5, 6, 7)


def test_sample_at_voxel_centres_equals_decode(trained):
    model = trained["model"]
    nz, ny, nx = model.shape
    z, y, x = np.meshgrid((np.arange(nz) + 0.5) / nz, (np.arange(ny) + 0.5) / ny, (np.arange(nx) + 0.5) / nx,
                          indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1).astype(np.float32)
    decoded = model.decode(device="cpu")
    np.testing.assert_array_equal(model.sample(points, device="cpu").reshape(nz, ny, nx), decoded)
    # float64 and strided inputs are converted (same float32 coordinates, same values).
    np.testing.assert_array_equal(model.sample(points.astype(np.float64), device="cpu").reshape(decoded.shape), decoded)
    np.testing.assert_array_equal(model.sample(np.asfortranarray(points), device="cpu").reshape(decoded.shape), decoded)


def test_render_equals_cli(trained, cli):
    d = trained["dir"]
    cli("render", trained["cli_model"], "-o", d / "r.pfm", "--size", "40x32", "--orbit", "30,20", "--tf", "cool-warm",
        "--threads", THREADS, "--device", "cpu", "--spp", 2, "-q")
    model = vnr.Model.load(trained["cli_model"])
    image = vnr.render(model, camera=vnr.Camera.orbit(30, 20), tf="cool-warm", size=(40, 32), spp=2, device="cpu")
    assert image.shape == (32, 40, 4) and image.dtype == np.float32
    reference = read_pfm(str(d / "r.pfm"))
    np.testing.assert_array_equal(image[..., :3], reference)
    assert image[..., 3].max() > 0.05  # something was drawn
    # The same camera as a dict, and the TF as the JSON text of a file `vnr render --tf` reads.
    same = vnr.render(model, camera={"azimuth": 30, "elevation": 20}, tf="cool-warm", size=(40, 32), spp=2,
                      device="cpu")
    np.testing.assert_array_equal(same, image)
    tf = vnr.TransferFunction(colors=[(0, 0, 0, 1), (1, 1, 0, 0)], opacities=[(0, 0), (1, 0.5)])
    (d / "tf.json").write_text(tf.to_json())
    cli("render", trained["cli_model"], "-o", d / "r2.pfm", "--size", "24x24", "--tf", d / "tf.json",
        "--eye", "8,7,40", "--center", "8,7,6", "--threads", THREADS, "--device", "cpu", "-q")
    image2 = vnr.render(model, camera=dict(eye=(8, 7, 40), center=(8, 7, 6)), tf=tf, size=(24, 24), device="cpu")
    np.testing.assert_array_equal(image2[..., :3], read_pfm(str(d / "r2.pfm")))


def test_render_from_the_brick_cache_equals_cli(trained, cli):
    d = trained["dir"]
    cli("render", trained["cli_model"], "-o", d / "c.pfm", "--size", "40x32", "--orbit", "30,20", "--strategy", "cache",
        "--cache-dims", "40,36,30", "--cache-budget", "64MiB", "--threads", THREADS, "--spp", 8, "-q")
    model = vnr.Model.load(trained["cli_model"])
    image = vnr.render(model, camera=(30, 20), size=(40, 32), spp=8, device="cpu", strategy="cache",
                       cache_dims=(40, 36, 30), cache_budget="64MiB")
    np.testing.assert_array_equal(image[..., :3], read_pfm(str(d / "c.pfm")))
    direct = vnr.render(model, camera=(30, 20), size=(40, 32), spp=8, device="cpu", strategy="streaming")
    assert np.abs(image - direct).max() < 0.25 and not np.array_equal(image, direct)  # close, not the same samples
    with pytest.raises(Exception, match="cache_dims"):
        vnr.render(model, size=(8, 8), cache_dims=(0, 4, 4))


def test_render_volume_equals_cli(trained, cli):
    d = trained["dir"]
    cli("render", trained["side"], "-o", d / "v.pfm", "--size", "24x20", "--threads", THREADS, "-q")
    image = vnr.render(vnr.Volume.open(trained["side"]), size=(24, 20))
    np.testing.assert_array_equal(image[..., :3], read_pfm(str(d / "v.pfm")))


def test_metrics_equal_cli_eval(trained, cli):
    import json
    d = trained["dir"]
    cli("eval", trained["cli_model"], trained["side"], "--report", d / "eval.json", "--threads", THREADS,
        "--device", "cpu", "-q")
    report = json.loads((d / "eval.json").read_text())
    decoded = vnr.Model.load(trained["cli_model"]).decode(device="cpu")
    # decode() is in original units (float32); mapping back to normalised units rounds by ~1e-7.
    assert vnr.metrics.psnr(trained["array"], decoded) == pytest.approx(report["psnr"], abs=1e-4)
    assert vnr.metrics.ssim(trained["array"], decoded) == pytest.approx(report["ssim"], abs=1e-6)
    assert vnr.metrics.mse(trained["array"], decoded) == pytest.approx(report["mse"], rel=1e-5)
    assert vnr.metrics.psnr(trained["array"], trained["array"]) == 999


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "<u2", ">u2", "int32", "uint32", "float32", ">f4",
                                   "float64"])
def test_from_numpy_equals_raw_loader(tmp_path, dtype):
    array = smooth_volume((5, 6, 7), np.dtype(dtype).newbyteorder("=")).astype(dtype)
    side = write_raw(array, str(tmp_path / "v.json"))
    expected = vnr.Volume.open(side)
    volume = vnr.Volume.from_numpy(array)
    assert volume.source_dtype == np.dtype(dtype).newbyteorder("=")
    assert volume.value_range == expected.value_range and volume.dims == (7, 6, 5)
    np.testing.assert_array_equal(volume.normalised, expected.normalised)
    # Fortran order (nx, ny, nz) is the same memory; other layouts are copied into C order.
    np.testing.assert_array_equal(vnr.Volume.from_numpy(array.T).normalised, expected.normalised)
    flipped = array[:, :, ::-1]
    np.testing.assert_array_equal(vnr.Volume.from_numpy(flipped).normalised,
                                  vnr.Volume.from_numpy(np.ascontiguousarray(flipped)).normalised)
    ranged = vnr.Volume.from_numpy(array, value_range=(0, None))
    assert ranged.value_range[0] == 0


def test_bad_input_raises(trained, tmp_path):
    model = trained["model"]
    for bad in (np.zeros((4, 4)), np.zeros((2, 2, 2, 2)), np.zeros((0, 3, 3))):
        with pytest.raises(ValueError, match="3-D array|at least one voxel"):
            vnr.Volume.from_numpy(bad)
    for dtype in (np.int64, np.complex64, np.bool_, np.float16):
        with pytest.raises(ValueError, match="unsupported dtype"):
            vnr.Volume.from_numpy(np.ones((3, 3, 3), dtype))
    nan = np.ones((3, 3, 3), np.float32)
    nan[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite|NaN"):
        vnr.train(nan, **TRAIN)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        model.sample(np.zeros((5, 2), np.float32))
    with pytest.raises(ValueError, match="float32 or float64"):
        model.sample(np.zeros((5, 3), np.int32))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        model.sample(np.array([[0.5, 0.5, np.inf]]))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        model.sample(np.array([[0.5, 1.5, 0.5]]))
    with pytest.raises(ValueError, match="shape"):
        model.decode(shape=(0, 4, 4))
    with pytest.raises(ValueError, match="device"):
        model.decode(device="tpu")
    with pytest.raises(ValueError, match="data type"):
        model.decode(dtype="complex")
    with pytest.raises(ValueError, match="config|preset|unknown"):
        vnr.train(trained["array"], config={"encoding": {"otype": "NoSuchEncoding"}}, steps=1)
    with pytest.raises(ValueError, match="sampler"):
        vnr.train(trained["array"], sampler="mmap", steps=1)
    with pytest.raises(ValueError, match="mode"):
        vnr.render(model, mode="xray", size=(8, 8))
    with pytest.raises(ValueError, match="camera"):
        vnr.render(model, camera={"eye": (1, 2, 3), "zoom": 2}, size=(8, 8))
    for bad_spp in ("many", 0):
        with pytest.raises(ValueError, match="spp"):
            vnr.render(model, spp=bad_spp, size=(8, 8))
    with pytest.raises(ValueError, match="max_spp"):
        vnr.render(model, size=(8, 8), max_spp=2)
    with pytest.raises(ValueError, match="shape"):
        vnr.metrics.psnr(np.zeros((3, 3, 3)), np.zeros((3, 3, 4)))
    for missing in (lambda: vnr.Model.load(str(tmp_path / "none.vnr")),
                    lambda: vnr.Volume.open(str(tmp_path / "none.json")),
                    lambda: vnr.train(trained["array"], config=str(tmp_path / "none.json")),
                    lambda: vnr.render(model, tf=str(tmp_path / "none_tf.json"), size=(8, 8))):
        with pytest.raises(FileNotFoundError, match="none"):
            missing()


def test_callback_stops_training(trained):
    seen = []

    def callback(step, loss, samples_per_second):
        seen.append((step, loss, samples_per_second))
        return step < 4

    model = vnr.train(trained["array"], config="small", steps=100, seed=1, device="cpu", callback=callback)
    assert [s for s, _, _ in seen] == [1, 2, 3, 4]
    assert all(np.isfinite(loss) and rate > 0 for _, loss, rate in seen)
    assert model.training["steps"] == 4

    def raising(step, loss, rate):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        vnr.train(trained["array"], config="small", steps=100, device="cpu", callback=raising)


def test_ctrl_c_returns_model(tmp_path):
    script = textwrap.dedent("""
        import sys, numpy as np, vnr
        array = np.random.default_rng(0).random((16, 16, 16), dtype=np.float32)
        def callback(step, loss, rate):
            if step == 1:
                print("started", flush=True)
        model = vnr.train(array, config="small", seconds=60, device="cpu", callback=callback)
        print("steps", model.training["steps"], model.decode().shape, flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ))
    assert proc.stdout.readline().strip() == "started"
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    steps = int(out.split()[1])
    assert 1 <= steps and "(16, 16, 16)" in out
    assert "interrupted" in err


def test_512_cubed_uint8_trains_and_decodes_within_memory_bound():
    """No hidden copy: peak RSS of train + decode stays under input + max(normalised, decoded) + model +
    256 MiB (bench/python_memory.py, the small config here for speed; docs/benchmarks.md: paper)."""
    script = os.path.join(os.path.dirname(__file__), "..", "..", "bench", "python_memory.py")
    r = subprocess.run([sys.executable, script, "--size", "512", "--steps", "2", "--config", "small"],
                       capture_output=True, text=True, env=dict(os.environ))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "within the bound" in r.stdout


def test_path_trains_like_the_array(trained):
    """vnr.train on a file path (the CLI's loader) and on the array of its values give one model."""
    from_path = vnr.train(trained["side"], **TRAIN)
    np.testing.assert_array_equal(from_path.decode(device="cpu"), trained["model"].decode(device="cpu"))


def test_train_series_equals_cli(tmp_path, cli):
    """vnr.train_series runs `vnr train --timesteps`'s library call: the same models and report rows."""
    frames = [smooth_volume(seed=k) for k in range(3)]
    for k, f in enumerate(frames):
        f.tofile(str(tmp_path / f"f{k}.raw"))
    side = tmp_path / "s.json"
    side.write_text(json.dumps({"file": [f"f{k}.raw" for k in range(3)], "dims": [16, 14, 12], "dtype": "uint8"}))
    cli("train", side, "--timesteps", "0,2", "-o", tmp_path / "cli", "--config", "small", "--steps", 30, "--seed",
        SEED, "--threads", THREADS, "--device", "cpu", "--no-ssim", "-q")
    rep = vnr.train_series(side, tmp_path / "py", "0,2", ssim=False, threads=THREADS, config="small", steps=30,
                           seed=SEED, device="cpu")
    cli_rep = json.loads((tmp_path / "cli" / "series.json").read_text())
    assert rep["complete"] and rep["timesteps"] == [0, 2] == cli_rep["timesteps"]
    assert json.loads((tmp_path / "py" / "series.json").read_text())["rows"] == rep["rows"]
    for row, cli_row in zip(rep["rows"], cli_rep["rows"]):
        assert row["timestep"] == cli_row["timestep"] and row["psnr"] == cli_row["psnr"]
        py_model, cli_model = vnr.Model.load(row["model"]), vnr.Model.load(cli_row["model"])
        np.testing.assert_array_equal(py_model.decode(device="cpu"), cli_model.decode(device="cpu"))
    with pytest.raises(Exception, match="switch_every needs continuous"):
        vnr.train_series(side, tmp_path / "bad", switch_every=5, config="small")
    with pytest.raises(Exception, match="unknown"):
        vnr.train_series(side, tmp_path / "bad", config="small", stepz=3)
    assert not (tmp_path / "bad").exists()


def test_stubs_match_the_compiled_signatures():
    """_vnr.pyi names every compiled function and method with the parameters pybind11 reports."""
    import ast
    import re
    stub_path = os.path.join(os.path.dirname(vnr.__file__), "_vnr.pyi")
    with open(stub_path) as f:
        tree = ast.parse(f.read())

    def params(fn):
        a = fn.args
        return [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs if p.arg != "self"]

    def compiled_params(obj):  # from pybind11's signature line, split at top-level commas
        first = obj.__doc__.splitlines()[0]
        inner, names, depth, part = first[first.index("(") + 1:first.rindex(")")], [], 0, ""
        for ch in inner + ",":
            depth += ch in "[(" and 1 or (ch in "])" and -1 or 0)
            if ch == "," and depth == 0:
                name = re.match(r"\s*(\w+)", part)
                if name and name.group(1) != "self":
                    names.append(name.group(1))
                part = ""
            else:
                part += ch
        return names

    checked = 0
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            assert params(node) == compiled_params(getattr(vnr._vnr, node.name)), node.name
            checked += 1
        elif isinstance(node, ast.ClassDef):
            cls = getattr(vnr._vnr, node.name)
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not any(
                        isinstance(d, ast.Name) and d.id == "property" for d in item.decorator_list):
                    assert params(item) == compiled_params(getattr(cls, item.name)), f"{node.name}.{item.name}"
                    checked += 1
                elif isinstance(item, ast.FunctionDef):
                    assert isinstance(getattr(cls, item.name), property), f"{node.name}.{item.name}"
                    checked += 1
    assert checked >= 25
