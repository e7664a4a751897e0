"""Makes docs/images/paraview_bonsai.png: a vnr model in ParaView, volume rendered and contoured + sliced.

    PYTHONPATH=build/python xvfb-run -a pvpython scripts/paraview_screenshot.py MODEL.vnr OUT.png

(Debian's ParaView renders through X only, hence xvfb-run.)
"""

import inspect
import os
import sys

# Debian 12's ParaView 5.11 plugin loader still imports inspect.getargspec, gone in Python 3.11.
if not hasattr(inspect, "getargspec"):
    inspect.getargspec = inspect.getfullargspec

from paraview import simple  # noqa: E402

PLUGIN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src", "paraview", "vnr_reader.py")


def camera(view, focus, size):
    view.CameraFocalPoint = focus
    view.CameraPosition = [focus[0] + 1.5 * size, focus[1] + 0.7 * size, focus[2] + 2.2 * size]
    view.CameraViewUp = [0, 1, 0]  # the bonsai grows along +y
    view.CameraViewAngle = 30


def show_volume(reader, view, lut):
    volume = simple.Show(reader, view)
    volume.SetRepresentationType("Volume")
    simple.ColorBy(volume, ("POINTS", "value"))
    volume.LookupTable = lut
    opacity = simple.GetOpacityTransferFunction("value")
    opacity.Points = [0, 0, 0.5, 0, 35, 0, 0.5, 0, 60, 0.08, 0.5, 0, 255, 0.9, 0.5, 0]


def show_contour(reader, view):
    surface = simple.Show(simple.Contour(Input=reader, ContourBy=["POINTS", "value"], Isosurfaces=[70.0]), view)
    simple.ColorBy(surface, None)
    surface.DiffuseColor = [0.85, 0.75, 0.55]


def show_slice(reader, view, lut, focus):
    """A z-slice through the trunk, seen head-on, with its iso-lines at the contour's value."""
    cut = simple.Slice(Input=reader, SliceType="Plane")
    cut.SliceType.Origin = focus
    cut.SliceType.Normal = [0, 0, 1]
    plane = simple.Show(cut, view)
    simple.ColorBy(plane, ("POINTS", "value"))
    plane.LookupTable = lut
    lines = simple.Show(simple.Contour(Input=cut, ContourBy=["POINTS", "value"], Isosurfaces=[70.0]), view)
    simple.ColorBy(lines, None)
    lines.DiffuseColor = [1.0, 1.0, 1.0]
    lines.LineWidth = 1.5
    bar = simple.GetScalarBar(lut, view)
    bar.Title, bar.ComponentTitle = "value", ""
    bar.TitleColor = bar.LabelColor = [0.1, 0.1, 0.1]
    bar.HorizontalTitle = 1
    bar.RangeLabelFormat = "%.0f"
    bar.WindowLocation = "Any Location"
    bar.Position = [0.72, 0.08]
    plane.SetScalarBarVisibility(view, True)


def main(model, out):
    simple.LoadPlugin(PLUGIN, ns=globals())
    reader = simple.OpenDataFile(model)
    reader.UpdatePipeline()
    nx, ny, nz = [b + 1 for b in reader.GetDataInformation().GetExtent()[1::2]]
    focus = [(nx - 1) / 2.0, (ny - 1) / 2.0, (nz - 1) / 2.0]
    size = max(nx, ny, nz)
    lut = simple.GetColorTransferFunction("value")
    lut.ApplyPreset("Viridis (matplotlib)", True)
    lut.AutomaticRescaleRangeMode = "Never"

    layout = simple.CreateLayout("vnr")
    layout.SplitHorizontal(0, 1.0 / 3.0)
    layout.SplitHorizontal(2, 0.5)
    views = [simple.CreateView("RenderView") for _ in range(3)]
    for cell, view in zip((1, 5, 6), views):
        layout.AssignView(cell, view)
        view.Background = [1, 1, 1]
        view.OrientationAxesVisibility = 0
        if view.GetProperty("UseColorPaletteForBackground") is not None:
            view.UseColorPaletteForBackground = 0
        if cell != 6:
            simple.Show(simple.Outline(Input=reader), view).DiffuseColor = [0.6, 0.6, 0.6]
    for view, title in zip(views, ("volume rendering", "contour at 70", "slice z = %g" % focus[2])):
        label = simple.Show(simple.Text(Text=title), view)
        label.WindowLocation, label.FontSize, label.Color = "Upper Center", 20, [0.1, 0.1, 0.1]
    show_volume(reader, views[0], lut)
    show_contour(reader, views[1])
    show_slice(reader, views[2], lut, focus)
    lut.RescaleTransferFunction(0.0, 255.0)
    for view in views[:2]:
        camera(view, focus, size)
    head_on = [focus[0] + 0.24 * size, focus[1], focus[2]]  # the slice left of centre, the colour bar right
    views[2].CameraFocalPoint = head_on
    views[2].CameraPosition = [head_on[0], head_on[1], head_on[2] + 3.1 * size]
    views[2].CameraViewUp = [0, 1, 0]
    simple.SaveScreenshot(out, layout, ImageResolution=[1500, 560], CompressionLevel="9")
    print("wrote", out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
