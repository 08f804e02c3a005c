from os import PathLike
from typing import Any, Callable, Optional, Sequence, Tuple, Union

Tiles = Union[str, PathLike[str], Sequence[Union[str, PathLike[str], Tuple[str, int, int]]]]

def build(tiles: Tiles, out: Union[str, PathLike[str]], *, seam: str = "strict",
          tile_size: Optional[int] = None, progress: Optional[Callable[[str, int, int], Any]] = None,
          **options: Any) -> dict[str, Any]: ...
def add(dataset: Union[str, PathLike[str]], src: Union[str, PathLike[str]], *,
        at: Optional[Tuple[int, int]] = None, replace: bool = False, seam: Optional[str] = None,
        progress: Optional[Callable[[str, int, int], Any]] = None, **options: Any) -> dict[str, Any]: ...
