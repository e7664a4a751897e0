"""Type stubs of vnr's compiled core (_vnr); the package `vnr` re-exports these names."""
from __future__ import annotations

import os
from typing import Any, Callable, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

DeviceName = Literal["auto", "cpu", "cuda"]
NanPolicy = Literal["error", "zero", "clamp"]
PathLike = Union[str, os.PathLike]
Range = Tuple[Optional[float], Optional[float]]


def set_num_threads(threads: int) -> None:
    """Sets the CPU threads vnr uses (0: all cores), as the CLI's --threads does."""


def num_threads() -> int:
    """The CPU threads vnr uses."""


class Volume:
    """A scalar volume in memory: values normalised to [0, 1], the value range in original units and the
    source dtype. Arrays are (nz, ny, nx) in C order (x fastest) or (nx, ny, nz) in Fortran order."""

    @staticmethod
    def from_numpy(array: npt.ArrayLike, value_range: Optional[Range] = None, nan: NanPolicy = "error") -> Volume:
        """A volume from a 3-D array of any numeric dtype, converted as `vnr train` reads a raw file."""

    @staticmethod
    def open(path: str, timestep: Optional[int] = None, *, dims: Optional[Tuple[int, int, int]] = None,
             dtype: Optional[str] = None, endian: Optional[Literal["little", "big"]] = None,
             offset: Optional[int] = None, value_range: Optional[Range] = None,
             nan: NanPolicy = "error") -> Volume:
        """Opens any volume source the CLI reads (sidecar, scene, NRRD, raw with dims and dtype)."""

    @property
    def dims(self) -> Tuple[int, int, int]:
        """Voxels per axis (x, y, z)."""

    @property
    def shape(self) -> Tuple[int, int, int]:
        """The numpy shape (nz, ny, nx)."""

    @property
    def source_dtype(self) -> np.dtype[Any]:
        """The dtype the values came in."""

    @property
    def value_range(self) -> Tuple[float, float]:
        """(lo, hi) in original units."""

    @property
    def normalised(self) -> npt.NDArray[np.float32]:
        """The normalised values, a read-only (nz, ny, nx) view of vnr's memory."""

    def to_numpy(self) -> npt.NDArray[np.float32]:
        """The values in original units, a new (nz, ny, nx) float32 array."""


class Model:
    """A trained neural representation of a volume."""

    @staticmethod
    def load(path: str) -> Model:
        """Loads a .vnr model (or instantvnr BSON)."""

    def save(self, path: str) -> None:
        """Writes the model atomically (.vnr; .bson/.json: instantvnr's BSON)."""

    def decode(self, shape: Optional[Sequence[int]] = None,
               dtype: Union[Literal["float32", "source"], str] = "float32",
               device: DeviceName = "auto") -> npt.NDArray[Any]:
        """The volume decoded at voxel centres in original units, shape (nz, ny, nx)."""

    def decode_to_file(self, path: str, shape: Optional[Sequence[int]] = None,
                       dtype: Union[Literal["float32", "source"], str] = "float32",
                       device: DeviceName = "auto", force: bool = False) -> None:
        """What `vnr decode` writes (OUT.raw + OUT.json, or OUT.nrrd), in slabs: any size."""

    def sample(self, points: npt.NDArray[np.floating[Any]], device: DeviceName = "auto") -> npt.NDArray[np.float32]:
        """Values (original units) at an (N, 3) array of normalised x, y, z in [0, 1]."""

    @property
    def config(self) -> dict[str, Any]:
        """The tiny-cuda-nn config."""

    @property
    def n_params(self) -> int:
        """Number of parameters."""

    @property
    def compression_ratio(self) -> float:
        """Source volume bytes / model bytes."""

    @property
    def value_range(self) -> Tuple[float, float]:
        """(lo, hi): original units of normalised 0 and 1."""

    @property
    def dims(self) -> Tuple[int, int, int]:
        """Voxels per axis (x, y, z)."""

    @property
    def shape(self) -> Tuple[int, int, int]:
        """The numpy shape (nz, ny, nx) of decode()'s default output."""

    @property
    def source_dtype(self) -> np.dtype[Any]:
        """The dtype of the volume it was trained on."""

    @property
    def training(self) -> dict[str, Any]:
        """The training record."""


def train(volume: Union[npt.ArrayLike, Volume, PathLike], config: Union[str, dict[str, Any], PathLike] = "auto",
          steps: Optional[int] = None, seconds: Optional[float] = None, seed: int = 1337, device: DeviceName = "auto",
          sampler: Literal["incore", "outofcore", "mmap"] = "incore", target_ratio: Optional[float] = None,
          callback: Optional[Callable[[int, float, float], Optional[bool]]] = None, *, batch: int = 65536,
          precision: Literal["auto", "fp32", "bf16"] = "auto", macrocell_size: int = 16,
          threads: Optional[int] = None, verbose: bool = False, target_psnr: Optional[float] = None,
          bits_per_param: Optional[float] = None, qat_fraction: Optional[float] = None,
          max_error: Optional[float] = None, max_rel_error: Optional[float] = None,
          cooldown: Optional[float] = None, rate_weight: Optional[float] = None,
          residuals: str = "auto", learn_steps: bool = False) -> Model:
    """Trains a model of the volume (`vnr train`'s session); returns it. Ctrl-C returns the model so far."""


def train_series(volume: PathLike, output_dir: PathLike, timesteps: str = "all", *, continuous: bool = False,
                 switch_every: int = 0, seconds: Optional[float] = None, ssim: bool = True,
                 report: Optional[PathLike] = None, threads: Optional[int] = None, **kwargs: Any) -> dict[str, Any]:
    """Trains a time series into output_dir/t0000.vnr, ... (`vnr train --timesteps`); returns the report."""


def _render(target: Union[Model, Volume], settings_json: str) -> npt.NDArray[np.float32]:
    """vnr::RenderSettings as JSON (vnr.render builds it)."""


def _error_stats(reference: npt.NDArray[Any], test: npt.NDArray[Any],
                 value_range: Optional[Tuple[float, float]]) -> Tuple[float, float, float]: ...


def _ssim(reference: npt.NDArray[Any], test: npt.NDArray[Any], value_range: Optional[Tuple[float, float]]) -> float: ...
