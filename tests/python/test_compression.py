"""Compact models and the error bound through the Python module: vnr.train's target_ratio, target_psnr and
max_error / max_rel_error, against the CLI on the same data and against the original voxels."""
import json
import os

import pytest

np = pytest.importorskip("numpy", reason="numpy (Debian python3-numpy) is needed for the vnr module's tests")
vnr = pytest.importorskip("vnr", reason="the vnr module is not built (VNR_PYTHON=ON) or not on PYTHONPATH")

from conftest import read_raw_json, smooth_volume, write_raw  # noqa: E402

TRAIN = dict(config="small", steps=60, seed=3, device="cpu", threads=2)
SHAPE = (24, 28, 32)


def test_max_error_holds_at_every_voxel_of_decode(tmp_path):
    array = smooth_volume(SHAPE, "float32", seed=4)
    bound = 0.5  # data units; the range is about 100
    model = vnr.train(array, max_error=bound, **TRAIN)
    decoded = model.decode(dtype="source", device="cpu")
    assert np.abs(decoded.astype(np.float64) - array).max() <= bound
    # Without the residuals the network alone is far outside the bound: they are what holds it.
    plain = vnr.train(array, **TRAIN)
    assert np.abs(plain.decode(dtype="source", device="cpu").astype(np.float64) - array).max() > 4 * bound
    # Saved and loaded (and decoded by the CLI), the bound still holds.
    path = str(tmp_path / "bounded.vnr")
    model.save(path)
    loaded = vnr.Model.load(path)
    np.testing.assert_array_equal(loaded.decode(dtype="source", device="cpu"), decoded)


def test_max_rel_error_is_a_fraction_of_the_range():
    array = smooth_volume(SHAPE, "uint8", seed=5)
    model = vnr.train(array, max_rel_error=1e-2, **TRAIN)
    span = float(array.max()) - float(array.min())
    assert model.value_range == (float(array.min()), float(array.max()))
    decoded = model.decode(device="cpu")  # float32 in data units
    assert np.abs(decoded.astype(np.float64) - array).max() <= 1e-2 * span


def test_target_ratio_file_equals_the_cli(tmp_path, cli):
    array = smooth_volume(SHAPE, "float32", seed=6)
    side = write_raw(array, str(tmp_path / "v.json"))
    cli("train", side, "-o", tmp_path / "cli.vnr", "--config", "small", "--steps", 60, "--seed", 3, "--threads", 2,
        "--device", "cpu", "--target-ratio", 16, "-q")
    model = vnr.train(side, target_ratio=16, **TRAIN)
    path = str(tmp_path / "py.vnr")
    model.save(path)
    target = array.nbytes / 16
    assert 0.95 * target <= os.path.getsize(path) <= target
    cli("decode", tmp_path / "cli.vnr", "-o", tmp_path / "cli.raw", "--device", "cpu", "--threads", 2, "-q")
    np.testing.assert_array_equal(model.decode(device="cpu"), read_raw_json(str(tmp_path / "cli.json")))


def test_rate_weight_equals_the_cli(tmp_path, cli):
    array = smooth_volume(SHAPE, "float32", seed=9)
    side = write_raw(array, str(tmp_path / "v.json"))
    cli("train", side, "-o", tmp_path / "cli.vnr", "--config", "small", "--steps", 60, "--seed", 3, "--threads", 2,
        "--device", "cpu", "--target-ratio", 16, "--rate-weight", 1, "-q")
    model = vnr.train(side, target_ratio=16, rate_weight=1.0, **TRAIN)
    plain = vnr.train(side, target_ratio=16, **TRAIN)
    cli("decode", tmp_path / "cli.vnr", "-o", tmp_path / "cli.raw", "--device", "cpu", "--threads", 2, "-q")
    np.testing.assert_array_equal(model.decode(device="cpu"), read_raw_json(str(tmp_path / "cli.json")))
    assert not np.array_equal(model.decode(device="cpu"), plain.decode(device="cpu"))  # the term changed the run


def test_learn_steps_equals_the_cli(tmp_path, cli):
    array = smooth_volume(SHAPE, "float32", seed=9)
    side = write_raw(array, str(tmp_path / "v.json"))
    cli("train", side, "-o", tmp_path / "cli.vnr", "--config", "small", "--steps", 60, "--seed", 3, "--threads", 2,
        "--device", "cpu", "--target-ratio", 16, "--residuals", "off", "--learn-steps", "-q")
    model = vnr.train(side, target_ratio=16, residuals="off", learn_steps=True, **TRAIN)
    plain = vnr.train(side, target_ratio=16, residuals="off", **TRAIN)
    cli("decode", tmp_path / "cli.vnr", "-o", tmp_path / "cli.raw", "--device", "cpu", "--threads", 2, "-q")
    np.testing.assert_array_equal(model.decode(device="cpu"), read_raw_json(str(tmp_path / "cli.json")))
    assert not np.array_equal(model.decode(device="cpu"), plain.decode(device="cpu"))  # the steps moved


def test_target_psnr_search_reaches_the_target(tmp_path):
    array = smooth_volume(SHAPE, "float32", seed=7)
    model = vnr.train(array, target_psnr=26, **dict(TRAIN, steps=150))
    path = str(tmp_path / "m.vnr")
    model.save(path)
    decoded = model.decode(device="cpu").astype(np.float64)
    span = float(array.max()) - float(array.min())
    psnr = 20 * np.log10(span) - 10 * np.log10(np.mean((decoded - array) ** 2))
    assert psnr >= 25.5  # the held-back estimate chose it; the full volume agrees within 0.5 dB
    assert os.path.getsize(path) <= array.nbytes / 8  # far smaller than the volume


def test_target_psnr_out_of_reach_warns_and_returns_the_largest_model():
    array = smooth_volume(SHAPE, "float32", seed=8)
    with pytest.warns(RuntimeWarning, match="target_psnr=80"):
        model = vnr.train(array, target_psnr=80, **TRAIN)
    assert model.decode(device="cpu").shape == array.shape


def test_bad_compression_options_raise():
    array = smooth_volume((8, 8, 8), "float32")
    with pytest.raises(ValueError, match="target_psnr must be positive"):
        vnr.train(array, target_psnr=float("nan"), **TRAIN)
    with pytest.raises(ValueError, match="qat_fraction"):
        vnr.train(array, target_ratio=8, qat_fraction=2.0, **TRAIN)
    with pytest.raises(ValueError, match="rate_weight"):
        vnr.train(array, target_ratio=8, rate_weight=-1.0, **TRAIN)


def test_residuals_fill_a_target_ratio_as_the_cli(tmp_path, cli):
    # 1 MiB of float32 at 8x: the file has bits to spare, so residuals="auto" (the default) spends most of it on
    # residuals beside a smaller network; decode() applies them, and equals the CLI's file; "off" does not.
    array = smooth_volume((64, 64, 64), "float32", seed=7)
    side = write_raw(array, str(tmp_path / "v.json"))
    cli("train", side, "-o", tmp_path / "cli.vnr", "--config", "small", "--steps", 20, "--seed", 3, "--threads", 2,
        "--device", "cpu", "--target-ratio", 8, "-q")
    model = vnr.train(side, target_ratio=8, **dict(TRAIN, steps=20))
    path = str(tmp_path / "py.vnr")
    model.save(path)
    target = array.nbytes / 8
    assert 0.95 * target <= os.path.getsize(path) <= target
    cli("decode", tmp_path / "cli.vnr", "-o", tmp_path / "cli.raw", "--device", "cpu", "--threads", 2, "-q")
    decoded = model.decode(device="cpu")
    np.testing.assert_array_equal(decoded, read_raw_json(str(tmp_path / "cli.json")))
    off = vnr.train(side, target_ratio=8, residuals="off", **dict(TRAIN, steps=20))
    err = np.abs(decoded.astype(np.float64) - array).max()
    assert err < 0.5 * np.abs(off.decode(device="cpu").astype(np.float64) - array).max()
    with pytest.raises(Exception, match="residuals must be auto or off"):
        vnr.train(side, target_ratio=8, residuals="some", **dict(TRAIN, steps=20))
