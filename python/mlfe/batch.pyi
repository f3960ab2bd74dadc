"""Type stubs of mlfe.batch (python/mlfe/batch.py)."""
import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

PathLike = Union[str, "os.PathLike[str]"]

VOLUME_SUFFIXES: Tuple[str, ...]

class BatchResult:
    rows: List[Dict[str, Any]]
    csv_path: str
    json_path: str
    @property
    def failed(self) -> List[Tuple[str, str]]: ...
    def count(self, status: str) -> int: ...

def find_scans(folder: PathLike, recursive: bool = ...) -> List[str]: ...
def convert(
    inputs: Union[PathLike, Sequence[PathLike]],
    out_dir: PathLike,
    *,
    iso: Any = ...,
    asset_ext: str = ...,
    hierarchy: bool = ...,
    report: bool = ...,
    scheduler: Any = ...,
    n_workers: Optional[int] = ...,
    overwrite: bool = ...,
    summary: str = ...,
    on_row: Optional[Callable[[Dict[str, Any]], None]] = ...,
    **options: Any,
) -> BatchResult: ...
