"""Type hints of the compiled extension (python/src/lib.rs). Use the package `ctsid` instead."""

from typing import List, Optional, Tuple

Run = Tuple[str, List[List[float]]]

class CtsidError(ValueError): ...

class Model:
    @staticmethod
    def from_json(text: str) -> "Model": ...
    @staticmethod
    def load(path: str) -> "Model": ...
    def to_json(self) -> str: ...
    def save(self, path: str) -> None: ...
    def equations(self) -> List[str]: ...
    @property
    def outputs(self) -> List[str]: ...
    @property
    def inputs(self) -> List[str]: ...
    @property
    def orders(self) -> List[int]: ...
    @property
    def tau(self) -> Optional[float]: ...
    def coefficients(self) -> List[Tuple[str, str, float, Optional[float]]]: ...
    def simulate(
        self, tau: float, names: List[str], runs: List[Run], segment: Optional[float] = ...
    ) -> List[Tuple[str, List[List[float]], List[float], List[float]]]: ...

def identify(
    tau: float,
    names: List[str],
    runs: List[Run],
    outputs: List[str],
    inputs: List[str],
    degree: int,
    train: Optional[str] = ...,
    validation: Optional[str] = ...,
    test: Optional[str] = ...,
    order: Optional[List[int]] = ...,
    orders: Optional[List[int]] = ...,
    terms: List[str] = ...,
    engine: str = ...,
    refine: bool = ...,
    eta: Optional[float] = ...,
    segment: Optional[float] = ...,
    limits: bool = ...,
) -> Tuple[Model, str]: ...
def derive(y: List[float], tau: float, order: int) -> Tuple[List[List[float]], List[List[float]]]: ...
def discover(
    tau: float,
    names: List[str],
    runs: List[Run],
    nominal: Model,
    train: Optional[str] = ...,
    validation: Optional[str] = ...,
    test: Optional[str] = ...,
    seed: int = ...,
    segment: Optional[float] = ...,
) -> Tuple[str, str, Model, float, float]: ...
def throttle_dataset(
    path: str,
    runs: int = ...,
    samples: int = ...,
    tau: float = ...,
    noise: float = ...,
    seed: int = ...,
    truth: bool = ...,
) -> None: ...
