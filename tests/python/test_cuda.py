"""The vnr module's device="cuda" paths against its CPU paths: decode, sample and render of one model (also
from the brick cache), and training on the GPU. The GPU's MLP runs in half precision, so values agree
within 2e-2 of the value range and images above 35 dB. Without a CUDA device (or a build without CUDA)
every test skips, saying why -- unless VNR_REQUIRE_CUDA=1 (bench/gpu_python.sh on a GPU machine), where a
module that does not load or a device that fails is a failure, not a skip."""
import os

import pytest

REQUIRE = os.environ.get("VNR_REQUIRE_CUDA") == "1"
np = pytest.importorskip("numpy", reason="numpy (Debian python3-numpy) is needed for the vnr module's tests")
if REQUIRE:
    import vnr  # noqa: E402  (an import error fails the run)
else:
    vnr = pytest.importorskip("vnr", reason="the vnr module is not built (VNR_PYTHON=ON) or not on PYTHONPATH")

from conftest import smooth_volume  # noqa: E402


@pytest.fixture(scope="module")
def model():
    m = vnr.train(smooth_volume((24, 20, 16)), config="small", steps=200, seed=3, device="cpu", threads=2)
    try:
        m.sample(np.zeros((1, 3), np.float32), device="cuda")
    except (RuntimeError, ValueError) as e:
        if REQUIRE:
            pytest.fail(f"VNR_REQUIRE_CUDA=1 and the GPU failed: {e}")
        pytest.skip(f"no CUDA device: {e}")
    return m


def image_psnr(a, b):
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return 200.0 if mse == 0 else 10 * np.log10(1.0 / mse)


def test_decode_and_sample_on_cuda_match_the_cpu(model):
    lo, hi = model.value_range
    tol = 2e-2 * (hi - lo)
    for shape in (None, (13, 9, 7)):
        cpu = model.decode(shape=shape, device="cpu")
        gpu = model.decode(shape=shape, device="cuda")
        assert gpu.shape == cpu.shape and gpu.dtype == cpu.dtype
        assert np.max(np.abs(gpu - cpu)) < tol
    pts = np.random.default_rng(1).random((5000, 3), dtype=np.float32)
    assert np.max(np.abs(model.sample(pts, device="cuda") - model.sample(pts, device="cpu"))) < tol


def test_render_on_cuda_matches_the_cpu(model):
    for mode in ("raymarch", "shadow"):
        cpu = vnr.render(model, size=(96, 64), mode=mode, spp=4, device="cpu")
        gpu = vnr.render(model, size=(96, 64), mode=mode, spp=4, device="cuda")
        assert gpu.shape == cpu.shape
        assert image_psnr(gpu, cpu) > 35.0, mode


def test_render_from_the_brick_cache_on_cuda_matches_the_cpu(model):
    # the GPU's copy of the cache, at the model's dims and at a resolution 8x finer (any size)
    for dims in (None, (192, 160, 128)):
        kw = {} if dims is None else {"cache_dims": dims}
        cpu = vnr.render(model, size=(96, 64), spp=4, device="cpu", strategy="cache", **kw)
        gpu = vnr.render(model, size=(96, 64), spp=4, device="cuda", strategy="cache", **kw)
        assert image_psnr(gpu, cpu) > 35.0, dims


def test_training_on_cuda_reaches_the_cpu_quality(model):
    array = smooth_volume((24, 20, 16))
    gpu = vnr.train(array, config="small", steps=300, seed=3, device="cuda")
    cpu = vnr.train(array, config="small", steps=300, seed=3, device="cpu", threads=2)
    truth = array.astype(np.float32)
    quality = {name: vnr.metrics.psnr(truth, m.decode(device="cpu"), value_range=(0, 255))
               for name, m in (("cuda", gpu), ("cpu", cpu))}
    print(f"300 steps, small config: PSNR {quality['cuda']:.2f} dB on the GPU, {quality['cpu']:.2f} on the CPU")
    assert quality["cuda"] > quality["cpu"] - 1.5
