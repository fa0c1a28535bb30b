# Type stubs of brdfd._native, the Rust side of the package (python/src/lib.rs).
from typing import List, Optional, Sequence, Tuple, Union

VERSION: str

class Scan:
    @property
    def sample(self) -> str: ...
    @property
    def reference(self) -> str: ...
    def to_json(self) -> str: ...

class FitReport:
    def to_json(self) -> str: ...
    def measured(self) -> List[Optional[List[float]]]: ...
    def estimated(self) -> List[List[float]]: ...

def read_scan(path: str) -> Scan: ...
def import_export(
    path: str, sra: Optional[str] = None, reference: Optional[str] = None
) -> List[Tuple[Scan, Optional[str]]]: ...
# The options after `sra` are brdfd.fit's keyword-only string options (specular … model),
# passed through by name: brdfd/__init__.py owns their names, defaults and documentation.
def fit(
    scan: Scan,
    cost: str,
    method: Optional[str] = None,
    seed: Optional[int] = None,
    bootstrap: int = 0,
    sra: Optional[str] = None,
    **options: Optional[str],
) -> FitReport: ...
def geometries() -> List[Tuple[str, str, float, float, float, float]]: ...
def wavelengths() -> List[int]: ...
def evaluate(
    kd: Sequence[float],
    ks: float,
    alpha: float,
    ior: float,
    geometries: Sequence[Union[str, Tuple[float, float, float]]],
    wavelengths: Sequence[int],
    fresnel: Optional[str] = None,
    model: Optional[str] = None,
    extra: Optional[Sequence[float]] = None,
) -> List[List[float]]: ...
def store_tidy(path: str, include_simulated: bool = True) -> Tuple[str, str]: ...
