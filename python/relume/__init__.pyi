from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Union

from ._relume import Graph as _NativeGraph
from ._relume import GraphError as GraphError
from ._relume import ParamValue, RunResult, StrPath
from ._relume import RunError as RunError
from ._relume import RunResult as RunResult
from ._relume import nodes as nodes
from ._relume import read_image as read_image
from ._relume import write_image as write_image
from ._nodes import Image as Image
from ._nodes import Metrics as Metrics
from ._nodes import node as node
from ._nodes import param as param

class Node:
    id: str
    @property
    def kind(self) -> str: ...
    @property
    def doc(self) -> str: ...
    @property
    def params(self) -> List[Dict[str, Any]]: ...
    def __getitem__(self, param: str) -> Any: ...
    def __setitem__(self, param: str, value: ParamValue) -> None: ...

class Graph(_NativeGraph):
    @classmethod
    def load(cls, path: StrPath, *, cache: Optional[StrPath] = ..., no_disk_cache: bool = ...) -> "Graph": ...
    def __getitem__(self, node_id: str) -> Node: ...
    def __setitem__(self, assignment: str, value: ParamValue) -> None: ...
    def run(  # type: ignore[override]
        self,
        outputs: Optional[Sequence[str]] = ...,
        *,
        progress: Union[Callable[[str, float], None], bool, Literal["auto"]] = ...,
    ) -> RunResult: ...
