"""ParaView reader plugin for vnr neural volume models (.vnr).

Load it in ParaView with Tools > Manage Plugins > Load New (this file), or in pvpython with
``LoadPlugin("vnr_reader.py", ns=globals())``; the ``vnr`` Python module must be importable (set
PYTHONPATH to the directory that holds the ``vnr`` package before starting ParaView).

Opening a ``.vnr`` file decodes the model to vtkImageData: one float32 point array (``value`` by
default) in the volume's original units, so ParaView's volume rendering, slicing and contouring work
on it as on the original volume.

Geometry: the original volume of N voxels per axis is placed as ParaView places a raw volume with
spacing 1, its voxel centres at 0 .. N-1. vnr decodes a resolution of M points per axis at cell
centres, point j at (j + 0.5) / M of the box (docs/semantics.md B.2, as ``vnr decode --dims``), so
the reader uses spacing N / M and origin (N / M - 1) / 2: every point sits where its value was
sampled, the cells always cover the original's box [-0.5, N - 0.5], and at the model's own
resolution the origin is 0 and the spacing 1.
"""

import os

import numpy
from paraview.util.vtkAlgorithm import VTKPythonAlgorithmBase, smdomain, smhint, smproperty, smproxy
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkOutputWindow
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

try:
    import vnr
except ImportError as error:
    raise ImportError(
        "vnr ParaView reader: cannot import the vnr Python module (%s). Set PYTHONPATH to the directory "
        "that holds the vnr package (build/python in a build tree, or the site-packages directory that "
        "`cmake --install` printed) before starting ParaView or pvpython." % error
    ) from None

DEVICES = ("auto", "cpu", "cuda")


def output_geometry(model_dims, requested):
    """(dims, spacing, origin) of the output, all in x, y, z order; requested 0 on an axis = the model's."""
    if len(requested) != 3 or any(int(r) < 0 for r in requested):
        raise ValueError("output dimensions must be 3 integers >= 0 (0 = the model's own), got %s" % (list(requested),))
    dims = [int(r) if int(r) > 0 else int(n) for r, n in zip(requested, model_dims)]
    spacing = [float(n) / m for n, m in zip(model_dims, dims)]
    origin = [(s - 1.0) / 2.0 for s in spacing]
    return dims, spacing, origin


def report_error(message):
    vtkOutputWindow.GetInstance().DisplayErrorText("vnr reader: %s\n" % message)


@smproxy.reader(name="VnrModelReader", label="vnr model reader", extensions="vnr",
                file_description="vnr neural volume model")
class VnrModelReader(VTKPythonAlgorithmBase):
    """Decodes a vnr model to vtkImageData (see the module docstring for the geometry)."""

    def __init__(self):
        VTKPythonAlgorithmBase.__init__(self, nInputPorts=0, nOutputPorts=1, outputType="vtkImageData")
        self._file_name = None
        self._dims = [0, 0, 0]
        self._device = 0
        self._array_name = "value"
        self._model = None
        self._model_key = None
        self._failed = False

    @smproperty.stringvector(name="FileName", panel_visibility="never")
    @smdomain.filelist()
    @smhint.filechooser(extensions="vnr", file_description="vnr neural volume model")
    def SetFileName(self, name):
        if name != self._file_name:
            self._file_name = name
            self.Modified()

    @smproperty.intvector(name="OutputDimensions", label="Output Dimensions", default_values=[0, 0, 0])
    @smdomain.xml('<Documentation>Points per axis x, y, z of the decoded volume; 0 = the model\'s own '
                  'resolution.</Documentation>')
    def SetOutputDimensions(self, x, y, z):
        if [x, y, z] != self._dims:
            self._dims = [x, y, z]
            self.Modified()

    @smproperty.intvector(name="Device", label="Decode Device", default_values=[0])
    @smdomain.xml('<EnumerationDomain name="enum">' +
                  "".join('<Entry value="%d" text="%s"/>' % (i, d) for i, d in enumerate(DEVICES)) +
                  '</EnumerationDomain><Documentation>Where the model is decoded: auto (the GPU when vnr '
                  'was built with CUDA and one is visible, else the CPU), cpu or cuda.</Documentation>')
    def SetDevice(self, index):
        if index != self._device:
            self._device = index
            self.Modified()

    @smproperty.stringvector(name="ArrayName", label="Array Name", default_values="value")
    def SetArrayName(self, name):
        if name != self._array_name:
            self._array_name = name
            self.Modified()

    def _load_model(self):
        """The model of FileName, loaded once per file version (RequestInformation needs only its dims)."""
        if not self._file_name:
            raise ValueError("no file name given")
        try:
            stat = os.stat(self._file_name)
        except OSError as error:
            raise FileNotFoundError("cannot open '%s': %s" % (self._file_name, error.strerror)) from error
        key = (self._file_name, stat.st_mtime_ns, stat.st_size)
        if key != self._model_key:
            self._model, self._model_key = None, None
            self._model = vnr.Model.load(self._file_name)
            self._model_key = key
        return self._model

    def _geometry(self):
        model = self._load_model()
        return model, output_geometry(model.dims, self._dims)  # model.dims: x, y, z

    # A failure is reported once, as one line, and leaves an empty image: returning 0 instead would add
    # the executive's own multi-line error (and RequestData would repeat the first).
    def RequestInformation(self, request, inInfoVec, outInfoVec):
        info = outInfoVec.GetInformationObject(0)
        try:
            _, (dims, spacing, origin) = self._geometry()
            self._failed = False
        except Exception as error:
            report_error(error)
            self._failed = True
            info.Set(vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT(), 0, -1, 0, -1, 0, -1)
            return 1
        info.Set(vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT(), 0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1)
        info.Set(vtkImageData.SPACING(), *spacing)
        info.Set(vtkImageData.ORIGIN(), *origin)
        return 1

    def RequestData(self, request, inInfoVec, outInfoVec):
        output = vtkImageData.GetData(outInfoVec, 0)
        output.Initialize()
        if self._failed:
            return 1
        try:
            model, (dims, spacing, origin) = self._geometry()
            device = DEVICES[self._device] if 0 <= self._device < len(DEVICES) else str(self._device)
            values = decode(model, dims, device)
        except Exception as error:
            report_error(error)
            return 1
        output.SetExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1)
        output.SetSpacing(*spacing)
        output.SetOrigin(*origin)
        # (nz, ny, nx) C order is x fastest, VTK's point order: the array is shared, not copied.
        array = numpy_support.numpy_to_vtk(values.reshape(-1), deep=False)
        array.SetName(self._array_name or "value")
        output.GetPointData().SetScalars(array)
        return 1


def decode(model, dims, device):
    """The model decoded at dims (x, y, z) as a C-contiguous float32 (nz, ny, nx) array in original units."""
    values = model.decode(shape=(dims[2], dims[1], dims[0]), dtype="float32", device=device)
    values = numpy.ascontiguousarray(values, dtype=numpy.float32)
    if values.shape != (dims[2], dims[1], dims[0]):
        raise ValueError("decode returned shape %s, expected %s" % (values.shape, (dims[2], dims[1], dims[0])))
    return values
