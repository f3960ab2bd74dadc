"""Type stubs of mlfe.distributed (python/mlfe/distributed.py)."""
from typing import Any, Dict, Optional

from mlfe import IsoValues, PathLike, Progress

def convert(
    input: PathLike,
    output: PathLike,
    client: Any = ...,
    *,
    iso: Optional[IsoValues] = ...,
    progress: Optional[Progress] = ...,
    n_workers: Optional[int] = ...,
    **options: Any,
) -> Dict[str, Any]: ...
