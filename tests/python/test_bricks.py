"""Multi-brick models (`vnr train --bricks`) in the Python module: opened like one model, decoding as
`vnr decode` does, and refused by save()."""
import json

import pytest

np = pytest.importorskip("numpy", reason="numpy (Debian python3-numpy) is needed for the vnr module's tests")
vnr = pytest.importorskip("vnr", reason="the vnr module is not built (VNR_PYTHON=ON) or not on PYTHONPATH")

from conftest import read_raw_json, smooth_volume, write_raw  # noqa: E402


def test_multi_brick_model_opens_like_one_model(tmp_path, cli):
    side = write_raw(smooth_volume(), str(tmp_path / "vol.json"))
    model_dir = tmp_path / "bricks"
    cli("train", side, "-o", model_dir, "--config", "small", "--steps", 20, "--bricks", "2,1,1", "--ghost", 2,
        "--threads", 2, "--device", "cpu", "-q", "--no-ssim")
    cli("decode", model_dir, "-o", tmp_path / "dec.raw", "--threads", 2, "--device", "cpu", "-q")
    info = json.loads(cli("info", "--json", model_dir).stdout)
    model = vnr.Model.load(str(model_dir))
    assert model.dims == (16, 14, 12)
    assert model.n_params == info["n_params"]
    assert model.compression_ratio == pytest.approx(info["compression_ratio"])
    np.testing.assert_array_equal(model.decode(device="cpu"), read_raw_json(str(tmp_path / "dec.json")))
    with pytest.raises(ValueError, match="multi-brick"):
        model.save(str(tmp_path / "one.vnr"))
