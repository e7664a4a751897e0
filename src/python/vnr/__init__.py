"""vnr: volumetric neural representations (hash-grid encoding + tiny MLP) from Python.

numpy in, numpy out::

    import numpy as np, vnr
    model = vnr.train(array, steps=500)          # array: (nz, ny, nx), any numeric dtype
    decoded = model.decode()                     # (nz, ny, nx) float32, original units
    image = vnr.render(model, camera=vnr.Camera.orbit(30, 20), tf="cool-warm")  # (H, W, 4)

Axis convention: an array of shape (nz, ny, nx) in C order has x fastest in memory, which is vnr's
layout (no copy); (nx, ny, nz) in Fortran order is the same memory (no copy either); any other layout
is copied once. Arrays vnr returns are (nz, ny, nx) in C order: a[z, y, x].

Errors from vnr raise ValueError with the CLI's messages; a missing file raises FileNotFoundError.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Optional, Sequence, Tuple, Union

from ._vnr import Model, Volume, __version__, num_threads, set_num_threads, train, train_series
from ._vnr import _render
from . import metrics

__all__ = ["Camera", "Model", "TransferFunction", "Volume", "metrics", "num_threads", "render",
           "set_num_threads", "train", "train_series", "__version__"]


@dataclass
class Camera:
    """A pinhole camera in vnr's world space: the volume box spans [0, dims] (voxel units).

    Either eye/center (with up, fovy) or an orbit around the volume: Camera.orbit(azimuth, elevation),
    degrees, azimuth about +y with 0 looking from +z, at the distance `vnr render --orbit` uses.
    """

    eye: Optional[Sequence[float]] = None
    center: Optional[Sequence[float]] = None
    up: Sequence[float] = (0.0, 1.0, 0.0)
    fovy: float = 30.0
    azimuth: Optional[float] = None
    elevation: float = 0.0

    @staticmethod
    def orbit(azimuth: float, elevation: float = 0.0, fovy: float = 30.0) -> "Camera":
        """The camera of `vnr render --orbit AZIMUTH,ELEVATION --fovy FOVY`."""
        return Camera(azimuth=azimuth, elevation=elevation, fovy=fovy)


@dataclass
class TransferFunction:
    """A transfer function given as control points over the normalised value range [0, 1]:
    colors [(x, r, g, b), ...] and opacities [(x, alpha), ...] (alpha per voxel step), passed as
    vnr's transfer-function JSON. A preset name, JSON text, a dict or a file path work as well."""

    colors: Sequence[Sequence[float]]
    opacities: Sequence[Sequence[float]]
    resolution: int = 1024

    def to_json(self) -> str:
        """vnr's transfer-function JSON ({"colors", "opacities", "resolution"}), what `vnr render --tf FILE`
        reads."""
        return json.dumps({"colors": [[float(v) for v in c] for c in self.colors],
                           "opacities": [[float(v) for v in o] for o in self.opacities],
                           "resolution": int(self.resolution)})


def _camera_args(camera: Union[None, Camera, dict, Tuple[float, float]]) -> dict:
    if camera is None:
        return dict(eye=None, center=None, up=(0.0, 1.0, 0.0), fovy=30.0, orbit=None)
    if isinstance(camera, (tuple, list)) and len(camera) in (1, 2):
        camera = Camera.orbit(*camera)
    if isinstance(camera, dict):
        known = {"eye", "center", "up", "fovy", "azimuth", "elevation", "orbit"}
        unknown = set(camera) - known
        if unknown:
            raise ValueError(f"unknown camera keys {sorted(unknown)} (allowed: {sorted(known)})")
        c = dict(camera)
        if "orbit" in c:
            c["azimuth"], c["elevation"] = (tuple(c.pop("orbit")) + (0.0,))[:2]
        camera = Camera(**c)
    if not isinstance(camera, Camera):
        raise ValueError("camera must be a vnr.Camera, a dict {eye, center, up, fovy} or {azimuth, elevation, fovy}, "
                         "or an (azimuth, elevation) pair")
    vec = lambda v: None if v is None else tuple(float(x) for x in v)  # noqa: E731
    orbit = None if camera.azimuth is None else (float(camera.azimuth), float(camera.elevation))
    return dict(eye=vec(camera.eye), center=vec(camera.center), up=vec(camera.up), fovy=float(camera.fovy),
                orbit=orbit)


def _tf_arg(tf: Union[None, str, dict, TransferFunction, os.PathLike]) -> str:
    if tf is None:
        return "ramp"
    if isinstance(tf, TransferFunction):
        return tf.to_json()
    if isinstance(tf, dict):
        return json.dumps(tf)
    if isinstance(tf, os.PathLike):
        return os.fspath(tf)
    if isinstance(tf, str):
        return tf
    raise ValueError("tf must be a preset name, transfer-function JSON (text or dict), a path or a "
                     "vnr.TransferFunction")


def render(target: Union[Model, Volume], camera: Union[None, Camera, dict, Tuple[float, float]] = None,
           tf: Union[None, str, dict, TransferFunction, os.PathLike] = None, mode: str = "raymarch",
           size: Tuple[int, int] = (512, 512), spp: Union[int, str] = "auto", device: str = "auto", *,
           strategy: str = "auto", macrocells: Optional[str] = None, step: float = 1.0, seed: int = 0,
           shade: bool = False, background: Optional[Sequence[float]] = None,
           light: Optional[Sequence[float]] = None, noise: float = 1 / 255, max_spp: int = 256,
           cache_budget: str = "auto", cache_dims: Optional[Sequence[int]] = None) -> Any:
    """Renders a vnr.Model (or a vnr.Volume, the ground truth) and returns the image as a float32 array
    of shape (height, width, 4): straight RGB and alpha, row 0 at the top.

    The same settings give the image `vnr render` writes (as PFM) for the same input:
    camera: None (the default orbit, azimuth 0), vnr.Camera, a dict {eye, center, up, fovy} or
    {azimuth, elevation, fovy}, or an (azimuth, elevation) pair (the CLI's --orbit);
    tf: a preset name (e.g. "ramp", "cool-warm"), transfer-function JSON as text or a dict (what
    `vnr render --tf FILE` reads), a path, or a vnr.TransferFunction;
    mode: "raymarch", "shadow" or "pathtrace"; size: (width, height); spp: frames accumulated, or "auto"
    (the default, as the CLI's): until the image's noise (RMS standard error of its pixels) is at most
    `noise`, at most max_spp frames;
        device: "auto", "cpu" or "cuda"; strategy: "auto" (as the CLI's: a model's brick cache
    when 8 frames or more are accumulated, docs/RENDERING.md), "cache", "streaming" or "inshader";
    macrocells: "grid", "online" or "off" (default as the CLI's); step, seed, shade, background, light:
    the CLI's options; cache_budget ("512MiB", ...; "auto": a quarter of the available memory, at most
    4 GiB) and cache_dims ((x, y, z): the resolution the cache decodes a model at, any size): the CLI's
    --cache-budget and --cache-dims.
    """
    w, h = (int(v) for v in size)
    if (isinstance(spp, str) and spp != "auto") or (not isinstance(spp, str) and int(spp) < 1):
        raise ValueError(f"spp must be 'auto' or at least 1, got {spp!r}")
    settings = dict(tf=_tf_arg(tf), mode=mode, size=[w, h], spp=0 if spp == "auto" else int(spp),
                    noise=float(noise), max_spp=int(max_spp), device=device, strategy=strategy,
                    macrocells=macrocells or "", step=float(step), seed=int(seed), shade=bool(shade),
                    background=None if background is None else [float(x) for x in background],
                    light=None if light is None else [float(x) for x in light], cache_budget=str(cache_budget),
                    cache_dims=None if cache_dims is None else [int(x) for x in cache_dims],
                    **_camera_args(camera))
    # vnr::RenderSettings as JSON (the library's one settings object; None: the library's default).
    return _render(target, json.dumps({k: v for k, v in settings.items() if v is not None}))
