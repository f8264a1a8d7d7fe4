"""Type stubs of relume's native module (re-exported by ``relume``)."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

StrPath = Union[str, "PathLike[str]"]
ParamValue = Union[float, int, bool, str, Sequence[Union[float, int]]]

class GraphError(ValueError):
    """A graph or parameter value the engine refuses, with ``relume run --set``'s message."""

    file: Optional[str]
    line: Optional[int]
    column: Optional[int]
    node: Optional[str]
    param: Optional[str]

class RunError(RuntimeError):
    """A run that failed: which node, of which kind, and why."""

class RunResult:
    """A finished run's outputs, images, metrics and report."""

    outputs: Dict[str, Any]
    images: Dict[str, npt.NDArray[np.float32]]
    metrics: Dict[str, Dict[str, float]]
    report: Dict[str, Any]
    @property
    def ran(self) -> List[str]: ...
    def __getitem__(self, name: str) -> Any: ...

class Graph:
    def __init__(self, path: Optional[StrPath] = ..., *, cache: Optional[StrPath] = ..., no_disk_cache: bool = ...) -> None: ...
    @property
    def path(self) -> Optional[str]: ...
    @property
    def nodes(self) -> List[Dict[str, Any]]: ...
    @property
    def outputs(self) -> List[str]: ...
    def set(self, assignment: str, value: ParamValue) -> None: ...
    def get(self, assignment: str) -> Any: ...
    def run(
        self,
        outputs: Optional[Sequence[str]] = ...,
        *,
        progress: Optional[Callable[[str, float], None]] = ...,
    ) -> RunResult: ...
    def add(self, kind: str, *, id: Optional[str] = ..., **params: ParamValue) -> str: ...
    def connect(self, source: str, target: str) -> None: ...
    def output(self, name: str, port: str) -> None: ...
    def feed(self, target: str, array: npt.ArrayLike) -> str: ...
    def shrink_to_test_size(self) -> None: ...
    def to_ron(self) -> str: ...
    def save(self, path: StrPath) -> None: ...

def nodes() -> List[Dict[str, Any]]: ...
def read_image(path: StrPath) -> npt.NDArray[np.float32]: ...
def write_image(path: StrPath, array: npt.ArrayLike) -> None: ...
def _define_node(
    kind: str,
    doc: str,
    inputs: List[Tuple[str, str]],
    outputs: List[Tuple[str, str]],
    params: List[Tuple[str, Any, Optional[Tuple[float, float]], str, str]],
    source: str,
    func: Callable[..., Any],
) -> None: ...
