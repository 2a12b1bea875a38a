"""Run one .tflite model with LiteRT (Google's TFLite runtime), checked on load.

Every camera model (BlazeFace, face landmarks, iris) goes through this one
wrapper so that a wrong file fails the same way everywhere: at load time,
with a `ModelLoadError` (a `ConfigError`, so the service exits 2) that names
the file and says which tensor layout was expected and which one the file
has. A model that loaded but has another layout would otherwise run and
produce garbage (a short-range BlazeFace decoded with full-range anchors
finds faces in the wrong places), so the layout is part of the contract.

LiteRT (`ai_edge_litert`, no TensorFlow) runs the models with its XNNPACK
CPU delegate, which is on by default; `num_threads` defaults to one so a
2-core robot computer keeps a core for capture and the rest of the robot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from ai_edge_litert.interpreter import Interpreter  # type: ignore[import-untyped]

from buddybot.runtime.errors import ConfigError

P = TypeVar("P")
R = TypeVar("R")
FloatArray = npt.NDArray[np.float32]

ANY = -1
"""A dimension of any size in a `Tensor` shape."""


class ModelLoadError(ConfigError):
    """The model file cannot be loaded, or its tensors are not the expected ones."""


@dataclass(frozen=True)
class Tensor:
    """An expected tensor: its shape (`ANY` for a free dimension), and optionally the
    model's name for it. Without a name, outputs are matched by shape."""

    shape: tuple[int, ...]
    name: str | None = None
    dtype: type[np.generic] = np.float32

    def accepts(self, name: str, shape: Sequence[int], dtype: Any) -> bool:
        """Whether an actual tensor (name, shape, dtype) is this one."""
        if self.name is not None and name != self.name:
            return False
        if np.dtype(dtype) != np.dtype(self.dtype) or len(shape) != len(self.shape):
            return False
        return all(want in (ANY, got) for want, got in zip(self.shape, shape, strict=True))

    def describe(self) -> str:
        dims = "x".join("?" if d == ANY else str(d) for d in self.shape)
        label = f"{self.name} " if self.name else ""
        return f"{label}{dims} {np.dtype(self.dtype).name}"


Details = Mapping[str, Any]
"""One entry of LiteRT's get_input_details()/get_output_details()."""


def _first_line(exc: BaseException) -> str:
    """LiteRT's own words for a failure: the first line of its message."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _shape(d: Details) -> list[int]:
    return [int(v) for v in np.asarray(d["shape"]).tolist()]


def _describe(details: Sequence[Details]) -> str:
    parts = []
    for d in details:
        dims = "x".join(str(v) for v in _shape(d))
        parts.append(f"{d['name']} {dims} {np.dtype(d['dtype']).name}")
    return ", ".join(parts) or "none"


class LiteModel:
    """A loaded, layout-checked model: `run(x)` -> its outputs in the caller's order.

    `input` is the one input tensor expected; `outputs` the output tensors in
    the order `run` returns them (matched by name where given, else by shape:
    each expected output must match exactly one of the model's outputs).
    """

    def __init__(self, path: Path, input: Tensor, outputs: Sequence[Tensor],
                 num_threads: int = 1) -> None:
        self.path = Path(path)
        self.input = input
        self.outputs = tuple(outputs)
        self.num_threads = num_threads
        try:
            self._interp = Interpreter(model_path=str(self.path), num_threads=num_threads)
            self._interp.allocate_tensors()
        except (ValueError, RuntimeError, OSError) as exc:
            reason = _first_line(exc)
            raise ModelLoadError(
                f"cannot load model {self.path}: LiteRT says: {reason} (expected a .tflite "
                f"file with input {input.describe()} and outputs "
                f"{', '.join(o.describe() for o in self.outputs)})"
            ) from None
        ins = self._interp.get_input_details()
        outs = self._interp.get_output_details()
        self._input_index, self._output_indices = self._check(ins, outs)

    def _check(self, ins: Sequence[Details], outs: Sequence[Details]) -> tuple[int, list[int]]:
        """Indices of the input and of each expected output, or a ModelLoadError."""
        def problem(what: str) -> ModelLoadError:
            return ModelLoadError(
                f"model {self.path} has the wrong tensor layout ({what}): expected input "
                f"{self.input.describe()} and outputs "
                f"{', '.join(o.describe() for o in self.outputs)}; the file has input "
                f"{_describe(ins)} and outputs {_describe(outs)}"
            )

        def fits(want: Tensor, d: Details) -> bool:
            return want.accepts(str(d["name"]), _shape(d), d["dtype"])

        if len(ins) != 1 or not fits(self.input, ins[0]):
            raise problem("input")
        if len(outs) < len(self.outputs):
            raise problem(f"{len(outs)} outputs, {len(self.outputs)} needed")
        chosen: list[int] = []
        for want in self.outputs:
            matches = [d for d in outs if fits(want, d)]
            if len(matches) != 1:
                found = "none" if not matches else f"{len(matches)} candidates"
                raise problem(f"output {want.describe()}: {found}")
            index = int(matches[0]["index"])
            if index in chosen:
                raise problem(f"output {want.describe()} matched twice")
            chosen.append(index)
        return int(ins[0]["index"]), chosen

    @property
    def input_shape(self) -> tuple[int, ...]:
        return self.input.shape

    def resize_input(self, input: Tensor, outputs: Sequence[Tensor]) -> None:
        """Run the (fully convolutional) model at another input size: `input` is the new
        input, `outputs` what the outputs must then be. Checked like a load: a model
        that cannot run at that size, or gives other outputs, is a ModelLoadError."""
        try:
            self._interp.resize_tensor_input(self._input_index, list(input.shape))
            self._interp.allocate_tensors()
        except (ValueError, RuntimeError) as exc:
            reason = _first_line(exc)
            raise ModelLoadError(f"model {self.path} cannot run with input "
                                 f"{input.describe()}: LiteRT says: {reason}") from None
        self.input, self.outputs = input, tuple(outputs)
        self._input_index, self._output_indices = self._check(
            self._interp.get_input_details(), self._interp.get_output_details())

    def run(self, x: FloatArray) -> list[FloatArray]:
        """One inference; returns copies of the outputs in the order they were expected."""
        self._interp.set_tensor(self._input_index, x)
        self._interp.invoke()
        return [np.asarray(self._interp.get_tensor(i), np.float32)
                for i in self._output_indices]

    def infer(self, fill: Callable[[FloatArray], P],
              read: Callable[[P, FloatArray, FloatArray], R]) -> R:
        """One inference without copying a tensor (the per-frame BlazeFace path).

        `fill(x)` writes the input in place: `x` is LiteRT's own input buffer,
        which keeps its contents from one call to the next (so a letterbox
        border written once stays). `read(filled, *outputs)` then gets what
        `fill` returned and the outputs as views, in the expected order; it
        must return nothing that refers to them: LiteRT refuses to run again
        while a view of its buffers is alive. Saves the input and output
        copies of `run` (0.1 ms of a whole-frame pass).
        """
        filled = fill(self._interp.tensor(self._input_index)())
        self._interp.invoke()
        return read(filled, *(self._interp.tensor(i)() for i in self._output_indices))

    def input_copy(self) -> FloatArray:
        """A copy of what the input tensor holds now (tests: what `fill` wrote)."""
        return np.array(self._interp.get_tensor(self._input_index), np.float32)
