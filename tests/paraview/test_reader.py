"""pvpython test of the vnr ParaView reader (ctest: paraview_reader).

Trains a small model with the CLI on a generated volume, reads it through the plugin at the model's
resolution and at two others, and compares every value with what `vnr decode` (same dims, CPU) writes:
they must be bit-identical (both decode the same model with the same library code in float32). Also
checks the geometry, that RequestInformation reports the extent without decoding, one clear error for
a bad file and for a missing module, and that Contour and Slice produce the surfaces they should.

Run: VNR_CLI=build/vnr PYTHONPATH=build/python pvpython tests/paraview/test_reader.py
"""

import importlib.util
import inspect
import json
import os
import subprocess
import sys
import tempfile

try:
    from paraview import servermanager
    from paraview import simple
except ImportError:
    print("SKIPPED: run this test with pvpython (ParaView's Python), which was not found")
    sys.exit(77)

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

# Debian 12's ParaView 5.11 plugin loader still imports inspect.getargspec, gone in Python 3.11.
if not hasattr(inspect, "getargspec"):
    inspect.getargspec = inspect.getfullargspec

HERE = os.path.dirname(os.path.abspath(__file__))
PLUGIN = os.environ.get("VNR_PARAVIEW_PLUGIN", os.path.join(HERE, "..", "..", "src", "paraview", "vnr_reader.py"))
CLI = os.environ["VNR_CLI"]
MODEL_DIMS = (20, 16, 12)  # x, y, z: all different, so a swapped axis shows


def run_cli(*args):
    subprocess.run([CLI, *args], check=True, stdout=subprocess.DEVNULL)


def cli_decode(model, out_dir, dims=None):
    """`vnr decode` on the CPU -> (nz, ny, nx) float32 array, read from the raw file and its sidecar."""
    name = "decoded_%s" % ("own" if dims is None else "x".join(map(str, dims)))
    raw = os.path.join(out_dir, name + ".raw")
    size = [] if dims is None else ["--dims", ",".join(map(str, dims))]
    run_cli("decode", model, "-o", raw, "--device", "cpu", "-q", *size)
    with open(os.path.join(out_dir, name + ".json")) as f:
        meta = json.load(f)
    assert meta["dtype"] == "float32" and meta["byte_order"] == "little", meta
    nx, ny, nz = meta["dims"]
    return np.fromfile(raw, dtype="<f4").reshape(nz, ny, nx)


def read_image(reader):
    reader.UpdatePipeline()
    image = servermanager.Fetch(reader)
    values = numpy_support.vtk_to_numpy(image.GetPointData().GetArray("value"))
    nx, ny, nz = image.GetDimensions()
    return image, values.reshape(nz, ny, nx)


def check_resolution(reader, expected, dims):
    image, values = read_image(reader)
    assert image.GetDimensions() == tuple(dims), (image.GetDimensions(), dims)
    spacing = [n / m for n, m in zip(MODEL_DIMS, dims)]
    assert np.allclose(image.GetSpacing(), spacing, rtol=0, atol=1e-12), image.GetSpacing()
    assert np.allclose(image.GetOrigin(), [(s - 1) / 2 for s in spacing], rtol=0, atol=1e-12), image.GetOrigin()
    assert image.GetPointData().GetScalars().GetName() == "value"
    assert values.dtype == np.float32
    differ = np.count_nonzero(values != expected)
    assert differ == 0, "%d of %d values differ from vnr decode at %s" % (differ, values.size, dims)
    print("reader == vnr decode at %s: all %d values bit-identical" % ("x".join(map(str, dims)), values.size))
    return image


def check_information_without_decode(model):
    """The algorithm alone: UpdateInformation reports WHOLE_EXTENT and does not decode."""
    spec = importlib.util.spec_from_file_location("vnr_reader_under_test", PLUGIN)
    plugin = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plugin)
    decodes = []
    real_decode = plugin.decode
    plugin.decode = lambda *args: decodes.append(args) or real_decode(*args)
    algorithm = plugin.VnrModelReader()
    algorithm.SetFileName(model)
    algorithm.SetOutputDimensions(7, 0, 5)
    algorithm.UpdateInformation()
    extent = algorithm.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT())
    assert tuple(extent) == (0, 6, 0, MODEL_DIMS[1] - 1, 0, 4), extent
    assert not decodes, "RequestInformation decoded the model"
    algorithm.Update()
    assert len(decodes) == 1 and algorithm.GetOutputDataObject(0).GetNumberOfPoints() == 7 * MODEL_DIMS[1] * 5
    print("RequestInformation: whole extent %s without decoding" % (tuple(extent),))
    return plugin


def check_bad_file(plugin, work):
    bad = os.path.join(work, "bad.vnr")
    with open(bad, "w") as f:
        f.write("not a model")
    messages = vtkStringOutputWindow()
    previous = vtkOutputWindow.GetInstance()
    vtkOutputWindow.SetInstance(messages)
    try:
        algorithm = plugin.VnrModelReader()
        algorithm.SetFileName(bad)
        algorithm.Update()
    finally:
        vtkOutputWindow.SetInstance(previous)
    text = messages.GetOutput()
    assert text.count("vnr reader: ") == 1 and "bad.vnr" in text and "vnr model file" in text, text
    assert "Traceback" not in text and "returned failure" not in text, text
    assert algorithm.GetOutputDataObject(0).GetNumberOfPoints() == 0
    print("bad file: %s" % text.strip().splitlines()[0])


def check_missing_module(work):
    """The plugin's ImportError names PYTHONPATH when the vnr module cannot be imported."""
    script = os.path.join(work, "load_without_vnr.py")
    with open(script, "w") as f:
        f.write("import inspect, sys\n"
                "try:\n    import vnr\n    print('VNR_IMPORTABLE')\n    sys.exit(0)\nexcept ImportError:\n    pass\n"
                "if not hasattr(inspect, 'getargspec'): inspect.getargspec = inspect.getfullargspec\n"
                "from paraview.simple import LoadPlugin\nLoadPlugin(%r, ns=globals())\n" % PLUGIN)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    result = subprocess.run([os.environ.get("VNR_PVPYTHON", "pvpython"), script], env=env, capture_output=True,
                            text=True, timeout=120)
    output = result.stdout + result.stderr
    if "VNR_IMPORTABLE" in output:
        print("missing module: skipped (vnr is importable without PYTHONPATH)")
        return
    assert "cannot import the vnr Python module" in output and "PYTHONPATH" in output, output
    print("missing module: the plugin says to set PYTHONPATH")


def check_filters(reader, values):
    """Contour at the middle of the range and a z-slice through the middle: non-empty, and where they belong."""
    iso = float(0.5 * (values.min() + values.max()))
    contour = simple.Contour(Input=reader, ContourBy=["POINTS", "value"], Isosurfaces=[iso], ComputeScalars=1)
    surface = servermanager.Fetch(contour)
    assert surface.GetNumberOfCells() > 0, "empty contour"
    on_surface = numpy_support.vtk_to_numpy(surface.GetPointData().GetArray("value"))
    assert np.allclose(on_surface, iso, rtol=0, atol=1e-5 * max(1.0, abs(iso))), (on_surface.min(), on_surface.max())
    z = (MODEL_DIMS[2] - 1) / 2.0
    cut = simple.Slice(Input=reader, SliceType="Plane")
    cut.SliceType.Origin = [(MODEL_DIMS[0] - 1) / 2.0, (MODEL_DIMS[1] - 1) / 2.0, z]
    cut.SliceType.Normal = [0.0, 0.0, 1.0]
    plane = servermanager.Fetch(cut)
    assert plane.GetNumberOfCells() > 0, "empty slice"
    points = numpy_support.vtk_to_numpy(plane.GetPoints().GetData())
    assert np.allclose(points[:, 2], z), "slice points off the plane"
    print("contour at %.4g: %d triangles; slice z=%.1f: %d cells" % (iso, surface.GetNumberOfCells(), z,
                                                                     plane.GetNumberOfCells()))


def main():
    simple.LoadPlugin(PLUGIN, ns=globals())
    with tempfile.TemporaryDirectory(prefix="vnr_paraview_") as work:
        volume, model = os.path.join(work, "ml.json"), os.path.join(work, "ml.vnr")
        run_cli("synth", "marschner-lobb", "--dims", ",".join(map(str, MODEL_DIMS)), "-o", volume)
        run_cli("train", volume, "-o", model, "--config", "small", "--steps", "40", "--seed", "3", "-q")
        reader = simple.OpenDataFile(model)  # picks the reader by the .vnr extension
        assert reader.GetXMLName() == "VnrModelReader", reader.GetXMLName()
        reader.DecodeDevice = "cpu"
        image = check_resolution(reader, cli_decode(model, work), MODEL_DIMS)
        for dims in [(2 * MODEL_DIMS[0], MODEL_DIMS[1], MODEL_DIMS[2]), (9, 7, 5)]:
            reader.OutputDimensions = [dims[0], 0 if dims[1] == MODEL_DIMS[1] else dims[1], dims[2]]
            check_resolution(reader, cli_decode(model, work, dims), dims)
        reader.OutputDimensions = [0, 0, 0]
        image, values = read_image(reader)
        check_filters(reader, values)
        plugin = check_information_without_decode(model)
        check_bad_file(plugin, work)
        check_missing_module(work)
    print("paraview_reader: all checks passed")


if __name__ == "__main__":
    main()
